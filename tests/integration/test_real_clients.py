"""Real third-party MAVLink clients (from PyPI) fly a real `enclose sim` process.

MAVSDK (PX4 flavour), MAVProxy and dronekit (ArduPilot flavour) each connect, arm, take off
and fly; the simulator's closing per-message counts prove nothing they sent went unanswered.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time
from functools import partial
from pathlib import Path

import pytest

from tests.integration import runs
from tests.integration.sim_process import assert_all_answered, start_sim

pytestmark = [pytest.mark.integration, pytest.mark.timeout(90)]


# runs.wait_for, polled faster: client state moves at telemetry rate.
wait_for = partial(runs.wait_for, period_s=0.05)


def test_mavsdk_arms_takes_off_flies_offboard_and_lands() -> None:
    from mavsdk import ComponentType, Configuration, Mavsdk
    from mavsdk.plugins.action.action import Action
    from mavsdk.plugins.offboard.offboard import Offboard, VelocityNedYaw
    from mavsdk.plugins.telemetry.telemetry import Telemetry

    sim = start_sim()
    drone = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        drone.add_any_connection(f"udpin://127.0.0.1:{sim.send_base}")
        system = drone.first_autopilot(10.0)
        assert system is not None
        telemetry, action, offboard = Telemetry(system), Action(system), Offboard(system)
        action.arm()  # MAVSDK fills unused params with NaN: must be accepted
        action.set_takeoff_altitude(3.0)
        action.takeoff()
        wait_for(lambda: telemetry.position().relative_altitude_m > 2.7, 15.0, "take-off")
        offboard.set_velocity_ned(VelocityNedYaw(1.5, 0.0, 0.0, 0.0))
        offboard.start()
        start_n = telemetry.position_velocity_ned().position.north_m
        for _ in range(20):
            offboard.set_velocity_ned(VelocityNedYaw(1.5, 0.0, 0.0, 0.0))
            time.sleep(0.1)
        pvn = telemetry.position_velocity_ned()
        assert pvn.position.north_m - start_n > 1.5
        assert pvn.velocity.north_m_s == pytest.approx(1.5, abs=0.2)
        offboard.stop()
        action.land()
        wait_for(lambda: not telemetry.armed(), 20.0, "landed and auto-disarmed")
    finally:
        drone.destroy()
        code = sim.stop()
    assert code == 0
    outcomes = assert_all_answered(sim.output())
    assert outcomes.get("COMMAND_LONG:answered", 0) >= 4


class MavProxy:
    """MAVProxy driven through its stdin as a person would type, output collected."""

    def __init__(self, port: int) -> None:
        self.dir = tempfile.mkdtemp(prefix="enclose-mavproxy-")
        exe = str(Path(sys.executable).with_name("mavproxy.py"))
        self.proc = subprocess.Popen(
            [exe, f"--master=udpin:127.0.0.1:{port}", "--source-system=255",
             "--default-modules=param,mode,arm,cmdlong,ftp,misc,wp", "--nowait",
             f"--state-basedir={self.dir}"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            bufsize=1, env={**os.environ, "HOME": self.dir})
        self.lines: list[tuple[float, str]] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append((time.monotonic(), line.rstrip()))

    def send(self, command: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()

    def seen(self, text: str) -> float | None:
        return next((t for t, line in self.lines if text in line), None)

    def expect(self, text: str, timeout_s: float) -> float:
        wait_for(lambda: self.seen(text) is not None, timeout_s, f"MAVProxy printing {text!r}")
        return self.seen(text) or 0.0

    def stop(self) -> None:
        self.proc.terminate()  # by PID; MAVProxy may ignore SIGTERM while its threads run
        try:
            self.proc.wait(3.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(3.0)


def test_mavproxy_scripted_gets_params_switches_mode_arms_takes_off_and_flies() -> None:
    sim = start_sim("--flavour", "ardupilot")
    mp = MavProxy(sim.send_base)
    try:
        detected = mp.expect("Detected vehicle 1:1", 20.0)
        got_params = mp.expect("Received 13 parameters", 10.0)
        assert got_params - detected < 3.0  # MAVFTP is NAKed at once, no 10 s FTP timeout
        mp.send("mode GUIDED")
        mp.expect("GUIDED>", 5.0)
        mp.send("arm throttle")
        mp.expect("ARMED", 5.0)
        mp.send("takeoff 3")
        mp.expect("NAV_TAKEOFF: ACCEPTED", 5.0)
        time.sleep(3.0)  # climbing; MAVProxy has no "wait until" command
        mp.send("velocity 2 0 0")
        mp.send("status LOCAL_POSITION_NED")
        mp.expect("LOCAL_POSITION_NED {", 5.0)
        mp.lines.clear()
        time.sleep(1.0)
        mp.send("status LOCAL_POSITION_NED")
        mp.expect("LOCAL_POSITION_NED {", 5.0)
        line = next(line for _, line in mp.lines if "LOCAL_POSITION_NED {" in line)
        fields = dict(part.strip().split(" : ") for part in
                      line.split("{", 1)[1].rstrip("}").split(","))
        assert float(fields["z"]) < -2.5 and float(fields["x"]) > 0.5
        mp.send("mode LAND")
        mp.expect("LAND>", 5.0)
    finally:
        mp.stop()
        code = sim.stop()
    assert code == 0
    assert_all_answered(sim.output())


def test_mavproxy_flies_a_signing_vehicle_with_the_passphrase_enclose_gives(
        tmp_path: Path) -> None:
    """docs/sim.md's recipe: `enclose vehicle-key SECRET 2` prints vehicle 2's passphrase,
    MAVProxy's `signing key <passphrase>` makes the same key; vehicle 2 then obeys it."""
    from agents.mavlink.signing_keys import write_key
    from deploy.cli import main as enclose

    write_key(tmp_path / "secret.bin")
    printed = subprocess.run([sys.executable, "-m", "deploy.cli", "vehicle-key",
                              str(tmp_path / "secret.bin"), "2"], capture_output=True,
                             text=True, check=True).stdout.strip()
    assert enclose(["vehicle-key", str(tmp_path / "secret.bin"), "2"]) == 0
    sim = start_sim("--flavour", "ardupilot", "--signing-secret", str(tmp_path / "secret.bin"),
                    vehicles=2)
    mp = MavProxy(sim.send_base + 1)
    try:
        mp.expect("Detected vehicle 2:1", 20.0)  # HEARTBEATs: signed, read without a key
        mp.send("module load signing")
        mp.expect("Loaded module signing", 5.0)
        mp.send(f"signing key {printed}")
        mp.expect("Setup signing key", 5.0)
        mp.send("mode GUIDED")
        mp.expect("GUIDED>", 5.0)
        mp.send("arm throttle")
        mp.expect("ARMED", 5.0)
    finally:
        mp.stop()
        code = sim.stop()
    assert code == 0
    assert "signing_rejected_bad_signature" not in sim.output()


