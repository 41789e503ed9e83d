"""What a follower's law was handed, journaled, and read back.

The follower's `LawRunner` writes one record per call that changes it: a step (`"s"`:
the clock, control tick or estimator step, its vehicle's sample, its targets and peers as
handed to the law, and what came out), a change of members (`"g"`), a join (`"j"`),
and the experiment's start and stop as the follower heard them (`"w"`: the replay's
time axis, and the origin of the law's `Inputs.t_s`, which a replay derives from it).
Targets and peers are written as changes: the keys in the order the law iterates them,
and only the entries that are not the very objects of the last record (agents.follower.inputs
makes a new one per newer message), so a record costs about the messages that arrived.
A step's result is kept as CRCs of its command, its estimate and rate, and its
published fields; `enclose replay` (agents.follower.journal_replay) re-runs the same runner
and compares.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import msgpack

from agents.follower.journal_file import FrameWriter
from agents.law.interface import Output, Peer, Sample
from transport.law_fields import FieldSpec, LawFields

STEP, REGROUP, JOIN, WINDOW, REBASE = "s", "g", "j", "w", "r"
_new = tuple.__new__


# A Sample as bytes: its four plane numbers as float32 when that is exact (a vehicle's
# telemetry arrives as MAVLink float32: a fifth of a record's bytes), else float64.
_F32, _F64 = struct.Struct("<4fd"), struct.Struct("<5d")


def _sample(s: Sample) -> bytes:
    v, r = s.value, s.rate
    x, y, vx, vy = v.real, v.imag, r.real, r.imag
    try:
        short = _F32.pack(x, y, vx, vy, s.stamp_s)
        if _F32.unpack(short)[:4] == (x, y, vx, vy):
            return short
    except OverflowError:  # beyond float32's range
        pass
    return _F64.pack(x, y, vx, vy, s.stamp_s)


def fields_crc(wire: LawFields) -> int:
    """The published fields' fingerprint: equal iff their msgpack bytes are."""
    return zlib.crc32(msgpack.packb(wire, use_bin_type=True))


_TWO, _FOUR = struct.Struct("<2d"), struct.Struct("<4d")


def result_crcs(result: tuple[Output, LawFields] | None) -> list[int] | None:
    """A step's result as the journal keeps it: CRCs of its command, of its estimate and
    rate, and of its published fields (None: the law failed).  A replay recomputes them:
    the values are its own, a fingerprint is enough to say it is the run's, bit for bit."""
    if result is None:
        return None
    out, wire = result
    u, r, dr = out.u_m_s, out.r_m, out.dr_m_s
    return [zlib.crc32(_TWO.pack(u.real, u.imag)),
            zlib.crc32(_FOUR.pack(r.real, r.imag, dr.real, dr.imag)), fields_crc(wire)]


class Changes:
    """A keyed map written as what changed since the last one (by identity)."""

    def __init__(self, encode: Any) -> None:
        self._last: dict[int, object] = {}
        self._encode = encode

    def delta(self, now: Mapping[int, Any]) -> list[Any]:
        last, changed = self._last, []
        for j, v in now.items():
            if last.get(j) is not v:
                changed.append([j, *self._encode(v)])
        self._last = dict(now)
        return [list(now), changed]


