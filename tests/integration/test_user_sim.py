"""A user's own tests against the simulator, as docs/simulator-ci.md shows them: pymavlink
and MAVSDK fly `enclose_sim` (the enclose.testing plugin's fixture), nothing else needed."""

from __future__ import annotations

import contextlib
import socket
import time
from collections.abc import Iterator

import pytest
from pymavlink import mavutil

import enclose
from deploy.launch.port_slots import slot_ports

# An installed enclose loads the plugin by its entry point; this line serves a source tree.
pytest_plugins = ("enclose.testing",)
pytestmark = [pytest.mark.integration, pytest.mark.timeout(90)]

ARM = mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM
ACCEPTED = mavutil.mavlink.MAV_RESULT_ACCEPTED


def arm_result(conn: mavutil.mavfile, sysid: int, timeout_s: float = 3.0) -> int | None:
    """Send ARM; the COMMAND_ACK's result, None when no answer came in time."""
    conn.mav.command_long_send(sysid, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
    ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=timeout_s)
    return None if ack is None else int(ack.result)


@pytest.mark.enclose_sim(vehicles=2)
def test_pymavlink_sees_each_vehicle_and_arms_it(enclose_sim) -> None:
    for vehicle in enclose_sim.vehicles:
        conn = mavutil.mavlink_connection(vehicle.pymavlink_address, source_system=255)
        try:
            beat = conn.wait_heartbeat(timeout=10)
            assert beat is not None and conn.target_system == vehicle.sysid
            assert beat.autopilot == mavutil.mavlink.MAV_AUTOPILOT_PX4
            assert arm_result(conn, vehicle.sysid) == ACCEPTED
            deadline = time.monotonic() + 5.0
            while not conn.motors_armed() and time.monotonic() < deadline:
                conn.recv_match(type="HEARTBEAT", blocking=True, timeout=1)
            assert conn.motors_armed()
        finally:
            conn.close()


@pytest.mark.enclose_sim(flavour="ardupilot", signing=True)
def test_signed_vehicle_answers_only_signed_commands(enclose_sim) -> None:
    vehicle = enclose_sim[0]
    conn = mavutil.mavlink_connection(vehicle.pymavlink_address, source_system=255)
    try:
        beat = conn.wait_heartbeat(timeout=10)
        assert beat is not None
        assert beat.autopilot == mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
        assert arm_result(conn, vehicle.sysid, timeout_s=1.5) is None  # unsigned: dropped
        conn.setup_signing(enclose_sim.signing_key, sign_outgoing=True)
        assert arm_result(conn, vehicle.sysid) == ACCEPTED
    finally:
        conn.close()


def test_mavsdk_takes_off(enclose_sim) -> None:
    from mavsdk import ComponentType, Configuration, Mavsdk
    from mavsdk.plugins.action.action import Action
    from mavsdk.plugins.telemetry.telemetry import Telemetry

    drone = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        drone.add_any_connection(enclose_sim[0].mavsdk_address)
        system = drone.first_autopilot(10.0)
        assert system is not None
        telemetry, action = Telemetry(system), Action(system)
        action.arm()
        action.set_takeoff_altitude(3.0)
        action.takeoff()
        deadline = time.monotonic() + 15.0
        while telemetry.position().relative_altitude_m < 2.7:
            assert time.monotonic() < deadline, "no take-off in 15 s"
            time.sleep(0.05)
    finally:
        drone.destroy()


FIRST_BLOCK = slot_ports(0)


@pytest.fixture
def first_block_held() -> Iterator[int]:
    """A UDP socket on the first port block, as a connection a failed test's traceback
    keeps open holds one; the port (already held by some other process: as good)."""
    port = FIRST_BLOCK.start
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        with contextlib.suppress(OSError):  # held already: as good
            sock.bind(("127.0.0.1", port))
        yield port


@pytest.mark.enclose_swarm(duration_s=5.0)
def test_both_fixtures_take_the_next_block_when_a_port_is_held(
        first_block_held: int, enclose_sim, enclose_swarm: enclose.Run) -> None:
    vehicle = enclose_sim[0]
    assert first_block_held not in (vehicle.listen_port, vehicle.send_port)
    conn = mavutil.mavlink_connection(vehicle.pymavlink_address, source_system=255)
    try:
        assert conn.wait_heartbeat(timeout=10) is not None
    finally:
        conn.close()
    run = enclose_swarm
    assert run.exit_code == 0 and run.verdict.error is None, run.verdict.processes
    assert run.launch["vehicle_base_port"] not in FIRST_BLOCK
    # each in a block of its own: the simulator's slot stays held while the run flies
    flown = range(run.launch["vehicle_base_port"], run.launch["adapter_base_port"] + 6)
    assert vehicle.listen_port not in flown and vehicle.send_port not in flown


USER_TEST = '''
from pymavlink import mavutil


def test_heartbeat(enclose_sim):
    conn = mavutil.mavlink_connection(enclose_sim[0].pymavlink_address, source_system=255)
    assert conn.wait_heartbeat(timeout=10) is not None
    conn.close()
'''


def test_plugin_loads_by_its_entry_point_alone(tmp_path) -> None:
    """A user's project: a test file with no plugin line, the plugin found by its pytest11
    entry point (declared here by a distribution's metadata, as pip installs it)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    dist = tmp_path / "site" / "enclose_probe-0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: enclose-probe\nVersion: 0\n")
    (dist / "entry_points.txt").write_text("[pytest11]\nenclose.testing = enclose.testing\n")
    project = tmp_path / "project"
    project.mkdir()
    (project / "test_mine.py").write_text(USER_TEST)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path / "site"), str(root)])}
    env.pop("PYTEST_ADDOPTS", None)
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_mine.py"],
        cwd=project, env=env, capture_output=True, text=True, timeout=80)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert "1 passed" in proc.stdout