def test_dronekit_connects_ready_arms_and_flies() -> None:
    from dronekit import VehicleMode, connect

    sim = start_sim("--flavour", "ardupilot")
    vehicle = None
    try:
        vehicle = connect(f"udpin:127.0.0.1:{sim.send_base}", wait_ready=True, timeout=30,
                          heartbeat_timeout=15)
        assert vehicle.gps_0.fix_type == 3 and len(vehicle.parameters) > 5
        vehicle.mode = VehicleMode("GUIDED")
        wait_for(lambda: vehicle.mode.name == "GUIDED", 5.0, "GUIDED")
        vehicle.armed = True
        wait_for(lambda: vehicle.armed, 5.0, "armed")
        vehicle.simple_takeoff(3)
        wait_for(lambda: vehicle.location.global_relative_frame.alt > 2.7, 15.0, "take-off")
        north0 = vehicle.location.local_frame.north
        msg = vehicle.message_factory.set_position_target_local_ned_encode(
            0, 0, 0, 1, 0b0000111111000111, 0, 0, 0, 1.5, 0, 0, 0, 0, 0, 0, 0)
        for _ in range(20):
            vehicle.send_mavlink(msg)
            time.sleep(0.1)
        assert vehicle.location.local_frame.north - north0 > 1.5
        vehicle.mode = VehicleMode("LAND")
        wait_for(lambda: not vehicle.armed, 20.0, "landed and disarmed")
    finally:
        if vehicle is not None:
            vehicle.close()
        code = sim.stop()
    assert code == 0
    assert_all_answered(sim.output())
