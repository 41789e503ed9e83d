"""Contract: a plain pymavlink client flies a simulated vehicle like a real PX4/ArduPilot."""

from __future__ import annotations

import math
import time

import pytest

from tests.integration.sim_process import PlainClient, start_sim

pytestmark = [pytest.mark.integration, pytest.mark.timeout(60)]

OFFBOARD = 6 << 16
HOLD = (4 << 16) | (3 << 24)


def velocity(c: PlainClient, vn: float, ve: float, vd: float, mask: int = 3527) -> None:
    c.send(c.mav.set_position_target_local_ned_encode(0, c.sysid, 1, 1, mask, 0, 0, 0, vn, ve,
                                                      vd, 0, 0, 0, 0, 0))


def heartbeat_mode(c: PlainClient) -> int:
    return c.last["HEARTBEAT"].custom_mode  # type: ignore[attr-defined]


def test_px4_arm_offboard_velocity_and_failsafe() -> None:
    sim = start_sim(vehicles=2)
    client = PlainClient(sim.send_base + 1, sim.listen_base + 1, target_sysid=2)
    try:
        client.until(lambda: "HEARTBEAT" in client.last and "LOCAL_POSITION_NED" in client.last,
                     10.0, "heartbeat and position")
        hb = client.last["HEARTBEAT"]
        assert hb.autopilot == 12 and hb.get_srcSystem() == 2 and hb.get_srcComponent() == 1
        assert client.last["SYS_STATUS"].onboard_control_sensors_health & 32
        assert client.command(400, 1) == 0  # arm
        client.until(lambda: client.last["HEARTBEAT"].base_mode & 128, 2.0, "armed heartbeat")
        assert client.command(176, 1, 6, 0) == 1  # offboard refused: no setpoints yet
        start = client.last["LOCAL_POSITION_NED"]
        gps0 = client.last["GLOBAL_POSITION_INT"]
        velocity(client, 2.0, 0.0, -1.0)
        assert client.command(176, 1, 6, 0) == 0
        client.until(lambda: heartbeat_mode(client) == OFFBOARD, 2.0, "OFFBOARD heartbeat",
                     every=lambda: velocity(client, 2.0, 0.0, -1.0))
        deadline = time.monotonic() + 1.5
        client.until(lambda: time.monotonic() > deadline, 3.0, "flight",
                     every=lambda: velocity(client, 2.0, 0.0, -1.0, mask=4039))
        pos = client.last["LOCAL_POSITION_NED"]
        assert pos.x - start.x > 1.5 and abs(pos.y - start.y) < 0.1 and pos.z < -0.8
        assert pos.vx == pytest.approx(2.0, abs=0.1)
        assert client.last["GLOBAL_POSITION_INT"].lat > gps0.lat  # north
        # Failsafe: setpoints stop -> HOLD within 0.5 s (+ a heartbeat), and the vehicle stops.
        stopped = time.monotonic()
        client.until(lambda: heartbeat_mode(client) == HOLD, 2.0, "failsafe HOLD")
        assert time.monotonic() - stopped < 1.2
        client.until(lambda: math.hypot(client.last["LOCAL_POSITION_NED"].vx,
                                        client.last["LOCAL_POSITION_NED"].vy) < 0.2,
                     3.0, "vehicle stopped")
        assert client.command(21) == 0  # land
    finally:
        client.close()
        code = sim.stop()
    assert code == 0
    summary = sim.output()
    assert "sim stopped" in summary and "failsafes=1" in summary


def test_ardupilot_guided_takeoff_and_velocity() -> None:
    sim = start_sim("--flavour", "ardupilot")
    client = PlainClient(sim.send_base, sim.listen_base)
    try:
        client.until(lambda: "HEARTBEAT" in client.last, 10.0, "heartbeat")
        assert client.last["HEARTBEAT"].autopilot == 3
        assert client.command(176, 1, 4) == 0  # GUIDED
        assert client.command(400, 1) == 0
        assert client.command(22, 0, 0, 0, 0, 0, 0, 2.0) == 0
        client.until(lambda: client.last["LOCAL_POSITION_NED"].z < -1.8, 5.0, "take-off")
        assert client.last["HEARTBEAT"].custom_mode == 4
        east0 = client.last["LOCAL_POSITION_NED"].y
        deadline = time.monotonic() + 1.0
        client.until(lambda: time.monotonic() > deadline, 3.0, "flight",
                     every=lambda: velocity(client, 0.0, 1.5, 0.0))
        assert client.last["LOCAL_POSITION_NED"].y - east0 > 0.8
        # ArduPilot: setpoints stop -> stays GUIDED and stops after GUID_TIMEOUT (3 s).
        client.until(lambda: "STATUSTEXT" in client.last, 5.0, "guided timeout STATUSTEXT")
        assert b"timed out" in client.last["STATUSTEXT"].text.encode()
        client.until(lambda: abs(client.last["LOCAL_POSITION_NED"].vy) < 0.1, 2.0, "stopped")
        assert client.last["HEARTBEAT"].custom_mode == 4  # still GUIDED
    finally:
        client.close()
        assert sim.stop() == 0


def test_message_interval_request_message_and_params_over_udp() -> None:
    sim = start_sim(console_script=True)
    client = PlainClient(sim.send_base, sim.listen_base)
    try:
        client.until(lambda: "HEARTBEAT" in client.last, 10.0, "heartbeat")
        assert client.command(511, 32, 200_000) == 0  # LOCAL_POSITION_NED at 5 Hz
        assert client.command(511, 30, -1) == 0  # ATTITUDE off
        client.received.clear()
        end = time.monotonic() + 1.0
        client.until(lambda: time.monotonic() > end, 3.0, "one second of telemetry")
        assert 3 <= client.received.count("LOCAL_POSITION_NED") <= 7
        assert client.received.count("ATTITUDE") == 0
        assert client.command(512, 148) == 0
        client.until(lambda: "AUTOPILOT_VERSION" in client.last, 2.0, "AUTOPILOT_VERSION")
        assert client.command(512, 242) == 0
        client.until(lambda: "HOME_POSITION" in client.last, 2.0, "HOME_POSITION")
        assert client.last["HOME_POSITION"].latitude == round(47.397742 * 1e7)
        client.send(client.mav.param_request_read_encode(1, 1, b"COM_OF_LOSS_T", -1))
        client.until(lambda: "PARAM_VALUE" in client.last, 2.0, "PARAM_VALUE")
        assert client.last["PARAM_VALUE"].param_value == pytest.approx(0.5)
        assert client.command(31010) == 3  # UNSUPPORTED
        client.send(client.mav.command_int_encode(1, 1, 0, 400, 0, 0, 1, 0, 0, 0, 0, 0, 0))
        client.until(lambda: (400, 0) in client.acks, 2.0, "COMMAND_INT arm ACK")
    finally:
        client.close()
        assert sim.stop() == 0
