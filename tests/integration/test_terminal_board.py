"""`enclose run` on a real terminal (a tmux pane): the live board is drawn and redrawn in
place, and the verdict ends what it printed.  Piped output: test_swarm_run.py."""

from __future__ import annotations

import contextlib
import os
import shlex
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from deploy.launch.port_slots import port_slot
from tests.integration.runs import kill_leftovers, wait_for

pytestmark = pytest.mark.integration
TMUX = shutil.which("tmux")
REPO = Path(__file__).resolve().parents[2]
BOARD_HEADER = "error (last 1 s)"


@contextlib.contextmanager
def tmux_server(tmp_path: Path) -> Iterator[list[str]]:
    """A tmux server of this test's own (own socket, no user config); killed after."""
    conf = tmp_path / "tmux.conf"
    conf.write_text("set -g remain-on-exit on\nset -g history-limit 5000\n")
    tmux = [str(TMUX), "-L", f"enclose-test-{os.getpid()}", "-f", str(conf)]
    try:
        yield tmux
    finally:
        subprocess.run([*tmux, "kill-server"], capture_output=True, timeout=10, check=False)


def pane(tmux: list[str], history: bool = False) -> str:
    argv = [*tmux, "capture-pane", "-p", "-t", "run", *(["-S", "-"] if history else [])]
    return subprocess.run(argv, capture_output=True, text=True, timeout=10).stdout


@pytest.mark.skipif(TMUX is None, reason="tmux is not installed (deploy/bootstrap.sh --dev "
                                         "installs it as root)")
@pytest.mark.timeout(200)
def test_run_on_a_terminal_draws_the_board_and_ends_with_the_verdict(tmp_path: Path) -> None:
    out, rc_file = tmp_path / "run", tmp_path / "rc"
    with port_slot() as slot, tmux_server(tmp_path) as tmux:  # ports of its own: runs.spawned_run
        cmd = (f"{shlex.quote(sys.executable)} -m deploy.cli run --out {shlex.quote(str(out))} "
               f"--duration 10 --link-timeout 60 --port-range {slot.flag}; "
               f"echo $? > {shlex.quote(str(rc_file))}")
        try:
            subprocess.run([*tmux, "new-session", "-d", "-s", "run", "-x", "160", "-y", "50",
                            cmd], check=True, cwd=REPO, timeout=10)
            wait_for(lambda: BOARD_HEADER in pane(tmux), 120.0, "the board on the terminal",
                     period_s=0.2)
            board = pane(tmux)
            wait_for(rc_file.exists, 150.0, "the run to end", period_s=0.5)
            screen = pane(tmux, history=True)
        finally:
            kill_leftovers(out)
    assert rc_file.read_text().strip() == "0", screen[-3000:]
    assert "enclose run paper" in board and "follower-3" in board and "links:" in board
    # Redrawn in place: the board was drawn many times but stands once in the scrollback.
    assert screen.count(BOARD_HEADER) == 1, screen
    last = [line for line in screen.splitlines() if line.strip()][-30:]
    tail = "\n".join(last)
    assert "enclose run paper: INSIDE the paper's bounds" in tail or \
        "enclose run paper: OUTSIDE the paper's bounds" in tail, tail
    for text in ("estimator error |r-LAP|", "< 0.0999 m", "< 0.0199", "settle time",
                 "processes", f"files        {out}/"):
        assert text in tail, (text, tail)
