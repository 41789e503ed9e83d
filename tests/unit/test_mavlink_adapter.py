"""Adapter message handling with an injected clock: ENU state, clock mapping, link loss."""

from __future__ import annotations

import math
import socket
import time
from collections.abc import Iterator

import pytest

from agents.mavlink.adapter import AdapterConfig, MavlinkAdapter
from agents.mavlink.modes import encode_custom_mode
from agents.mavlink.offboard import OffboardKeeper
from agents.mavlink.timemap import SO_TIMESTAMPNS, BootClockMap, kernel_arrival_s
from agents.mavlink.wire import new_codec
from agents.mavlink.wire_decode import decode_datagram
from errors import LinkLostError, MavlinkError

ADDR = ("127.0.0.1", 14580)


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def feed(ad: MavlinkAdapter, msg, now: float, sysid: int = 1) -> None:
    sender = new_codec(sysid, 1)
    for m in decode_datagram(new_codec(99, 0), msg(sender).pack(sender)).messages:
        ad.handle(m, ADDR, now)


def heartbeat(mode: str = "OFFBOARD", armed: bool = True, autopilot: int = 12):
    return lambda mav: mav.heartbeat_encode(2, autopilot, 1 | (128 if armed else 0),
                                            encode_custom_mode("px4", mode), 4)


def local_pos(boot_ms: int, x: float = 1.0):
    return lambda mav: mav.local_position_ned_encode(boot_ms, x, 2.0, -3.0, 0.5, -0.5, -1.0)


def make() -> tuple[MavlinkAdapter, FakeClock]:
    clock = FakeClock()
    return MavlinkAdapter(AdapterConfig(local_port=0, target_sysid=1), clock=clock), clock


def test_heartbeat_gives_flavour_mode_and_remote() -> None:
    ad, clock = make()
    feed(ad, heartbeat(), clock.t)
    assert ad.flavour == "px4" and ad.remote == ADDR
    assert ad.state.mode == "OFFBOARD" and ad.state.armed


def test_ground_station_and_other_vehicles_ignored() -> None:
    ad, clock = make()
    feed(ad, heartbeat(autopilot=8), clock.t)  # a GCS heartbeat
    feed(ad, heartbeat(), clock.t, sysid=7)
    feed(ad, local_pos(10), clock.t, sysid=7)
    assert ad.flavour is None and not ad.state.link_ok
    assert ad.counters["ignored_other_system"] == 2


def test_position_converted_to_enu_and_stamped_on_agent_clock() -> None:
    ad, _ = make()
    feed(ad, local_pos(5000), 100.0)
    s = ad.state
    assert s.pos_enu_m == pytest.approx((2.0, 1.0, 3.0))
    assert s.vel_enu_m_s == pytest.approx((-0.5, 0.5, 1.0))
    assert s.stamp_s == pytest.approx(100.0)
    feed(ad, local_pos(5020), 100.030)  # 10 ms later than the best path: stamp is not delayed
    assert ad.state.stamp_s == pytest.approx(100.020)
    feed(ad, local_pos(5040), 100.035)  # faster path found: offset shrinks
    assert ad.state.stamp_s == pytest.approx(100.035)


def test_clock_map_resets_on_reboot() -> None:
    m = BootClockMap()
    assert m.stamp(100.0, 1000.0) == 1000.0
    assert m.stamp(0.5, 1001.0) == 1001.0
    assert m.resets == 1


def test_link_loss_after_half_a_second_without_telemetry() -> None:
    ad, clock = make()
    feed(ad, local_pos(1000), clock.t)
    assert ad.poll().link_ok
    clock.t += 0.49
    assert ad.poll().link_ok
    clock.t += 0.02
    assert not ad.poll().link_ok
    assert ad.counters["link_losses"] == 1
    with pytest.raises(LinkLostError):
        ad.check_link()
    feed(ad, local_pos(1600), clock.t)
    assert ad.poll().link_ok


def test_non_finite_telemetry_ignored() -> None:
    ad, clock = make()
    feed(ad, local_pos(1000, x=math.nan), clock.t)
    assert not ad.state.link_ok and ad.counters["ignored_nonfinite"] == 1


