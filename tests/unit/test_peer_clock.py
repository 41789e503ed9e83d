"""Per-host clock offsets from the routers' probe exchange, on injected clocks
(transport.peer_clock, transport.clock_sync.ClockExchange and ClockListener,
transport.clock): offsets of seconds, 100 ppm drift, delays with jitter, loss, a router
restarting, a clock step, and a process that only listens to the routers."""

from __future__ import annotations

import heapq
import itertools
import random
from dataclasses import dataclass, field

import pytest

from agents.shell.process import StatusReporter
from errors import ConfigError
from transport.bus import Received
from transport.clock import SkewedClock, clock_env, process_clock
from transport.clock_sync import (
    ClockExchange,
    ClockListener,
    format_clock_hosts,
    parse_clock_hosts,
)
from transport.codec import decode, encode
from transport.decoder import Decoder
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.message_checks import DEFAULT_LIMITS
from transport.messages import ClockProbe, FollowerState, Header, ProcessStatus, RunControl
from transport.peer_clock import (
    MAX_STEP_S,
    MIN_GAP_S,
    RELOCK_SAMPLES,
    ClockBook,
    PeerClock,
    exchange_sample,
)

pytestmark = pytest.mark.timeout(60)


def test_exchange_sample_is_exact_for_symmetric_delays() -> None:
    # Peer clock = ours + 1.3 s; 10 ms each way; the peer holds the probe 0.2 s.
    t1 = 100.0
    t2 = t1 + 0.010 + 1.3
    t3 = t2 + 0.2
    t4 = t3 - 1.3 + 0.010
    s = exchange_sample(t1, t2, t3, t4)
    assert s is not None
    assert s.offset_s == pytest.approx(1.3, abs=1e-9)
    assert s.delay_s == pytest.approx(0.020, abs=1e-9)
    assert exchange_sample(t1, t2, t3, t1 - 5.0) is None  # negative round trip: refused


@dataclass
class Host:
    """A process with a skewed clock: local(T) = T + offset + drift * T (T: true time)."""

    name: str
    offset_s: float
    drift_ppm: float
    book: ClockBook = field(default_factory=ClockBook)
    ex: ClockExchange | None = None
    epoch_true_s: float = 0.0
    routers: tuple[str, ...] = ()  # every probing host's name (the swarm's routers)

    def local(self, t: float) -> float:
        return t + self.offset_s + self.drift_ppm * 1e-6 * t

    def start(self, t: float) -> None:
        self.ex = ClockExchange(self.name, lambda: self.local(self.now), self.book, self.routers)
        self.epoch_true_s = t

    now: float = 0.0


class Net:
    """Probes every 0.25 s from every host, delivered after base + exponential jitter,
    some lost; the receiver takes its receive time when a probe arrives."""

    def __init__(self, hosts: list[Host], base_s: float = 0.010, jitter_s: float = 0.003,
                 loss: float = 0.2, seed: int = 1) -> None:
        self.hosts = {h.name: h for h in hosts}
        # Processes that only listen: name -> (their host, listener); same clock as the host.
        self.listeners: dict[str, tuple[Host, ClockListener]] = {}
        self.base_s, self.jitter_s, self.loss = base_s, jitter_s, loss
        self.rng = random.Random(seed)
        self.events: list[tuple[float, int, str, str, bytes]] = []
        self._n = 0
        for h in hosts:
            h.routers = tuple(x.name for x in hosts)
            h.start(0.0)
            self._push(self.rng.uniform(0, 0.25), "send", h.name, b"")

    def _push(self, t: float, kind: str, name: str, payload: bytes) -> None:
        self._n += 1
        heapq.heappush(self.events, (t, self._n, kind, name, payload))

    def run_until(self, t_end: float) -> None:
        while self.events and self.events[0][0] <= t_end:
            t, _, kind, name, payload = heapq.heappop(self.events)
            host = self.hosts.get(name) or self.listeners[name][0]
            host.now = t
            assert host.ex is not None
            if kind == "send":
                wire = encode(host.ex.probe())
                for other in [*self.hosts, *self.listeners]:
                    if other != name and self.rng.random() >= self.loss:
                        delay = self.base_s + self.rng.expovariate(1.0 / self.jitter_s)
                        self._push(t + delay, "recv", other, wire)
                self._push(t + 0.25, "send", name, b"")
            elif name in self.listeners:
                on, listener = self.listeners[name]
                probe = decode(payload)
                assert isinstance(probe, ClockProbe)
                listener.receive(probe, on.local(t))
            else:
                probe = decode(payload)
                assert isinstance(probe, ClockProbe)
                host.ex.receive(probe, host.local(t))

    def error_s(self, at: str, peer: str, t: float) -> float:
        """Estimated minus true offset of `peer`'s clock from `at`'s, at true time t."""
        a, p = self.hosts[at], self.hosts[peer]
        est = a.book.offset_s(f"{peer}")
        assert est is not None, f"{at} has no estimate for {peer}"
        return est - (p.local(t) - a.local(t))


