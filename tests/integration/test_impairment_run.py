"""`enclose run` with impaired links: the recorder's "links" report matches the configuration.

Formation accuracy is not asserted: the paper's estimator is not built for 20 % loss.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.integration.test_swarm_run import assert_all_exited, launched

pytestmark = pytest.mark.integration

LOSS, DELAY_MS = 0.2, 50.0
RATIO_TOL = 0.06
AGE_SLACK_MS = 25.0  # a sample waits for the receiver's next 50 Hz tick after its release


@pytest.mark.timeout(240)
def test_seeded_run_delivers_what_was_configured(tmp_path: Path) -> None:
    out = tmp_path / "run"
    flags = ["--duration", "15", "--loss", str(LOSS), "--delay-ms", str(DELAY_MS),
             "--impair-seed", "3", "--no-figures"]
    with launched(out, *flags) as proc:
        output, _ = proc.communicate(timeout=200)
    assert proc.returncode == 0, output
    assert all(code == 0 for code in assert_all_exited(out).values())
    links = json.loads((out / "metrics.json").read_text())["links"]
    # The paper case: a ring of 4 followers, each hears 2 neighbours and its sensor.
    followers = {f"f{j}->f{i}" for i in range(4) for j in ((i + 1) % 4, (i + 3) % 4)}
    assert set(links) == followers | {f"sensor->f{i}" for i in range(4)}
    for name, link in links.items():
        assert link["final"], name
        assert link["sent"] > 500, (name, link)
        assert abs(link["delivered_ratio"] - (1.0 - LOSS)) <= RATIO_TOL, (name, link)
        assert DELAY_MS <= link["age_p50_ms"] <= DELAY_MS + AGE_SLACK_MS, (name, link)
        assert link["impairment"]["dropped"] > 0
    for name in followers:
        assert links[name]["sent_source"] == "states_sent"