def test_velocity_refused_when_non_finite_or_not_connected() -> None:
    ad, clock = make()
    assert not ad.send_velocity_enu((1.0, 0.0, 0.0))
    assert ad.counters["refused_not_connected"] == 1
    feed(ad, heartbeat(), clock.t)
    assert not ad.send_velocity_enu((math.nan, 0.0, 0.0))
    assert not ad.send_velocity_enu((1.0, 0.0, 0.0), yaw_enu_rad=math.inf)
    assert ad.counters["refused_nonfinite"] == 2


def test_command_needs_a_vehicle() -> None:
    ad = MavlinkAdapter(AdapterConfig(local_port=0), clock=FakeClock())
    with pytest.raises(MavlinkError):
        ad.send_command(400, (1.0,))


def test_ack_recorded() -> None:
    ad, clock = make()
    feed(ad, heartbeat(), clock.t)
    feed(ad, lambda mav: mav.command_ack_encode(400, 0, 0, 0, 245, 191), clock.t)
    assert ad.acks[400] == 0


@pytest.mark.realtime
def test_statustext_kept_and_a_failing_handler_is_contained() -> None:
    ad, clock = make()
    feed(ad, heartbeat(), clock.t)
    before = ad.statustext_count
    feed(ad, lambda mav: mav.statustext_encode(4, b"Takeoff denied: vehicle not armed"), clock.t)
    assert ad.statustexts_since(before) == ["Takeoff denied: vehicle not armed"]
    assert ad.statustexts_since(ad.statustext_count) == []
    ad.open()
    try:
        assert ad.sock is not None
        sender = new_codec(1, 1)
        # A message the handler chokes on (patched to raise) is counted, not raised.
        ad._position = lambda fields, now: 1 / 0  # type: ignore[method-assign]
        ad.sock.sendto(local_pos(10)(sender).pack(sender), ad.sock.getsockname())
        for _ in range(100):
            ad.poll()
            if ad.counters["handler_errors"]:
                break
            ad.wait_readable(0.01)
        assert ad.counters["handler_errors"] == 1
    finally:
        ad.close()


def open_pair() -> tuple[MavlinkAdapter, FakeClock, socket.socket]:
    """An open adapter whose vehicle is a plain socket on loopback."""
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(1.0)
    clock = FakeClock()
    ad = MavlinkAdapter(AdapterConfig(local_port=0, remote_port=vehicle.getsockname()[1],
                                      target_sysid=1), clock=clock).open()
    return ad, clock, vehicle


def next_of(sock: socket.socket, kind: str):
    while True:
        for m in decode_datagram(new_codec(99, 0), sock.recv(1000)).messages:
            if m.get_type() == kind:
                return m


@pytest.mark.realtime
def test_timesync_requests_answered_and_replies_lock_the_clock_map() -> None:
    ad, clock, vehicle = open_pair()
    try:
        px4 = new_codec(1, 1)
        feed(ad, lambda mav: mav.timesync_encode(0, 555), clock.t)  # the vehicle asks us
        reply = next_of(vehicle, "TIMESYNC")
        assert reply.ts1 == 555 and reply.tc1 == round(clock.t * 1e9)
        boot_offset_s = 90.0  # agent time - vehicle boot time
        for k in range(4):
            clock.t += 0.25
            ad.poll()  # sends our request
            request = next_of(vehicle, "TIMESYNC")
            assert request.tc1 == 0
            vehicle_ns = request.ts1 - round(boot_offset_s * 1e9) + 1_000_000  # 1 ms there
            clock.t += 0.002
            answer = px4.timesync_encode(vehicle_ns, request.ts1)
            for m in decode_datagram(new_codec(99, 0), answer.pack(px4)).messages:
                ad.handle(m, ADDR, clock.t)
            if k == 0:  # a duplicated reply is not a second sample
                ad.handle(m, ADDR, clock.t)
        assert ad.clock_counters()["timesync_unmatched"] == 1
        assert ad.clock_counters()["timesync_locked"] == 1
        feed(ad, local_pos(round((clock.t - boot_offset_s) * 1000)), clock.t + 0.3)
        assert ad.state.stamp_s == pytest.approx(clock.t, abs=1e-3)  # late, yet not re-stamped
    finally:
        ad.close()
        vehicle.close()