def _hosts() -> list[Host]:
    return [Host("follower-0", -0.8, -100.0), Host("follower-1", 0.0, 0.0),
            Host("follower-2", 1.3, 100.0)]


def test_offsets_of_seconds_with_drift_delay_and_loss_are_found_within_2_ms() -> None:
    net = Net(_hosts())
    for t in (3.0, 30.0, 120.0):  # converged in 3 s; stays locked under 100 ppm drift
        net.run_until(t)
        for a in net.hosts:
            for p in net.hosts:
                if a != p:
                    assert abs(net.error_s(a, p, t)) < 0.002, (a, p, t)


def test_heavier_jitter_still_bounded_by_half_the_least_delay_asymmetry() -> None:
    net = Net(_hosts(), base_s=0.010, jitter_s=0.020, loss=0.4, seed=7)
    net.run_until(60.0)
    assert max(abs(net.error_s(a, p, 60.0)) for a in net.hosts for p in net.hosts
               if a != p) < 0.005


def test_a_restarted_peer_on_the_same_host_clock_stays_locked() -> None:
    net = Net(_hosts())
    net.run_until(10.0)
    peer = net.hosts["follower-2"]
    peer.now = 10.0
    peer.start(10.0)  # new epoch: a restarted router, its host's clock as before
    net.run_until(11.5)
    assert abs(net.error_s("follower-0", "follower-2", 11.5)) < 0.002
    book = net.hosts["follower-0"].book
    assert book.peers["follower-2"].resets == 1 and not book.dropped


def test_a_clock_step_is_followed_in_bounded_steps() -> None:
    net = Net(_hosts(), loss=0.0)
    net.run_until(10.0)
    net.hosts["follower-1"].offset_s += 0.5  # e.g. NTP stepped the host clock
    book = net.hosts["follower-0"].book
    seen = [book.offset_s("follower-1") or 0.0]
    t = 10.0
    while t < 20.0:  # 0.5 s / MAX_STEP_S = 10 runs of RELOCK_SAMPLES probes at 4 Hz: 7.5 s
        t += 0.05
        net.run_until(t)
        seen.append(book.offset_s("follower-1") or 0.0)
    assert max(abs(b - a) for a, b in itertools.pairwise(seen)) <= MAX_STEP_S + 1e-3
    assert abs(net.error_s("follower-0", "follower-1", 20.0)) < 0.002
    assert book.dropped["step"] >= 10 * RELOCK_SAMPLES - 3


def _probe(sender: str, epoch_s: float, stamp_s: float,
           echoes: tuple[tuple[str, float, float], ...]) -> ClockProbe:
    return ClockProbe(Header(sender, 0, stamp_s), epoch_s, echoes)


