"""20 kinds of broken scenario files: each is one error line naming the field, no traceback."""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

import pytest

from agents.loading.scenario_file import shipped_text
from deploy.cli import main

PAPER = shipped_text("paper")


def edit(old: str, new: str) -> str:
    assert old in PAPER, old
    return PAPER.replace(old, new, 1)


# (what is broken, file text, a word the error must name)
BROKEN = [
    ("not toml", "name = [", "toml"),
    ("beta text", edit("beta_m_s = 1.118033988749895", 'beta_m_s = "fast"'), "beta_m_s"),
    ("beta negative", edit("beta_m_s = 1.118033988749895", "beta_m_s = -1.0"), "beta_m_s"),
    ("beta nan", edit("beta_m_s = 1.118033988749895", "beta_m_s = nan"), "beta_m_s"),
    ("radius zero", edit("rho_d_m = 8.0", "rho_d_m = 0.0"), "rho_d_m"),
    ("rate text", edit("w_d_rad_s = 0.2", 'w_d_rad_s = "x"'), "w_d_rad_s"),
    ("angles short", edit("angles_deg = [72.0, 72.0, 72.0, 144.0]", "angles_deg = [72.0]"),
     "angles_deg"),
    ("angles sum", edit("angles_deg = [72.0, 72.0, 72.0, 144.0]",
                        "angles_deg = [72.0, 72.0, 72.0, 72.0]"), "angles"),
    ("order repeats", edit("order = [1, 2, 3, 4]", "order = [1, 1, 3, 4]"), "order"),
    ("gain negative", edit("k_e = 6.0", "k_e = -6.0"), "k_e"),
    ("gain misspelt", edit("k_e = 6.0", "k_e = 6.0\nk_q = 1.0"), "gains.k_q"),
    ("run setting misspelt", edit("rate_hz = 50.0", "rate_hz = 50.0\nrate = 10.0"), "run.rate"),
    ("alpha text", edit('alpha1 = "7/3"', 'alpha1 = "seven"'), "alpha1"),
    ("edge unknown follower", edit("[4, 1]]", "[4, 9]]"), "edges"),
    ("edge malformed", edit("[4, 1]]", "[4]]"), "edges"),
    ("duration negative", edit("duration_s = 200.0", "duration_s = -5.0"), "duration_s"),
    ("dt zero", edit("dt_s = 0.001", "dt_s = 0.0"), "dt_s"),
    ("rate zero", edit("rate_hz = 50.0", "rate_hz = 0.0"), "rate_hz"),
    ("follower position short", edit("pos_m = [10.0, -20.0]", "pos_m = [10.0]"), "pos_m"),
    ("unknown profile", edit('profile = "paper_v1"', 'profile = "warp"'), "profile"),
    ("observer unknown", edit("observed_by = [1, 2]", "observed_by = [1, 7]"), "observed_by"),
    ("target position text", edit("pos_m = [0.0, 0.0]", 'pos_m = "here"'), "pos_m"),
]


@pytest.mark.parametrize(("what", "text", "field"), BROKEN, ids=[b[0] for b in BROKEN])
def test_broken_scenario_is_one_line_naming_the_field(
        what: str, text: str, field: str, tmp_path: Path,
        caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "broken.toml"
    path.write_text(text)
    with caplog.at_level(logging.ERROR):
        code = main(["simulate", str(path), "--out", str(tmp_path / "out")])
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert code == 2 and len(errors) == 1, (what, errors)
    assert field in errors[0] and "\n" not in errors[0], (what, errors[0])


@pytest.mark.realtime
def test_broken_scenario_from_the_shell_has_no_traceback(tmp_path: Path) -> None:
    path = tmp_path / "broken.toml"
    path.write_text(BROKEN[1][1])
    done = subprocess.run([sys.executable, "-m", "deploy.cli", "simulate", str(path)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr + done.stdout
    lines = [ln for ln in (done.stderr + done.stdout).splitlines() if ln.strip()]
    assert len(lines) == 1 and "beta_m_s" in lines[0], lines
