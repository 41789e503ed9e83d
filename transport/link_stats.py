"""Per-link delivery statistics at a receiver: unique messages received and their age.

A link is (sender, this receiver).  The sender of a sample comes from its key:
- a follower-state key of follower j is link `f<j>` (0-based, like the process names
  `follower-<j>` and the `followers` table of metrics.json);
- a sensor key is link `sensor` (sent by the simulator);
- control, status, truth and liveliness keys belong to no link.

`LinkDecoder` is a `transport.decoder.Decoder` that also tallies, per link, the messages
that reach the agent (one tally per key it hears, and per link one for the processes
gone from it: bounded by the scenario's senders when the decoder is given them).  Its
`counters()` add, for each link L seen:
- `rx_L`: unique messages (by sequence number) received;
- `rx_dup_L`: further copies of a sequence number already received (duplicates);
- `seq_first_L`, `seq_last_L`: lowest and highest sequence number received, so that the
  messages offered while listening were `seq_last_L - seq_first_L + 1`;
- `age_p50_us_L`, `age_p99_us_L`: age at delivery of the unique messages, receive stamp
  minus the sender's header stamp, in microseconds (100 µs resolution);
- `age_n_L`, `age_sum_us_L`: how many ages were taken and their sum (µs), so that a reader
  of two successive counter sets has the mean age over the time between them.  Once a RunControl
  "start" passes through the decoder, only messages stamped from the experiment's start on
  count: the backlog a process drains after its start-up (seconds old) says nothing of
  the link.
- `lat_p50_us_L`, `lat_p99_us_L`: one-way latency of the same messages, when the bus
  stamps arrivals (ZenohConfig.arrival_stamps): arrival in this process minus the
  sender's Zenoh HLC stamp, taken as its session put the sample (10 µs resolution);
  `nbr_lat_p50_us`, `nbr_lat_p99_us`, `nbr_lat_n`: the same over every follower link.
  Processes on one host read one clock, so this needs no clock sync.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from functools import lru_cache

from transport.bus import Received
from transport.decoder import Decoder, Inbound
from transport.key_exprs import parse_key
from transport.law_fields import FieldSpec
from transport.message_checks import Limits
from transport.messages import RunControl

SENSOR = "sensor"
AGE_BIN_S = 1e-4
AGE_MAX_S = 10.0  # older deliveries land in the last bin
LATENCY_BIN_S = 1e-5
LATENCY_MAX_S = 0.1  # slower arrivals land in the last bin
SEEN_WINDOW = 4096  # sequence numbers remembered per stream, to recognise copies


@dataclass(frozen=True)
class Link:
    """A link into this receiver: its counter suffix and the sending follower, if any."""

    name: str
    sender: int | None  # follower index; None for the simulator's sensor


def follower_link(j: int) -> str:
    return f"f{j}"


@lru_cache(maxsize=1024)  # asked for every message; keys come from the network: bounded
def link_of(key: str) -> Link | None:
    """The link a sample on `key` travels, or None for keys that are never impaired."""
    info = parse_key(key)
    if info is None or info.index is None:
        return None
    if info.kind == "follower":
        return Link(follower_link(info.index), info.index)
    if info.kind == "sensor":
        return Link(SENSOR, None)
    return None


class AgeHistogram:
    """Fixed-bin histogram of ages: O(1) per sample, whole-run percentiles, bounded memory.

    Sparse: only bins that hold samples exist (dicts), so a 100k-bin histogram costs
    memory per distinct age, not per bin (a follower holds several, and its process must
    stay small and without numpy: issue 15).  Bins are grouped in blocks with running
    block totals, so a percentile scans the blocks in use and one block's bins rather
    than every bin (it is asked for every loop tick).
    """

    BLOCK = 100

    def __init__(self, bin_s: float = AGE_BIN_S, max_s: float = AGE_MAX_S) -> None:
        self.bin_s = bin_s
        self.n_bins = round(max_s / bin_s)
        self._last = self.n_bins - 1
        self._bins: dict[int, int] = {}  # bin -> samples
        self._blocks: dict[int, int] = {}  # block -> samples
        self.count = 0
        self.sum_s = 0.0

    def add(self, age_s: float) -> None:
        if age_s > 0.0:  # NaN and negative ages land in the first bin, and add nothing
            q = age_s / self.bin_s
            k = int(q) if q < self._last else self._last
            self.sum_s += age_s if age_s < AGE_MAX_S else AGE_MAX_S
        else:
            k = 0
        bins, blocks, b = self._bins, self._blocks, k // self.BLOCK
        bins[k] = bins.get(k, 0) + 1
        blocks[b] = blocks.get(b, 0) + 1
        self.count += 1

    @property
    def bins(self) -> list[int]:
        """Every bin's count (a dense copy: for tests and reports, not per sample)."""
        out = [0] * self.n_bins
        for k, n in self._bins.items():
            out[k] = n
        return out

    @property
    def blocks(self) -> list[int]:
        out = [0] * (self.n_bins // self.BLOCK)
        for b, n in self._blocks.items():
            out[b] = n
        return out

    def merge(self, other: AgeHistogram) -> None:
        for mine, theirs in ((self._bins, other._bins), (self._blocks, other._blocks)):
            for k, n in theirs.items():
                mine[k] = mine.get(k, 0) + n
        self.count += other.count
        self.sum_s += other.sum_s

    def percentile_s(self, q: float) -> float | None:
        """The q-th percentile (0..100), at the middle of its bin; None when empty."""
        if self.count == 0:
            return None
        rank = max(1, math.ceil(q / 100.0 * self.count))
        before = 0
        for b in sorted(self._blocks):  # the first block whose running total reaches rank
            if before + self._blocks[b] >= rank:
                break
            before += self._blocks[b]
        for k in range(b * self.BLOCK, (b + 1) * self.BLOCK):
            before += self._bins.get(k, 0)
            if before >= rank:
                break
        return (k + 0.5) * self.bin_s


@dataclass
class LinkTally:
    """What one key's stream delivered to the agent."""

    link: str
    rx: int = 0
    rx_dup: int = 0
    seq_first: int | None = None
    seq_last: int | None = None
    ages: AgeHistogram = field(default_factory=AgeHistogram)
    latencies: AgeHistogram | None = None  # only when arrivals are stamped
    # The sequence numbers seen, as an anti-replay window (RFC 4303 3.4.3): bit k of
    # `_window` is `seq_last - k`.  A set of them grew by table doublings to ~0.5 MB per
    # link within two minutes, a follower's largest growth (issue 15: <= 50 MB per follower).
    _window: int = 0

    def observe(self, seq: int, age_s: float | None, latency_s: float | None = None) -> None:
        """One delivery; `age_s` None: counted, but its age (and latency) not of interest."""
        if not self._fresh(seq):
            self.rx_dup += 1
            return
        self.rx += 1
        if self.seq_first is None or seq < self.seq_first:
            self.seq_first = seq
        if self.seq_last is None or seq > self.seq_last:
            self.seq_last = seq
        if age_s is not None:
            self.ages.add(age_s)
            if latency_s is not None:
                if self.latencies is None:
                    self.latencies = latency_histogram()
                self.latencies.add(latency_s)

    def absorb(self, other: LinkTally) -> None:
        """Add `other`'s deliveries to this link's totals (another process on one link)."""
        self.rx += other.rx
        self.rx_dup += other.rx_dup
        if other.seq_first is not None:
            self.seq_first = other.seq_first if self.seq_first is None \
                else min(self.seq_first, other.seq_first)
        if other.seq_last is not None:
            self.seq_last = other.seq_last if self.seq_last is None \
                else max(self.seq_last, other.seq_last)
        self.ages.merge(other.ages)
        if other.latencies is not None:
            self.latencies = self.latencies or latency_histogram()
            self.latencies.merge(other.latencies)

    def _fresh(self, seq: int) -> bool:
        """Mark `seq` seen; False for a copy, or for one older than the window (arriving
        thousands of messages late, it can only be a copy).  The window's top is
        `seq_last`, which `observe` moves up to a fresh newest `seq`."""
        back = (-1 if self.seq_last is None else self.seq_last) - seq
        if back < 0:  # the newest yet: slide the window up to it (a jump: start anew)
            shifted = self._window << -back if back > -SEEN_WINDOW else 0
            self._window = (shifted | 1) & _WINDOW_MASK
            return True
        if back >= SEEN_WINDOW or self._window >> back & 1:
            return False
        self._window |= 1 << back
        return True


_WINDOW_MASK = (1 << SEEN_WINDOW) - 1


def latency_histogram() -> AgeHistogram:
    return AgeHistogram(LATENCY_BIN_S, LATENCY_MAX_S)


def _us(value_s: float | None) -> int | None:
    return None if value_s is None else round(value_s * 1e6)


class LinkDecoder(Decoder):
    """A Decoder that also tallies, per link, unique deliveries and their age."""

    def __init__(self, expect: tuple[type, ...] | None = None,
                 limits: Limits | None = None, senders: Collection[str] | None = None,
                 law_fields: Mapping[str, FieldSpec] | None = None) -> None:
        super().__init__(expect, limits, senders=senders, law_fields=law_fields)
        self.tallies: dict[str, LinkTally] = {}  # per key
        # Per link, what the processes gone from it delivered: one tally per link however
        # often its sender leaves and returns (a flapping token must not grow this).
        self.retired: dict[str, LinkTally] = {}
        self.ages_from_s = -float("inf")

    def decode(self, rec: Received) -> Inbound | None:
        inbound = super().decode(rec)
        if inbound is not None:
            msg = inbound.message
            # The launcher repeats its start word every second with the same start stamp:
            # only a new start resets the ages (else "whole-run" meant "the last second").
            if (isinstance(msg, RunControl) and msg.command == "start"
                    and msg.start_stamp_s != self.ages_from_s):
                self.ages_from_s = msg.start_stamp_s
                for t in [*self.tallies.values(), *self.retired.values()]:
                    t.ages, t.latencies = AgeHistogram(), None
            tally = self.tallies.get(rec.key)
            if tally is None:
                link = link_of(rec.key)
                if link is not None:
                    tally = self.tallies[rec.key] = LinkTally(link.name)
            if tally is not None:
                head = msg.header
                age_s = rec.recv_stamp_s - head.stamp_s
                latency_s = None
                if rec.arrival_s is not None:
                    latency_s = rec.arrival_s - (head.stamp_s if rec.hlc_stamp_s is None
                                                 else rec.hlc_stamp_s)
                tally.observe(head.seq, age_s if head.stamp_s >= self.ages_from_s else None,
                              latency_s)
        return inbound

    def forget(self, key: str) -> None:
        """As Decoder.forget; the old process's tally still counts in the link's totals."""
        super().forget(key)
        tally = self.tallies.pop(key, None)
        if tally is not None:
            self.retired.setdefault(tally.link, LinkTally(tally.link)).absorb(tally)

    def link_counters(self) -> dict[str, int]:
        """The per-link counters described in the module docstring."""
        groups: dict[str, list[LinkTally]] = {}
        for tally in [*self.tallies.values(), *self.retired.values()]:
            groups.setdefault(tally.link, []).append(tally)
        # A link with one tally (no sender gone from it) is read as it is: copying each
        # histogram every second was about half of a follower's per-link counters.
        merged = {link: ts[0] if len(ts) == 1 else _absorbed(link, ts)
                  for link, ts in groups.items()}
        out: dict[str, int] = {}
        neighbours = latency_histogram()
        for name, t in sorted(merged.items()):
            lat = t.latencies
            values = {
                "rx": t.rx, "rx_dup": t.rx_dup, "seq_first": t.seq_first,
                "seq_last": t.seq_last, "age_p50_us": _us(t.ages.percentile_s(50)),
                "age_p99_us": _us(t.ages.percentile_s(99)),
                "age_n": t.ages.count, "age_sum_us": _us(t.ages.sum_s),
                "lat_p50_us": None if lat is None else _us(lat.percentile_s(50)),
                "lat_p99_us": None if lat is None else _us(lat.percentile_s(99)),
            }
            out.update({f"{k}_{name}": v for k, v in values.items() if v is not None})
            if lat is not None and name != SENSOR:
                neighbours.merge(lat)
        p50, p99 = neighbours.percentile_s(50), neighbours.percentile_s(99)
        if p50 is not None and p99 is not None:
            out.update({"nbr_lat_p50_us": round(p50 * 1e6), "nbr_lat_p99_us": round(p99 * 1e6),
                        "nbr_lat_n": neighbours.count})
        return out

    def counters(self) -> dict[str, int]:
        return {**super().counters(), **self.link_counters()}


def _absorbed(link: str, tallies: list[LinkTally]) -> LinkTally:
    out = LinkTally(link)
    for tally in tallies:
        out.absorb(tally)
    return out