class PeerCodec:
    """A peer as the journal keeps it, for a law that declared `fields` (name, rate's
    name or None) in this order: its fields as a list in that order, a complex as 16
    bytes, a rated field's Sample as its value alone when its rate and stamp are those
    agents.follower.inputs gives it (the rate field's value, the message's stamp)."""

    def __init__(self, fields: Sequence[tuple[str, str | None]]) -> None:
        self.fields = [(name, rate) for name, rate in fields]

    def encode(self, p: Peer) -> list[Any]:
        held, stamp = p.fields, p.r.stamp_s
        out: list[Any] = []
        for name, rate in self.fields:
            v = held.get(name)
            if type(v) is complex:
                out.append(_TWO.pack(v.real, v.imag))
            elif isinstance(v, Sample):
                value = v.value
                if (rate is not None and type(value) is complex and v.stamp_s == stamp
                        and v.rate == held.get(rate, 0j)):
                    out.append(_TWO.pack(value.real, value.imag))
                else:
                    out.append(_sample(v))
            else:
                out.append(v)
        return [_sample(p.r), _sample(p.pos), out]

    def decode(self, v: list[Any]) -> Peer:
        r = read_sample(v[0])
        fields: dict[str, Any] = {}
        for (name, _), f in zip(self.fields, v[2], strict=True):
            if f is not None:
                fields[name] = (complex(*_TWO.unpack(f)) if isinstance(f, bytes)
                                and len(f) == _TWO.size else read_sample(f)
                                if isinstance(f, bytes) else f)
        for name, rate in self.fields:  # a value alone: the rate field's, at r's stamp
            f = fields.get(name)
            if rate is not None and type(f) is complex:
                fields[name] = _new(Sample, (f, fields.get(rate, 0j), r.stamp_s))
        return _new(Peer, (r, read_sample(v[1]), fields))


def field_names(specs: Mapping[str, FieldSpec]) -> list[tuple[str, str | None]]:
    """A law's declared fields as the journal's header keeps them."""
    return [(name, spec.rate) for name, spec in specs.items()]


class JournalWriter:
    """The journal of one follower's runner, in `path` (agents.follower.journal_file)."""

    def __init__(self, path: Path, header: dict[str, Any],
                 specs: Mapping[str, FieldSpec]) -> None:
        fields = field_names(specs)
        self.file = FrameWriter(path, {**header, "fields": fields})
        codec = PeerCodec(fields)
        self._targets = Changes(lambda s: [_sample(s)])
        self._peers = Changes(codec.encode)
        self._peers_join = Changes(codec.encode)

    def step(self, now_s: float, command: bool, own: Sample, targets: Mapping[int, Sample],
             peers: Mapping[int, Peer], result: tuple[Output, LawFields] | None) -> None:
        self.file.add([STEP, now_s, command, _sample(own), self._targets.delta(targets),
                       self._peers.delta(peers), result_crcs(result)])

    def regroup(self, members: tuple[int, ...]) -> None:
        self.file.add([REGROUP, list(members)])

    def join(self, peers: Mapping[int, Peer], now_s: float) -> None:
        self.file.add([JOIN, now_s, self._peers_join.delta(peers)])

    def rebase(self) -> None:
        self.file.add([REBASE])

    def window(self, start_s: float, stop_s: float) -> None:
        """The experiment's start and stop as this follower was told them (its clock)."""
        self.file.add([WINDOW, start_s, stop_s])

    def close(self) -> None:
        self.file.close()


def read_sample(b: bytes) -> Sample:
    v = (_F32 if len(b) == _F32.size else _F64).unpack(b)
    return _new(Sample, (complex(v[0], v[1]), complex(v[2], v[3]), v[4]))


def read_target(v: list[bytes]) -> Sample:
    return read_sample(v[0])


class Mirror:
    """The keyed map a `Changes` wrote, rebuilt from its records."""

    def __init__(self, decode: Any) -> None:
        self._held: dict[int, Any] = {}
        self._decode = decode

    def apply(self, delta: list[Any]) -> dict[int, Any]:
        keys, changed = delta
        held = self._held
        for entry in changed:
            held[entry[0]] = self._decode(entry[1:])
        self._held = {j: held[j] for j in keys}
        return dict(self._held)


def journal_path(folder: Path, index: int) -> Path:
    """Where follower `index` journals: its first file, or the next part (a restarted
    process) beside the earlier ones, in the order `enclose replay` reads them."""
    folder.mkdir(parents=True, exist_ok=True)
    path, part = folder / f"follower-{index}.journal", 2
    while path.exists():
        path, part = folder / f"follower-{index}-part{part}.journal", part + 1
    return path
