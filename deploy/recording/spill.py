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
        self._block_rows = block_rows
        # Rows as given until the block is full: appending a tuple to a list is ~20 times
        # cheaper than writing it into an array (ring64: ~1 300 states a second).
        self._pending: list[Sequence[float] | FloatArray] = []
        self._blocks: list[_Block] = []

    def append(self, row: Sequence[float] | FloatArray) -> None:
        self._pending.append(row)
        self.rows += 1
        if len(self._pending) == self._block_rows:
            self._write_pending()

    def _pending_rows(self) -> FloatArray:
        return np.asarray(self._pending, dtype=np.float64).reshape(-1, self.width)

    def _write_pending(self) -> None:
        block = self._pending_rows()
        self._file.seek(0, 2)
        self._file.write(block.tobytes())
        keys = block[:, 0]
        self._blocks.append(_Block(self.rows - len(block), len(block),
                                   float(keys.min()), float(keys.max())))
        self._pending = []

    def blocks(self, key_min: float = -np.inf, key_max: float = np.inf) -> Iterator[FloatArray]:
        """In file order, every block (the unwritten one last) that may hold a row whose
        key lies in [key_min, key_max]; callers select the rows themselves."""
        for b in self._blocks:
            if b.key_max < key_min or b.key_min > key_max:
                continue
            self._file.seek(b.offset_rows * self.width * _ITEM_BYTES)
            data = self._file.read(b.rows * self.width * _ITEM_BYTES)
            yield np.frombuffer(data, dtype=np.float64).reshape(b.rows, self.width)
        if self._pending:
            yield self._pending_rows()

    def key_blocks(self) -> Iterator[FloatArray]:
        """Column 0, block by block in file order."""
        for block in self.blocks():
            yield block[:, 0].copy()

    def close(self) -> None:
        self._file.close()
