"""Issue #12's attack against a default `enclose run`, by a rogue process of its own.

During the run the rogue (tests/integration/rogue.py) sends unsigned force-disarm and
NAV_LAND to every vehicle every 0.2 s, publishes forged follower states from a Zenoh peer
without credentials, and -- holding follower 0's own certificate -- throws random and
mutated payloads at follower 0's state key and forged states at follower 1's.
Nothing changes: the paper's bounds hold, and every hostile input read is refused and
counted.

The insider's fuzz is 10^5 payloads (about 5500 per second over 18 s; ROGUE_FUZZ sets
another count).  With a follower's queue per peer as large as the recorder's, this flood
broke the formation on 2 cores (estimator error 0.12 m, angle error 0.067: every neighbour
decoded every payload each tick); with a queue of 8 per peer it holds (0.016 m, 0.0015).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from deploy.launch.run_secrets import MAVLINK_SECRET_FILE
from tests.integration.real_time import judged
from tests.integration.runs import spawned_run, wait_for

pytestmark = pytest.mark.integration
DURATION_S = 24.0
FUZZ_COUNT = int(os.environ.get("ROGUE_FUZZ", "100000"))
ATTACK_S = DURATION_S - 4.0  # from the start on: it ends while the swarm still runs
STARTED = re.compile(r"swarm (\S+); Zenoh rendezvous (\S+); vehicles on UDP 127\.0\.0\.1:(\d+)\+; "
                     r"agents on UDP 127\.0\.0\.1:(\d+)")


def drops(counters: dict[str, int]) -> int:
    """Payloads a decoder refused (codec reasons, key mismatch, failed checks)."""
    return sum(v for k, v in counters.items() if k.startswith("drop_"))


@pytest.mark.serial  # the rogue floods the machine beside a swarm held to the bounds
@pytest.mark.xdist_group("timed-a")
@pytest.mark.timeout(240)
def test_attack_changes_nothing_and_every_hostile_input_is_counted(tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = [sys.executable, "-m", "deploy.cli", "run", "--out", str(out), "--link-timeout",
            "60", "--duration", str(DURATION_S)]
    with spawned_run(argv, out) as launcher:
        assert launcher.stdout is not None
        lines = []
        for line in launcher.stdout:
            lines.append(line)
            if (m := STARTED.search(line)) is not None:
                break
        else:
            pytest.fail("".join(lines))
        swarm, endpoint, vehicle_port = m.group(1), m.group(2), int(m.group(3))
        agent_port = int(m.group(4))
        ident = out / "credentials" / "follower-0.json"
        # The launcher names its ports before it makes the run's credentials: the rogue
        # reads an identity, so wait for the set (the MAVLink secret comes after every
        # identity is written).
        wait_for((out / "credentials" / MAVLINK_SECRET_FILE).exists, 60, "the credentials")
        report_path = tmp_path / "rogue.json"
        rogue = subprocess.run(
            [sys.executable, "-m", "tests.integration.rogue", "--vehicle-port",
             str(vehicle_port), "--agent-port", str(agent_port), "--vehicles", "6",
             "--endpoint", endpoint, "--swarm", swarm,
             "--followers", "4", "--fuzz-identity", str(ident), "--fuzz-count",
             str(FUZZ_COUNT), "--seconds", str(ATTACK_S), "--out", str(report_path),
             "--progress", str(out / "progress.json")],
            capture_output=True, text=True, timeout=120)
        assert rogue.returncode == 0, rogue.stderr[-3000:]
        output, _ = launcher.communicate(timeout=150)
    assert launcher.returncode == 0, "".join(lines) + output
    rep = json.loads(report_path.read_text())
    metrics = json.loads((out / "metrics.json").read_text())
    with judged(out):
        assert metrics["estimator_error_m"] < 0.0999
        assert metrics["radius_error_m"] < 0.0999
        assert metrics["angle_error"] < 0.0199
    status = json.loads((out / "launch.json").read_text())["status"]
    # MAVLink: every unsigned command refused and counted; none acknowledged.
    assert rep["mavlink_unsigned_sent"] > 400 and rep["mavlink_acks"] == 0
    assert status["sim-0"]["signing_rejected_unsigned"] == rep["mavlink_unsigned_sent"]
    # Forged telemetry: every agent refused all of it (the vehicles sign what they send).
    agents = [f"follower-{i}" for i in range(4)] + [f"target-{j}" for j in range(2)]
    forged = [status[a].get("signing_rejected_unsigned", 0) for a in agents]
    assert rep["telemetry_forged_sent"] > 400
    assert sum(forged) == rep["telemetry_forged_sent"] and min(forged) > 0, forged
    # Zenoh without credentials never linked; nothing of it, nor of the insider's forgeries
    # beyond its rights, was recorded.
    assert rep["plain_published"] > 100 and rep["plain_linked"] == 0
    recorder = metrics["recorder"]
    # No forged (seq 0) state got in; the launcher's repeated start words and its stop
    # carry one sequence, so nothing legitimate is stale either.
    assert recorder["decoder"]["seq_stale"] == 0
    # The insider's fuzz: all of it reached the recorder and was refused there.  Each
    # follower listening to follower 0 refused what it read; its queue for follower 0 holds
    # 8 (agents.follower.node.PEER_QUEUE), so the flood's overflow was discarded unread.
    # A recorder starved behind the flood for over 3 s loses what overflows its queue
    # (16 384 states): lost uncounted, not accepted (0.5-1.1 % in 2 of 4 runs beside another
    # timed swarm).
    assert rep["fuzz_sent"] == FUZZ_COUNT
    assert 0.97 * FUZZ_COUNT <= drops(recorder["decoder"]) <= FUZZ_COUNT
    listeners = [c for name, c in status.items() if name.startswith("follower-")
                 and name != "follower-0" and c.get("rx_f0", 0) > 0]
    assert listeners and all(0 < drops(c) <= FUZZ_COUNT for c in listeners), listeners