def test_forged_probes_move_an_estimate_by_at_most_the_bound_and_are_counted() -> None:
    book = ClockBook()
    listener = ClockListener("router-0", book, ["router-0", "router-1"])
    t = 100.0
    for _ in range(8):  # router-1 is 1.0 s ahead, 2 ms round trip
        listener.receive(_probe("router-1", 5.0, t + 1.001, (("router-0", t - 0.001, t + 1.0),)),
                         t + 0.001)
        t += 0.25
    assert book.offset_s("router-1") == pytest.approx(1.0, abs=1e-3)
    # A forger with a router's certificate: probes as router-1 claiming +4 s, new epochs,
    # zero delay (it would win the least-delay filter), a hundred a second.
    for k in range(400):
        listener.receive(_probe("router-1", 6.0 + k, t + 4.0, (("router-0", t, t + 4.0),)), t)
        t += 0.01
    moved = (book.offset_s("router-1") or 0.0) - 1.0
    assert 0.0 <= moved <= MAX_STEP_S * 400 * 0.01 / (MIN_GAP_S * RELOCK_SAMPLES) + 1e-9
    assert book.dropped["rate"] > 300 and book.dropped["step"] > 0
    # Made-up routers and echoes of somebody else are never a clock.
    listener.receive(_probe("router-7", 1.0, t, (("router-0", t, t),)), t)
    listener.receive(_probe("follower-0", 1.0, t, (("router-0", t, t),)), t)
    assert set(book.peers) == {"router-1"} and book.dropped["sender"] == 2
    assert book.counters()["clock_probes_dropped_sender"] == 2


def test_a_listening_process_learns_the_other_hosts_from_the_routers_probes() -> None:
    routers = [Host("router-0", -0.8, -100.0), Host("router-1", 0.0, 0.0),
               Host("router-2", 1.3, 100.0)]
    net = Net(routers, jitter_s=0.005, seed=3)
    book = ClockBook()
    book.set_hosts(parse_clock_hosts("sim-0,launcher-0;follower-0;follower-1,follower-2"))
    listener = ClockListener("router-0", book, [r.name for r in routers])
    net.listeners["follower-9"] = (routers[0], listener)
    for t in (3.0, 60.0):
        net.run_until(t)
        for peer in ("router-1", "router-2"):
            truth = net.hosts[peer].local(t) - routers[0].local(t)
            est = book.offset_s(peer)
            assert est is not None and abs(est - truth) < 0.002, (peer, t)
    assert "router-0" not in book.peers  # our own host's clock: never estimated
    assert book.offset_s("sim-0") is None  # a sender on our host: same clock
    assert book.offset_s("follower-2") == book.offset_s("router-2")
    ahead_s = routers[2].local(60.0) - routers[0].local(60.0)  # 2.1 s and 12 ms of drift
    moved = book.to_local(_state(101.3))  # follower-2, on host 2
    assert abs(moved.header.stamp_s - (101.3 - ahead_s)) < 0.002
    # A restarted router is heard on at once by the listener too.
    routers[2].now = 60.0
    routers[2].start(60.0)
    net.run_until(61.5)
    truth = routers[2].local(61.5) - routers[0].local(61.5)
    assert abs((book.offset_s("follower-2") or 0.0) - truth) < 0.002


def test_clock_hosts_argument_round_trips_and_refuses_a_sender_twice() -> None:
    spec = format_clock_hosts([["launcher-0", "sim-0"], [], ["follower-0"]])
    assert parse_clock_hosts(spec) == {"launcher-0": "router-0", "sim-0": "router-0",
                                       "follower-0": "router-2"}
    with pytest.raises(ConfigError, match="clock-hosts"):
        parse_clock_hosts("follower-0;follower-0")
    with pytest.raises(ConfigError, match="clock-hosts"):
        parse_clock_hosts("sim")


def test_peer_clock_prefers_the_least_delayed_sample_of_its_window() -> None:
    clock = PeerClock(window_s=8.0)
    for k, (offset, delay) in enumerate([(1.010, 0.02), (1.001, 0.002), (1.015, 0.03)]):
        s = exchange_sample(0.0, offset + delay / 2, offset + delay / 2, delay)
        assert s is not None
        clock.add(type(s)(offset, delay, float(k)))
    assert clock.offset_s == pytest.approx(1.001)


