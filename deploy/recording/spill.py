"""Rows of float64 numbers kept on disk as a run goes, read back block by block.

The recorder's assembler keeps every truth snapshot and follower state of a run until the
end, when it aligns them (deploy.recording.assembler): in memory that grew by ~9 MB a
minute on the paper's case.  A `RowSpill` appends each row to a small in-memory block and
writes the block to an anonymous temporary file when it fills; what stays in memory per
block is its place in the file and the range of its first column (a stamp), so that a
reader asking for a range of stamps reads only the blocks that may hold some.  The file
is unlinked from the start: it goes away with the process, however that ends (the MCAP is
the run's record; this is a cache of it).
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
BLOCK_ROWS = 2048
_ITEM_BYTES = 8


@dataclass(frozen=True)
class _Block:
    offset_rows: int
    rows: int
    key_min: float  # of column 0
    key_max: float


class RowSpill:
    """Append-only rows of `width` float64 values; column 0 is the key blocks are found by."""

    def __init__(self, width: int, spill_dir: Path | None = None,
                 block_rows: int = BLOCK_ROWS) -> None:
        self.width = width
        self.rows = 0
        self._file: IO[bytes] = tempfile.TemporaryFile(dir=spill_dir)  # noqa: SIM115
        self._buffer = np.empty((block_rows, width))
        self._filled = 0
        self._blocks: list[_Block] = []

    def append(self, row: Sequence[float] | FloatArray) -> None:
        self._buffer[self._filled] = row
        self._filled += 1
        self.rows += 1
        if self._filled == len(self._buffer):
            self._write_buffer()

    def _write_buffer(self) -> None:
        block = self._buffer[: self._filled]
        self._file.seek(0, 2)
        self._file.write(block.tobytes())
        keys = block[:, 0]
        self._blocks.append(_Block(self.rows - self._filled, self._filled,
                                   float(keys.min()), float(keys.max())))
        self._filled = 0

    def blocks(self, key_min: float = -np.inf, key_max: float = np.inf) -> Iterator[FloatArray]:
        """In file order, every block (the unwritten one last) that may hold a row whose
        key lies in [key_min, key_max]; callers select the rows themselves."""
        for b in self._blocks:
            if b.key_max < key_min or b.key_min > key_max:
                continue
            self._file.seek(b.offset_rows * self.width * _ITEM_BYTES)
            data = self._file.read(b.rows * self.width * _ITEM_BYTES)
            yield np.frombuffer(data, dtype=np.float64).reshape(b.rows, self.width)
        if self._filled:
            yield self._buffer[: self._filled].copy()

    def key_blocks(self) -> Iterator[FloatArray]:
        """Column 0, block by block in file order."""
        for block in self.blocks():
            yield block[:, 0].copy()

    def close(self) -> None:
        self._file.close()
