"""An insider on the MAVLink side: a real process holding vehicle 3's key (what follower 2's
host gets) attacks a real simulator whose vehicle 1 an agent is flying.

It sends signed force-disarm, NAV_LAND and velocity setpoints to vehicles 1 and 2 every
0.2 s, a frame to its own vehicle stamped an hour ahead, and floods the agent's MAVLink
port with 60 KB datagrams of badly signed frames (6 MB/s).  Vehicle 1 flies on, armed and
in offboard; no other vehicle answers the insider; every frame is refused and counted
(by the simulator as signed with vehicle 3's key); its own vehicle still takes a true
stamp after the future one.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from agents.mavlink.adapter import AdapterConfig, MavlinkAdapter
from agents.mavlink.signing_keys import vehicle_key, write_key, write_raw_key
from agents.mavlink.startup import StartupTimeouts, start_offboard
from tests.integration.sim_process import start_sim

pytestmark = [pytest.mark.integration, pytest.mark.timeout(90)]
ATTACK_S = 6.0
FLOOD_DPS, FLOOD_SIZE = 100, 60_000


def sim_counters(output: str) -> dict[str, int]:
    """The simulator's closing "sim stopped:" line as {counter: value}."""
    for line in output.splitlines():
        if line.startswith("sim stopped:"):
            pairs = (item.split("=", 1) for item in line.split(":", 1)[1].split())
            return {k: int(float(v)) for k, v in pairs}
    raise AssertionError(f"no 'sim stopped:' line in:\n{output[-2000:]}")


def test_an_insider_with_one_vehicles_key_moves_no_other_vehicle(tmp_path: Path) -> None:
    secret = write_key(tmp_path / "secret.bin")
    write_raw_key(tmp_path / "v3.bin", vehicle_key(secret, 3))
    sim = start_sim("--signing-secret", str(tmp_path / "secret.bin"), vehicles=3)
    cfg = AdapterConfig(local_port=sim.send_base, remote_port=sim.listen_base, target_sysid=1,
                        signing_key=vehicle_key(secret, 1), signing_link_id=0)
    ad = MavlinkAdapter(cfg).open()
    report_path = tmp_path / "insider.json"
    rogue: subprocess.Popen[bytes] | None = None
    try:
        start_offboard(ad, 2.0, StartupTimeouts(heartbeat_s=10.0, takeoff_s=15.0))
        rogue = subprocess.Popen(
            [sys.executable, "-m", "tests.integration.mav_insider", "--seconds", str(ATTACK_S),
             "--out", str(report_path), "--key", str(tmp_path / "v3.bin"), "--own-sysid", "3",
             "--vehicle-port", str(sim.listen_base), "--vehicles", "3",
             "--flood-port", str(sim.send_base), "--flood-dps", str(FLOOD_DPS),
             "--flood-size", str(FLOOD_SIZE)])
        seen = []
        deadline = time.monotonic() + ATTACK_S + 20.0
        while rogue.poll() is None:
            assert time.monotonic() < deadline, "the insider did not finish"
            ad.send_velocity_enu((0.5, 0.0, 0.0))
            state = ad.poll()
            seen.append((state.armed, state.mode, state.link_ok))
            ad.wait_readable(0.02)
        assert rogue.returncode == 0
    finally:
        if rogue is not None and rogue.poll() is None:
            rogue.kill()
            rogue.wait(5)
        ad.close()
        sim.stop()
    rep = json.loads(report_path.read_text())
    # Vehicle 1 flew on, armed and in offboard, its telemetry heard, all the while.
    assert len(seen) > 100 and set(seen) == {(True, "OFFBOARD", True)}, set(seen)
    # No vehicle but its own answered the insider; its own took a true stamp after the
    # future one (the stream was not moved by it).
    assert rep["signed_sent_to_others"] > 150 and rep.get("acks_others", 0) == 0
    assert rep["future_sent"] == 1 and rep.get("acks_own", 0) >= 1
    c = sim_counters(sim.output())
    assert c["signing_rejected_wrong_key"] == rep["signed_sent_to_others"]
    assert c["signing_wrong_key_vehicle_3"] == rep["signed_sent_to_others"]
    assert c["signing_rejected_future"] == 1
    # The flood: each datagram the agent read was refused by its first frame, unparsed;
    # the kernel's count shows what it dropped unread.
    sent = rep["flood_sent"] - rep["flood_errors"]
    assert sent >= 0.8 * FLOOD_DPS * ATTACK_S
    refused = ad.counters["signing_rejected_bad_signature"]
    assert refused > 0 and ad.counters["bad_packets"] == 0, ad.counters
    assert 0.8 * sent <= refused + ad.counters["mav_kernel_drops"] <= sent, ad.counters
