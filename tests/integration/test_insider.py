"""A process holding follower 2's certificate passes for others during a default `enclose
run` (tests/integration/rogue.py, part `identity`): statuses forged as the simulator, on
its key and on follower 2's own, 2000 made-up roles, "stop" words on follower 2's state key,
liveliness tokens out of range and malformed, and follower 2's own token declared and
withdrawn five times a second.

The access control keeps its puts and tokens off every other key; what it may put on its
own keys is refused by every receiver (transport.checks: a status counts only from the
process it names, a key carries one type of message).  Nothing forged reaches launch.json,
the recording or the verdict, the swarm stays inside the paper's bounds, and every refusal
is counted and shown (the verdict's processes line names follower 2).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.integration.runs import spawned
from tests.integration.test_attack import STARTED
from transport.access import sender_ids

pytestmark = pytest.mark.integration
DURATION_S = 24.0
ATTACK_S = DURATION_S - 4.0
ROGUE = 2


def rogue(out: Path, report: Path, m: dict[str, str]) -> subprocess.CompletedProcess[str]:
    ident = out / "credentials" / f"follower-{ROGUE}.json"
    return subprocess.run(
        [sys.executable, "-m", "tests.integration.rogue", "--vehicle-port", m["vehicle"],
         "--agent-port", m["agent"], "--vehicles", "6", "--endpoint", m["endpoint"],
         "--swarm", m["swarm"], "--followers", "4", "--fuzz-identity", str(ident),
         "--seconds", str(ATTACK_S), "--out", str(report),
         "--progress", str(out / "progress.json")],
        capture_output=True, text=True, timeout=120,
        env={**os.environ, "ROGUE_PARTS": "identity"})


@pytest.mark.timeout(240)
def test_an_insider_cannot_pass_for_another_process(tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = [sys.executable, "-m", "deploy.cli", "run", "--out", str(out), "--link-timeout",
            "60", "--duration", str(DURATION_S)]
    with spawned(argv, out) as launcher:
        assert launcher.stdout is not None
        lines = []
        for line in launcher.stdout:
            lines.append(line)
            if (found := STARTED.search(line)) is not None:
                break
        else:
            pytest.fail("".join(lines))
        ports = dict(zip(("swarm", "endpoint", "vehicle", "agent"), found.groups(),
                         strict=True))
        done = rogue(out, tmp_path / "rogue.json", ports)
        assert done.returncode == 0, done.stderr[-3000:]
        output, _ = launcher.communicate(timeout=150)
    assert launcher.returncode == 0, "".join(lines) + output
    rep = json.loads((tmp_path / "rogue.json").read_text())
    metrics = json.loads((out / "metrics.json").read_text())
    launch = json.loads((out / "launch.json").read_text())
    assert metrics["estimator_error_m"] < 0.0999
    assert metrics["radius_error_m"] < 0.0999
    assert metrics["angle_error"] < 0.0199
    assert rep["roles_sent"] == 2000 and rep["token_flaps"] > 50
    # launch.json: the scenario's processes only, each as it said itself.
    for table in (launch["status"], launch["status_at_stop"]):
        assert set(table) <= sender_ids(4, 2) and "sim-0" in table
        assert not [name for name, c in table.items() if "forged" in c]
    assert launch["status"]["sim-0"]["state"] != "failed" and launch["events"] == []
    # Every forgery on follower 2's own status key refused by the recorder (nothing
    # recorded: no channel for a made-up role) and by the launcher, and blamed on it.
    recorder = launch["status"]["recorder-0"]
    assert recorder["statuses_rejected"] == rep["statuses_forged_own_key"] > 2000
    assert recorder[f"rejected_from_follower-{ROGUE}"] >= recorder["statuses_rejected"]
    assert not [t for t in metrics["recorder"]["messages_per_topic"] if "/status/role" in t]
    own = launch["launcher"]
    assert 0 < own["statuses_rejected"] <= rep["statuses_forged_own_key"]
    assert own[f"rejected_from_follower-{ROGUE}"] == own["statuses_rejected"]
    # Its "stop" words: refused by the followers that listen to it, which flew on.
    listeners = {n: c for n, c in launch["status"].items()
                 if n.startswith("follower-") and c.get(f"rx_f{ROGUE}", 0) > 0}
    assert listeners and all(0 < c.get("drop_wrong_key", 0) <= rep["control_forged_sent"]
                             for c in listeners.values()), listeners
    # Tokens: out-of-range ones never got in (the access control) and follower 2's own,
    # declared beside the real one, changed nobody's member set in flight (at the stop,
    # followers leave one by one); nothing crashed.
    followers = [c for n, c in launch["status"].items() if n.startswith("follower-")]
    assert len(followers) == 4 and all(c["state"] == "done" for c in followers)
    flying = [c for n, c in launch["status_at_stop"].items() if n.startswith("follower-")]
    assert not [c for c in flying if c.get("membership_changes", 0)], flying
    assert all(p["exit_code"] == 0 for p in launch["processes"].values())
    # Shown: the verdict's processes line sums the refusals and names the sender.
    assert f"from follower-{ROGUE}" in output and "statuses" in output, output[-2000:]