def _state(stamp_s: float) -> FollowerState:
    z = (0.0, 0.0)
    return FollowerState(Header("follower-2", 0, stamp_s), 2, z, z, z, z, z, stamp_s - 0.01)


def test_book_maps_every_stamp_of_a_message_onto_our_clock() -> None:
    book = ClockBook()
    s = exchange_sample(0.0, 1.3 + 0.01, 1.3 + 0.01, 0.02)
    assert s is not None
    book.add("follower-2", 0.0, s)
    moved = book.to_local(_state(101.3))
    assert isinstance(moved, FollowerState)
    assert moved.header.stamp_s == pytest.approx(100.0)
    assert moved.vehicle_stamp_s == pytest.approx(99.99)
    word = RunControl(Header("follower-2", 0, 101.3), "start", 102.3, 10.0)
    assert book.to_local(word).start_stamp_s == pytest.approx(101.0)  # type: ignore[union-attr]
    assert book.to_local(_state(5.0)) != _state(5.0)
    other = FollowerState(Header("follower-1", 0, 7.0), 1, *((0.0, 0.0),) * 5, 7.0)
    assert book.to_local(other) == other  # no estimate: same clock


def test_decoder_maps_before_it_checks_a_state_stamped_seconds_ahead() -> None:
    key = "enclose/s/follower/2/state"
    wire = encode(_state(101.3))
    plain = Decoder(limits=DEFAULT_LIMITS, clocks=ClockBook())
    assert plain.decode(Received(key, wire, 100.0)) is None  # 1.3 s "in the future"
    book = ClockBook()
    s = exchange_sample(0.0, 1.31, 1.31, 0.02)
    assert s is not None
    book.add("follower-2", 0.0, s)
    inbound = Decoder(limits=DEFAULT_LIMITS, clocks=book).decode(Received(key, wire, 100.0))
    assert inbound is not None and inbound.message.header.stamp_s == pytest.approx(100.0)


def test_probe_round_trips_through_the_codec() -> None:
    probe = ClockProbe(Header("sim-0", 3, 12.5), 1.0, (("follower-0", 11.0, 12.4),))
    assert decode(encode(probe)) == probe


def test_process_clock_from_the_environment() -> None:
    assert process_clock({}) is not None
    clock = process_clock(clock_env(1.3, 100.0))
    assert isinstance(clock, SkewedClock) and clock.offset_s == 1.3
    skew = SkewedClock(-0.8, 100.0, base=lambda: 1010.0, origin_s=1000.0)
    assert skew() == pytest.approx(1010.0 - 0.8 + 10.0 * 1e-4)
    with pytest.raises(ConfigError, match="ENCLOSE_CLOCK_OFFSET_S"):
        process_clock({"ENCLOSE_CLOCK_OFFSET_S": "soon"})
    with pytest.raises(ConfigError, match="ENCLOSE_CLOCK_DRIFT_PPM"):
        process_clock({"ENCLOSE_CLOCK_DRIFT_PPM": "5000"})


def test_dropped_probes_are_in_the_process_status_counters() -> None:
    hub = MemoryHub()
    book = ClockBook()
    ClockListener("router-0", book, ["router-0", "router-1"]).receive(
        _probe("router-9", 1.0, 5.0, ()), 5.0)
    keys = SwarmKeys("t")
    with MemoryBus(hub, "a") as bus, MemoryBus(hub, "b") as other:
        sub = other.subscribe(keys.all_status())
        StatusReporter(bus, keys, "follower", 1, clocks=book).set("running")
        (rec,) = sub.drain()
    status = decode(rec.payload)
    assert isinstance(status, ProcessStatus)
    assert status.counters["clock_probes_dropped_sender"] == 1
