"""Receiver-side impairment on the in-memory bus with a fake clock: rates, delay, seeds."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from transport.bus import Bus, Received
from transport.codec import encode
from transport.impairment import ImpairedBus, ImpairedSubscription
from transport.key_exprs import SwarmKeys
from transport.link_stats import LinkDecoder, link_of
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import FollowerState, Header, RunControl
from transport.network_schema import LinkImpairment, NetworkConfig

K = SwarmKeys("imp")
PERIOD_S = 0.02


class FakeClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


class Rig:
    """Follower `sender` publishing to follower `receiver` through an ImpairedBus."""

    def __init__(self, network: NetworkConfig, receiver: int = 1) -> None:
        self.clock, self.hub = FakeClock(), MemoryHub()
        self.tx = MemoryBus(self.hub, "tx", self.clock)
        self.bus = ImpairedBus(MemoryBus(self.hub, "rx", self.clock), network, receiver)

    def pump(self, sub: ImpairedSubscription, key: str, count: int,
             drain_every_s: float = PERIOD_S) -> list[Received]:
        """Publish `count` numbered payloads every PERIOD_S, draining every `drain_every_s`."""
        out: list[Received] = []
        next_put = self.clock.t
        k = 0
        while k < count or self.clock.t < next_put + 2.0:
            if k < count and self.clock.t >= next_put - 1e-12:
                self.tx.publish(key, str(k).encode())
                k, next_put = k + 1, next_put + PERIOD_S
            out += sub.drain()
            self.clock.t += drain_every_s
        return out

    def close(self) -> None:
        self.tx.close()
        self.bus.close()


def net(seed: int = 7, **spec: float | str) -> NetworkConfig:
    return NetworkConfig(default=LinkImpairment(**spec), seed=seed)  # type: ignore[arg-type]


def seqs(received: list[Received]) -> list[int]:
    return [int(r.payload) for r in received]


def run_link(network: NetworkConfig, count: int, sender: int = 0, receiver: int = 1,
             drain_every_s: float = PERIOD_S) -> tuple[list[Received], ImpairedBus]:
    rig = Rig(network, receiver)
    sub = rig.bus.subscribe(K.follower_state(sender))
    out = rig.pump(sub, K.follower_state(sender), count, drain_every_s)
    rig.close()
    return out, rig.bus


def burst_lengths(delivered: set[int], count: int) -> list[int]:
    runs, run = [], 0
    for k in range(count):
        if k in delivered:
            if run:
                runs.append(run)
            run = 0
        else:
            run += 1
    return runs + ([run] if run else [])


def test_is_a_bus() -> None:
    rig = Rig(net())
    bus: Bus = rig.bus
    assert bus.now_s() == rig.clock.t
    rig.close()


@pytest.mark.timeout(30)
def test_identity_passes_everything_unchanged_and_in_order() -> None:
    rig = Rig(NetworkConfig())
    plain = MemoryBus(rig.hub, "plain", rig.clock)
    impaired = rig.bus.subscribe(K.all_follower_states())
    reference = plain.subscribe(K.all_follower_states())
    for k in range(500):
        rig.tx.publish(K.follower_state(k % 3), str(k).encode())
        rig.clock.t += 0.001
        if k % 7 == 0:
            assert impaired.drain() == reference.drain()
    assert impaired.drain() == reference.drain()
    assert not rig.bus.impaired
    stats = rig.bus.stats()
    assert stats["f0"].offered == stats["f0"].delivered == 167 and stats["f0"].dropped == 0
    assert "f1" not in stats  # follower 1 is the receiver: hearing itself is no link
    plain.close()
    rig.close()


@pytest.mark.timeout(60)
def test_same_seed_same_fate_whatever_the_other_links_and_settings() -> None:
    base, _ = run_link(net(seed=3, loss=0.3), 2000)
    again, _ = run_link(net(seed=3, loss=0.3), 2000)
    other_seed, _ = run_link(net(seed=4, loss=0.3), 2000)
    assert seqs(base) == seqs(again)
    assert seqs(base) != seqs(other_seed)
    # Jitter and duplication change when and how often, never which messages get through.
    noisy, _ = run_link(net(seed=3, loss=0.3, jitter_ms=5.0, duplicate=0.2), 2000)
    assert sorted(set(seqs(noisy))) == seqs(base)
    # Traffic on another link into the same receiver takes nothing from this one's draws.
    rig = Rig(net(seed=3, loss=0.3))
    sub = rig.bus.subscribe(K.follower_state(0))
    other = rig.bus.subscribe(K.follower_state(2))
    for _ in range(300):
        rig.tx.publish(K.follower_state(2), b"0")
        other.drain()
    mixed = rig.pump(sub, K.follower_state(0), 2000)
    rig.close()
    assert seqs(mixed) == seqs(base)


@pytest.mark.timeout(60)
def test_independent_loss_matches_the_configured_rate() -> None:
    count = 20_000
    out, bus = run_link(net(loss=0.2), count)
    loss = 1.0 - len(out) / count
    assert abs(loss - 0.2) < 0.015
    counts = bus.stats()["f0"]
    assert counts.offered == count and counts.dropped == count - len(out)
    runs = burst_lengths(set(seqs(out)), count)
    assert float(np.mean(runs)) == pytest.approx(1.25, abs=0.1)  # 1 / (1 - loss)


@pytest.mark.timeout(60)
def test_gilbert_elliott_loss_rate_and_burst_length() -> None:
    count = 40_000
    out, _ = run_link(net(loss=0.2, loss_model="gilbert_elliott", burst_len=4.0), count)
    assert abs((1.0 - len(out) / count) - 0.2) < 0.015
    runs = burst_lengths(set(seqs(out)), count)
    assert float(np.mean(runs)) == pytest.approx(4.0, rel=0.1)


@pytest.mark.timeout(60)
def test_delay_and_jitter_statistics() -> None:
    out, _ = run_link(net(delay_ms=50.0, jitter_ms=10.0), 5000, drain_every_s=0.0005)
    delay_ms = np.array([1000.0 * (r.recv_stamp_s - (r.hlc_stamp_s or 0.0)) for r in out])
    assert len(out) == 5000
    # Handed out at the first drain at or after the release: up to 0.5 ms late.
    assert float(delay_ms.mean()) == pytest.approx(50.25, abs=0.6)
    assert float(delay_ms.std()) == pytest.approx(10.0, abs=0.6)
    assert delay_ms.min() >= 0.0
    # Jitter of half a period reorders some messages on its own.
    order = seqs(out)
    assert sum(b < a for a, b in itertools.pairwise(order)) > 50


@pytest.mark.timeout(30)
def test_delay_counts_from_arrival_not_from_a_late_drain() -> None:
    rig = Rig(net(delay_ms=50.0))
    sub = rig.bus.subscribe(K.follower_state(0))
    rig.tx.publish(K.follower_state(0), b"0")
    rig.clock.t += 0.015  # the loop drains late
    assert sub.drain() == []
    rig.clock.t += 0.034
    assert sub.drain() == []
    rig.clock.t += 0.001
    got = sub.drain()
    assert seqs(got) == [0] and got[0].recv_stamp_s == rig.clock.t
    rig.close()


@pytest.mark.timeout(60)
def test_duplication_rate() -> None:
    count = 20_000
    out, bus = run_link(net(duplicate=0.1), count)
    counts = bus.stats()["f0"]
    assert counts.duplicated / count == pytest.approx(0.1, abs=0.015)
    assert len(out) == counts.delivered == count + counts.duplicated
    assert sorted(set(seqs(out))) == list(range(count))


@pytest.mark.timeout(60)
def test_reordering_rate_and_each_held_message_comes_after_a_later_one() -> None:
    count = 20_000
    out, bus = run_link(net(reorder=0.1), count)
    order = seqs(out)
    assert sorted(order) == list(range(count))
    late = sum(s < m for s, m in zip(order[1:], np.maximum.accumulate(order)[:-1], strict=True))
    counts = bus.stats()["f0"]
    assert late == counts.reordered
    assert counts.reordered / count == pytest.approx(0.1, abs=0.015)


@pytest.mark.timeout(30)
def test_control_status_and_truth_are_never_impaired() -> None:
    rig = Rig(net(loss=0.9, delay_ms=500.0, reorder=0.5))
    sub = rig.bus.subscribe(K.everything())
    keys = [K.control(), K.status("sim", 0), K.truth(), K.status("follower", 3)]
    for k in range(400):
        rig.tx.publish(keys[k % 4], str(k).encode())
    assert seqs(sub.drain()) == list(range(400))
    assert rig.bus.stats() == {}
    assert [link_of(k) for k in keys] == [None] * 4
    rig.close()


@pytest.mark.timeout(60)
def test_per_link_overrides_and_the_sensor_link() -> None:
    network = NetworkConfig(default=LinkImpairment(loss=0.3),
                            links=((0, 2, LinkImpairment()), (1, 2, LinkImpairment(loss=0.6))))
    rig = Rig(network, receiver=2)
    subs = [rig.bus.subscribe(K.follower_state(j)) for j in (0, 1, 3)]
    sensor = rig.bus.subscribe(K.sensor_targets(2))
    got = {name: 0 for name in ("f0", "f1", "f3", "sensor")}
    for _ in range(5000):
        for j in (0, 1, 3):
            rig.tx.publish(K.follower_state(j), b"0")
        rig.tx.publish(K.sensor_targets(2), b"0")
        for name, sub in zip(got, [*subs, sensor], strict=True):
            got[name] += len(sub.drain())
    rig.close()
    assert got["f0"] == 5000
    assert got["f1"] / 5000 == pytest.approx(0.4, abs=0.03)
    assert got["f3"] / 5000 == pytest.approx(0.7, abs=0.03)
    assert got["sensor"] / 5000 == pytest.approx(0.7, abs=0.03)
    assert rig.bus.counters()["imp_dropped_f0"] == 0
    assert rig.bus.counters()["imp_offered_sensor"] == 5000


@pytest.mark.timeout(30)
def test_held_messages_are_bounded_but_not_by_a_small_receive_queue() -> None:
    """In flight is not queued: a receive queue of 10 still lets 1 s of delay through, and
    what is held is bounded (by DEFAULT_CAPACITY), the oldest going first."""
    from transport.bus import DEFAULT_CAPACITY
    rig = Rig(net(delay_ms=1000.0))
    sub = rig.bus.subscribe(K.follower_state(0), capacity=10)
    total = DEFAULT_CAPACITY + 20
    for k in range(total):
        rig.tx.publish(K.follower_state(0), str(k).encode())
        sub.drain()
    rig.clock.t += 2.0
    assert seqs(sub.drain()) == list(range(20, total))
    assert rig.bus.stats()["f0"].overflow == 20
    rig.close()


def state(j: int, seq: int, stamp_s: float) -> bytes:
    z = (0.0, 0.0)
    return encode(FollowerState(Header(f"follower-{j}", seq, stamp_s), j, z, z, z, z, z, 0.0))


@pytest.mark.timeout(30)
def test_link_decoder_counts_unique_messages_and_their_age() -> None:
    rig = Rig(net(delay_ms=40.0, duplicate=0.5))
    sub = rig.bus.subscribe(K.follower_state(0))
    decoder = LinkDecoder()
    for k in range(1100):
        if k < 1000:
            rig.tx.publish(K.follower_state(0), state(0, k, rig.clock.t - 0.01))
        rig.clock.t += 0.001
        decoder.drain(sub)
    rig.close()
    c = decoder.counters()
    assert c["rx_f0"] == 1000 and c["seq_first_f0"] == 0 and c["seq_last_f0"] == 999
    assert c["rx_dup_f0"] == rig.bus.stats()["f0"].duplicated > 300
    # Stamped 10 ms before publishing, 40 ms delay, handed out within 1 ms of release.
    assert 50_000 <= c["age_p50_us_f0"] <= 51_100
    assert 50_000 <= c["age_p99_us_f0"] <= 51_100
    assert c["accepted"] == 1000 + c["rx_dup_f0"]


@pytest.mark.timeout(30)
def test_link_decoder_ages_leave_out_the_start_up_backlog() -> None:
    rig = Rig(NetworkConfig())
    subs = [rig.bus.subscribe(K.follower_state(0)), rig.bus.subscribe(K.control())]
    decoder = LinkDecoder()
    start_s = rig.clock.t + 1.0
    for k in range(100):  # queued while the process was taking off: 5 s old when drained
        rig.tx.publish(K.follower_state(0), state(0, k, rig.clock.t - 5.0))
    rig.tx.publish(K.control(), encode(RunControl(Header("l", 0, rig.clock.t), "start",
                                                  start_s, 10.0)))
    for sub in subs:
        decoder.drain(sub)
    rig.clock.t = start_s + 0.01
    for k in range(100, 200):
        rig.tx.publish(K.follower_state(0), state(0, k, rig.clock.t - 0.002))
        decoder.drain(subs[0])
    rig.close()
    c = decoder.counters()
    assert c["rx_f0"] == 200 and c["seq_first_f0"] == 0
    assert 1900 <= c["age_p50_us_f0"] <= c["age_p99_us_f0"] <= 2100  # 100 µs bins


@pytest.mark.timeout(30)
def test_link_decoder_keeps_its_ages_over_repeated_start_words() -> None:
    """The launcher repeats the start word each second: the ages (and their running sum, for
    the mean age between two status messages) must cover the run, not the last second."""
    rig = Rig(NetworkConfig())
    subs = [rig.bus.subscribe(K.control()), rig.bus.subscribe(K.follower_state(0))]
    decoder = LinkDecoder()
    start_s = rig.clock.t
    for k in range(100):
        rig.clock.t += 0.02
        if k % 50 == 0:  # the same start word again
            rig.tx.publish(K.control(), encode(RunControl(Header("l", k, rig.clock.t), "start",
                                                          start_s, 10.0)))
        rig.tx.publish(K.follower_state(0), state(0, k, rig.clock.t - 0.002))
        for sub in subs:
            decoder.drain(sub)
    rig.close()
    c = decoder.counters()
    assert c["age_n_f0"] == 100
    assert c["age_sum_us_f0"] == pytest.approx(100 * 2000, rel=0.05)


@pytest.mark.timeout(30)
def test_a_backlog_drained_late_comes_out_at_once_and_in_order() -> None:
    rig = Rig(net(delay_ms=50.0))
    sub = rig.bus.subscribe(K.follower_state(0))
    for k in range(150):  # 3 s of traffic while the loop is busy elsewhere
        rig.tx.publish(K.follower_state(0), str(k).encode())
        rig.clock.t += PERIOD_S
    first = seqs(sub.drain())
    assert first == list(range(148))  # the last 2 arrived less than 50 ms ago
    rig.clock.t += 0.05
    assert seqs(sub.drain()) == [148, 149]
    rig.close()