@pytest.fixture
def kernel_stamping() -> Iterator[None]:
    """Hold receive timestamping on, and wait until the kernel really stamps on arrival.

    Linux turns stamping on through a deferred work item when the first socket asks for it;
    until that runs, a datagram is stamped when it is read. On a loaded machine that took
    long enough to fail the test below, which is about the adapter, not the kernel."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    probe.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    probe.setblocking(False)
    deadline = time.monotonic() + 20.0
    try:
        while time.monotonic() < deadline:
            probe.sendto(b"x", probe.getsockname())
            time.sleep(0.02)  # the age a stamp taken on arrival must show
            _data, anc, _flags, _addr = probe.recvmsg(16, socket.CMSG_SPACE(16))
            if kernel_arrival_s(anc, time.time(), 0.0) < -0.01:
                break
        else:
            pytest.fail("the kernel did not start stamping datagrams on arrival within 20 s")
        yield
    finally:
        probe.close()


@pytest.mark.realtime
@pytest.mark.usefixtures("kernel_stamping")
def test_queued_datagrams_are_stamped_with_their_arrival() -> None:
    ad, clock, vehicle = open_pair()
    try:
        px4 = new_codec(1, 1)
        vehicle.sendto(px4.local_position_ned_encode(1000, 0, 0, 0, 0, 0, 0).pack(px4),
                       ad.sock.getsockname())
        time.sleep(0.2)  # the datagram waits in our socket (we are "paused")
        ad.poll()
        assert clock.t - 0.5 < ad.state.stamp_s <= clock.t - 0.15
    finally:
        ad.close()
        vehicle.close()


def test_offboard_is_requested_again_after_the_failsafe_hold_only() -> None:
    ad, clock = make()
    sent: list[tuple[int, tuple[float, ...]]] = []
    ad.send_command = lambda cmd, params, confirmation=0: sent.append((cmd, params))  # type: ignore[method-assign]
    keeper = OffboardKeeper(ad, retry_s=0.5)
    feed(ad, heartbeat("OFFBOARD"), clock.t)
    feed(ad, local_pos(1000), clock.t)
    keeper.check(clock.t)
    assert sent == []
    feed(ad, heartbeat("HOLD"), clock.t)  # setpoint-loss failsafe
    keeper.check(clock.t)
    keeper.check(clock.t + 0.1)  # not before retry_s
    assert [c for c, _ in sent] == [176]
    keeper.check(clock.t + 0.6)
    assert len(sent) == 2
    feed(ad, heartbeat("OFFBOARD"), clock.t)
    keeper.check(clock.t + 0.7)
    assert keeper.recoveries == 1 and len(sent) == 2
    feed(ad, heartbeat("LAND"), clock.t)  # somebody else's choice: left alone
    keeper.check(clock.t + 2.0)
    assert len(sent) == 2


@pytest.mark.realtime
def test_a_blocking_wait_calls_the_on_wait_hook() -> None:
    """While start-up helpers block (re-arming mid-run), the process keeps its heartbeat."""
    calls: list[int] = []
    with MavlinkAdapter(AdapterConfig(local_port=0)) as ad:
        ad.on_wait = lambda: calls.append(1)
        ad.wait_readable(0.0)
        ad.wait_readable(0.0)
        ad.on_wait = None
        ad.wait_readable(0.0)
    assert len(calls) == 2


@pytest.mark.realtime
@pytest.mark.timeout(30)
def test_a_type_the_lean_dialect_lacks_is_counted_apart_from_bad_bytes() -> None:
    """A real PX4 streams BATTERY_STATUS and more: framed, not ours, not garbage."""
    ad, _clock, vehicle = open_pair()
    try:
        assert ad.sock is not None and type(ad.mav).__module__ == "agents.mavlink.lean_common"
        px4 = new_codec(1, 1)  # the full common dialect
        battery = px4.battery_status_encode(0, 0, 0, 2500, [3700] * 10, -1, -1, -1, 80)
        datagram = battery.pack(px4) + local_pos(10)(px4).pack(px4) + b"\x00junk"
        vehicle.sendto(datagram, ad.sock.getsockname())
        for _ in range(100):
            ad.poll()
            if ad.counters["unknown_types"]:
                break
            ad.wait_readable(0.01)
        assert ad.counters["unknown_types"] == 1 and ad.counters["bad_packets"] == 1
        assert ad.state.pos_enu_m == (2.0, 1.0, 3.0)  # the position beside it was read
    finally:
        ad.close()
        vehicle.close()
