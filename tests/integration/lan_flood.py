"""A vehicle flown by its agent while anyone on the LAN floods both ends of its MAVLink link:
garbage and 8-byte HEARTBEAT prefixes from another address (127.0.0.2: all of 127/8 is
loopback, and a socket bound there sends from another address), no key needed.

Shared by tests/integration/test_lan_flood.py and bench/bench_lan_flood.py.  `closed`:
the simulator listens on every address but hears the agent's alone (`--mav-peers`), and
the agent its vehicle's alone (AdapterConfig.connect), as `enclose host` runs them;
otherwise both hear anyone, as before issue 51.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from agents.mavlink.adapter import AdapterConfig, MavlinkAdapter
from agents.mavlink.signing_keys import vehicle_key, write_key
from agents.mavlink.startup import StartupTimeouts, start_offboard
from tests.integration.sim_process import start_sim

FLOOD_FROM = "127.0.0.2"
TICK_S = 0.02


@dataclass(frozen=True)
class FloodResult:
    seconds: float
    flood_sent: int  # datagrams the flooder sent (both ports)
    setpoints_sent: int  # by the agent while flooded
    setpoints_sent_all: int  # by the agent, the whole run (its start-up's too)
    setpoints_handled: int  # by the vehicle, the whole run
    failsafes: int  # the vehicle's
    sim_rx_datagrams: int  # what reached the vehicle's socket, the whole run
    flying: bool  # armed, in offboard and its telemetry heard at every poll
    agent_counters: dict[str, int]


def sim_counters(output: str) -> dict[str, int]:
    """The simulator's closing "sim stopped:" line as {counter: value}."""
    for line in output.splitlines():
        if line.startswith("sim stopped:"):
            pairs = (item.split("=", 1) for item in line.split(":", 1)[1].split())
            return {k: int(float(v)) for k, v in pairs}
    raise AssertionError(f"no 'sim stopped:' line in:\n{output[-2000:]}")


def fly_flooded(seconds: float, rate_dps: float, size_b: int, closed: bool = True) -> FloodResult:
    """Fly vehicle 1 at a constant velocity for `seconds` under the flood; every process
    started here is stopped here, by PID."""
    with tempfile.TemporaryDirectory(prefix="enclose-lan-flood-") as tmp:
        secret = write_key(Path(tmp) / "secret.bin")
        peers = ("--mav-peers", "127.0.0.1") if closed else ()
        sim = start_sim("--signing-secret", str(Path(tmp) / "secret.bin"), "--host", "0.0.0.0",
                        *peers, vehicles=1)
        cfg = AdapterConfig(local_port=sim.send_base, remote_port=sim.listen_base,
                            local_host="0.0.0.0", target_sysid=1, connect=closed,
                            signing_key=vehicle_key(secret, 1), signing_link_id=0)
        ad = MavlinkAdapter(cfg).open()
        report = Path(tmp) / "flood.json"
        flooder: subprocess.Popen[bytes] | None = None
        try:
            start_offboard(ad, 2.0, StartupTimeouts(heartbeat_s=10.0, takeoff_s=15.0))
            sent_before = ad.counters["setpoints_sent"]
            flooder = subprocess.Popen(
                [sys.executable, "-m", "tests.integration.mav_insider", "--seconds",
                 str(seconds), "--out", str(report), "--flood-kind", "lan", "--flood-from",
                 FLOOD_FROM, "--flood-port", str(sim.listen_base), "--flood-port",
                 str(sim.send_base), "--flood-dps", str(rate_dps), "--flood-size", str(size_b)])
            flying = True
            deadline = time.monotonic() + seconds + 20.0
            next_tick = time.monotonic()
            while flooder.poll() is None:  # a 50-Hz loop, as a follower's
                assert time.monotonic() < deadline, "the flooder did not finish"
                if time.monotonic() >= next_tick:
                    next_tick += TICK_S
                    ad.send_velocity_enu((0.5, 0.0, 0.0))
                    state = ad.poll()
                    flying &= (state.armed, state.mode, state.link_ok) == (
                        True, "OFFBOARD", True)
                time.sleep(max(0.0, min(next_tick - time.monotonic(), TICK_S)))
            assert flooder.returncode == 0
            sent_all = ad.counters["setpoints_sent"]
            sent = sent_all - sent_before
        finally:
            if flooder is not None and flooder.poll() is None:
                flooder.kill()
                flooder.wait(5)
            ad.close()
            sim.stop()
        flood = json.loads(report.read_text())
        c = sim_counters(sim.output())
        return FloodResult(seconds, int(flood["flood_sent"]), sent, sent_all,
                           c.get("setpoints", 0),
                           c.get("failsafes", 0), c.get("rx_datagrams", 0), flying,
                           dict(ad.counters))
