"""Vehicle-clock mapping, injected times: TIMESYNC lock, pause, jump, drift, reboot, fallback."""

from __future__ import annotations

import math
import random
from collections.abc import Callable

from hypothesis import given, settings
from hypothesis import strategies as st

from agents.mavlink.timemap import BootClockMap, WindowedMinOffset
from agents.mavlink.timesync import TimesyncEstimator

OFFSET_S = 1_700_000_000.0  # agent (Unix) time at the vehicle's boot


class Link:
    """A vehicle whose clock is vehicle(t) = (t - OFFSET_S) * (1 + skew) + jump(t), and a
    loopback whose one-way delays are drawn from `delay` (seeded)."""

    def __init__(self, skew: float = 0.0, seed: int = 1,
                 delay: Callable[[random.Random], float] | None = None) -> None:
        self.skew, self.jump_s, self.jump_at_s = skew, 0.0, math.inf
        self.rng = random.Random(seed)
        self.delay = delay or (lambda r: 0.0002 + r.expovariate(1 / 0.0005))

    def vehicle_s(self, t: float) -> float:
        jump = self.jump_s if t >= self.jump_at_s else 0.0
        return (t - OFFSET_S) * (1.0 + self.skew) + jump

    def true_offset(self, t: float) -> float:
        return t - self.vehicle_s(t)

    def round_trip(self, est: TimesyncEstimator | BootClockMap, t: float,
                   extra_s: float = 0.0) -> None:
        there = t + self.delay(self.rng)
        back = there + self.delay(self.rng) + extra_s
        if isinstance(est, BootClockMap):
            est.timesync_sample(t, self.vehicle_s(there), back)
        else:
            est.add(t, self.vehicle_s(there), back)


def drive(link: Link, est: TimesyncEstimator, t0: float, t1: float, hz: float = 4.0) -> float:
    t = t0
    while t < t1:
        link.round_trip(est, t)
        t += 1.0 / hz
    return t


def test_locks_in_a_few_samples_to_within_a_millisecond() -> None:
    link, est = Link(), TimesyncEstimator()
    t = OFFSET_S + 100.0
    for _ in range(3):
        link.round_trip(est, t)
        t += 0.25
    assert est.locked
    assert abs(est.offset_at(t) - link.true_offset(t)) < 1e-3


def test_round_trips_slower_than_the_limit_are_dropped_and_counted() -> None:
    link, est = Link(), TimesyncEstimator()
    t = drive(link, est, OFFSET_S + 10.0, OFFSET_S + 20.0)
    before = est.offset_at(t)
    # Our own pause: replies waited 0.5 s in the socket; they say nothing about the offset.
    for _ in range(5):
        link.round_trip(est, t, extra_s=0.5)
        t += 0.25
    assert est.counters["timesync_dropped_rtt"] == 5 and est.resets == 0
    assert abs(est.offset_at(t) - before) < 1e-4


def test_a_jump_forward_relocks_within_a_second_and_is_counted() -> None:
    link, est = Link(), TimesyncEstimator()
    link.jump_s, link.jump_at_s = 1.0, OFFSET_S + 100.0
    drive(link, est, OFFSET_S + 50.0, OFFSET_S + 100.0)
    assert est.resets == 0
    t = OFFSET_S + 100.0
    relocked = None
    while t < OFFSET_S + 110.0:
        link.round_trip(est, t)
        t += 0.25
        if relocked is None and est.locked and \
                abs(est.offset_at(t) - link.true_offset(t)) < 1e-3:
            relocked = t - (OFFSET_S + 100.0)
    assert relocked is not None and relocked <= 1.0
    assert est.resets == 1
    assert abs(est.offset_at(t) - link.true_offset(t)) < 1e-3


def test_100_ppm_drift_is_tracked() -> None:
    link, est = Link(skew=100e-6), TimesyncEstimator()
    t = drive(link, est, OFFSET_S, OFFSET_S + 120.0)
    assert est.resets == 0
    assert abs(est.offset_at(t) - link.true_offset(t)) < 3e-4
    assert abs(est.skew + 100e-6) < 30e-6  # offset = agent - vehicle shrinks by 100 us/s


