"""A partition {1, 2} | {3, 4} of the paper's case on real processes (loopback): each
follower's membership loses the other half and takes it back at the heal, nothing dies,
and metrics.json reports the closest approach and the fault's recovery."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest

from tests.integration.runs import pid_alive, spawned_run

pytestmark = pytest.mark.integration
DURATION_S, AT_S, CUT_S = 36.0, 12.0, 8.0
RATE_HZ = 50.0  # the paper's control rate: one state a tick


def member_sets(log: str) -> list[str]:
    """The member sets a follower re-formed around, in order (agents.follower.node)."""
    return re.findall(r"members \[[0-9, ]*\] -> (\[[0-9, ]*\])", log)


@pytest.mark.timeout(240)
def test_a_partition_is_seen_by_membership_and_healed(tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = [sys.executable, "-m", "deploy.cli", "run", "--out", str(out), "--link-timeout",
            "60", "--duration", str(DURATION_S), "--estimator", "robust",
            "--fault", f"{AT_S:g}:partition:1,2|3,4:{CUT_S:g}"]
    with spawned_run(argv, out) as proc:
        output, _ = proc.communicate(timeout=DURATION_S + 150.0)
    assert proc.returncode == 0, output  # 3: a process died
    launch = json.loads((out / "launch.json").read_text())
    for name, p in launch["processes"].items():
        assert not pid_alive(p["pid"]), f"{name} (pid {p['pid']}) still running"
        assert p.get("restarts", 0) == 0, name
    halves = {0: "[0, 1]", 1: "[0, 1]", 2: "[2, 3]", 3: "[2, 3]"}
    for i, half in halves.items():
        sets = member_sets((out / "logs" / f"follower-{i}.log").read_text())
        assert half in sets, (i, sets)  # the other half gone ...
        # ... and back (what follows is the stop: the others leave one by one)
        assert "[0, 1, 2, 3]" in sets[sets.index(half):], (i, sets)
    # Follower 2 is follower 1's neighbour: the window's states never reached it.
    counters = launch["status_at_stop"]["follower-1"]
    missing = counters["seq_last_f2"] - counters["seq_first_f2"] + 1 - counters["rx_f2"]
    assert 0.8 * CUT_S * RATE_HZ <= missing <= 1.5 * CUT_S * RATE_HZ, missing
    assert counters["seq_last_f0"] - counters["seq_first_f0"] + 1 - counters["rx_f0"] == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["min_separation_m"] > 0.0
    assert {"min_separation_transient_m", "min_separation_steady_m"} <= set(metrics)
    (fault,) = metrics["net_faults"]
    assert (fault["at_s"], fault["end_s"]) == (AT_S, AT_S + CUT_S)
    assert fault["label"] == f"partition 1,2|3,4 {AT_S:g}-{AT_S + CUT_S:g} s"
    assert "min_separation_m" in fault and "recovery_s" in fault
