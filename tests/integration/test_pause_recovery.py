"""A loopback `enclose run` whose simulator, one follower and one target are each frozen for
0.5 s (SIGSTOP/SIGCONT by PID) at different times: after each resume the swarm is back
inside the paper's bounds within 10 s, with the defaults."""

from __future__ import annotations

from pathlib import Path

import pytest

from deploy.report.recovery import recoveries
from tests.integration.pauses import Pause, run_with_pauses
from tests.integration.real_time import judged

pytestmark = pytest.mark.integration
PLAN = [Pause(15.0, "sim", 0.5), Pause(30.0, "follower-0", 0.5), Pause(45.0, "target-0", 0.5)]


@pytest.mark.timeout(420)
def test_the_swarm_recovers_from_a_pause_of_each_role(tmp_path: Path) -> None:
    out = tmp_path / "run"
    run = run_with_pauses(out, 62.0, PLAN)
    assert run.returncode == 0, run.output[-3000:]
    assert len(run.pauses_wall_s) == len(PLAN)
    for pause, rec in zip(PLAN, recoveries(out, run.pauses_wall_s), strict=True):
        assert rec.window_end_s - rec.resume_s > 11.0, (pause, rec)
        with judged(out):
            assert rec.recovered_after_s is not None and rec.recovered_after_s < 10.0, (
                pause, rec)