def test_a_reboot_resets_the_map_and_it_relocks() -> None:
    link, tmap = Link(), BootClockMap()
    t = OFFSET_S + 300.0
    for _ in range(20):
        link.round_trip(tmap, t)
        tmap.stamp(link.vehicle_s(t), t + 0.001)
        t += 0.25
    assert tmap.timesync.locked
    link.jump_s, link.jump_at_s = -(t - OFFSET_S), t  # the vehicle's clock restarts at 0
    stamp = tmap.stamp(link.vehicle_s(t), t + 0.001)
    assert tmap.reboots == 1 and tmap.resets == 1 and not tmap.timesync.locked
    assert abs(stamp - t) < 0.002  # the fallback at once, from the first sample
    for _ in range(4):
        t += 0.25
        link.round_trip(tmap, t)
    assert tmap.timesync.locked
    assert abs(tmap.stamp(link.vehicle_s(t), t + 0.02) - t) < 1e-3


def test_without_timesync_the_windowed_minimum_forgets_a_lost_second() -> None:
    tmap = BootClockMap(window_s=2.0)
    t, boot = OFFSET_S, 0.0
    for _ in range(100):
        tmap.stamp(boot, t + 0.002)
        t, boot = t + 0.02, boot + 0.02
    boot -= 0.5  # the vehicle's clock lost half a second (an old simulator after a stall)
    stamps = []
    for _ in range(200):
        stamps.append(tmap.stamp(boot, t + 0.002) - t)
        t, boot = t + 0.02, boot + 0.02
    assert stamps[0] < -0.4  # at first stamped half a second too old ...
    assert all(abs(s) < 0.003 for s in stamps[110:])  # ... not for longer than the window
    assert tmap.reboots == 0


def test_a_stamp_is_never_after_its_receipt() -> None:
    tmap = BootClockMap()
    assert tmap.stamp(10.0, 5.0) == 5.0
    assert tmap.stamp(11.0, 5.5) <= 5.5


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(-10**12, 10**12), st.integers(-10**12, 10**12)),
                min_size=1, max_size=60))
def test_windowed_minimum_is_the_minimum_of_a_recent_window(samples: list[tuple[int, int]]) -> None:
    window = WindowedMinOffset(window_s=5.0)
    newest = -math.inf
    seen: list[tuple[float, float]] = []
    for boot_ms, rx_ms in samples:  # any order, huge jumps either way
        boot, rx = boot_ms * 1e-3, rx_ms * 1e-3
        got = window.add(boot, rx)
        newest = max(newest, rx)
        seen.append((rx, rx - boot))
        assert min(off for _, off in seen) <= got <= rx - boot
    if [rx for _, rx in samples] == sorted(rx for _, rx in samples):  # in order: exact
        assert got == min(off for r, off in seen if r >= newest - 5.0)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(-2**62, 2**62), st.integers(-2**62, 2**62),
                          st.integers(-2**62, 2**62)), max_size=40))
def test_hostile_timesync_replies_never_break_the_estimate(
        triples: list[tuple[int, int, int]]) -> None:
    est, tmap = TimesyncEstimator(), BootClockMap()
    for sent_ns, vehicle_ns, rx_ns in triples:
        est.add(sent_ns * 1e-9, vehicle_ns * 1e-9, rx_ns * 1e-9)
        tmap.timesync_sample(sent_ns * 1e-9, vehicle_ns * 1e-9, rx_ns * 1e-9)
        assert math.isfinite(est.offset_at(0.0)) and abs(est.skew) <= 1e-3
        stamp = tmap.stamp(vehicle_ns * 1e-9, rx_ns * 1e-9)
        assert math.isfinite(stamp) and stamp <= rx_ns * 1e-9


def test_kernel_arrival_stamp_ages_a_datagram_by_its_time_in_the_buffer() -> None:
    import socket
    import struct

    import pytest

    from agents.mavlink.timemap import SO_TIMESTAMPNS, kernel_arrival_s

    def stamp(wall_s: float) -> list[tuple[int, int, bytes]]:
        sec = int(wall_s)
        return [(socket.SOL_SOCKET, SO_TIMESTAMPNS,
                 struct.pack("qq", sec, round((wall_s - sec) * 1e9)))]

    wall, now = 1_800_000_000.5, 100.0
    assert kernel_arrival_s(stamp(wall - 0.3), wall, now) == pytest.approx(now - 0.3, abs=1e-6)
    assert kernel_arrival_s(stamp(wall + 5.0), wall, now) == now  # a stamp ahead: not future
    assert kernel_arrival_s([], wall, now) == now  # no stamp: read now
    assert kernel_arrival_s([(socket.SOL_SOCKET, SO_TIMESTAMPNS, b"\x00")], wall, now) == now
