"""The law's clock (`Inputs.t_s`, the time since the run's start): a law that raises in a
window of it fails in the same window lock-step and networked; each engine counts its
failures (`law_failures`), the verdict names them, and the followers' journals replay
the run's t_s, failures included, bit for bit."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.integration.laws.windowed_law import WINDOW_S
from tests.integration.runs import spawned_run

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]

LAWS = Path(__file__).resolve().parent / "laws"
LAW = f"{LAWS}/windowed_law:WindowedLaw"
NAMED = "windowed_law:WindowedLaw"
DURATION_S = "30"
RATE_HZ = 50  # the paper case's control rate, and the lock-step step below
PER_FOLLOWER = round((WINDOW_S[1] - WINDOW_S[0]) * RATE_HZ)  # control ticks in the window


def cli(*argv: str) -> list[str]:
    return [sys.executable, "-m", "deploy.cli", *argv]


def series(out: Path) -> list[tuple[float, list[complex]]]:
    """The run's series.csv: each row's time since the start and the four commands."""
    with (out / "series.csv").open() as f:
        return [(float(r["t_s"]), [complex(float(r[f"u{i}_x_m_s"]), float(r[f"u{i}_y_m_s"]))
                                   for i in range(1, 5)]) for r in csv.DictReader(f)]


def test_a_law_scheduled_on_the_runs_time_fails_in_its_window_lock_step(
        tmp_path: Path) -> None:
    out = tmp_path / "simulate"
    done = subprocess.run(cli("simulate", "paper", "--law", LAW, "--dt", str(1 / RATE_HZ),
                              "--duration", DURATION_S, "--out", str(out), "--no-progress",
                              "--json"), capture_output=True, text=True, timeout=200)
    assert done.returncode == 0, done.stderr[-3000:]
    failures = json.loads((out / "metrics.json").read_text())["law_failures"]
    assert failures == 4 * PER_FOLLOWER
    assert f"{NAMED}: FAILED {failures} times" in done.stdout
    # Every vehicle held on every control tick of the window, and on none outside it
    for t_s, u in series(out):
        inside = WINDOW_S[0] <= t_s < WINDOW_S[1]
        assert all(v == 0j for v in u) if inside else any(v != 0j for v in u), (t_s, u)


def test_a_law_scheduled_on_the_runs_time_fails_in_its_window_networked(
        tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = cli("run", "paper", "--law", LAW, "--duration", DURATION_S, "--out", str(out),
               "--no-live", "--no-figures", "--json", "--link-timeout", "60")
    with spawned_run(argv, out) as proc:
        stdout, _ = proc.communicate(timeout=240)
    assert proc.returncode == 0, stdout[-3000:]
    launch = json.loads((out / "launch.json").read_text())
    counts = {k: v["law_failures"] for k, v in launch["status_at_stop"].items()
              if k.startswith("follower-")}
    # A follower starved of the CPU skips the ticks it wakes too late for: at least half.
    assert len(counts) == 4, counts
    assert all(PER_FOLLOWER // 2 <= n <= PER_FOLLOWER + 1 for n in counts.values()), counts
    assert f"{NAMED}: FAILED {sum(counts.values())} times" in stdout
    # No follower published a step inside the window (its last command stands in the
    # recording), and they all did again once it closed.
    rows = series(out)
    held = [u for t_s, u in rows if WINDOW_S[0] + 0.1 <= t_s <= WINDOW_S[1] - 0.1]
    assert held and all(u == held[0] for u in held)
    after = [u for t_s, u in rows if WINDOW_S[1] + 0.1 <= t_s <= WINDOW_S[1] + 0.5]
    assert after and all(a != b for a, b in zip(after[-1], held[0], strict=True)), after[-1]
    replayed = subprocess.run(cli("replay", str(out), "--all"), capture_output=True,
                              text=True, timeout=120)
    assert replayed.returncode == 0, replayed.stdout + replayed.stderr[-3000:]
    assert "run reproduced: every follower" in replayed.stdout, replayed.stdout
