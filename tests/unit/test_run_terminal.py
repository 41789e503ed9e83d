"""The launcher's live board and the verdict at the end, rendered into a string buffer (not
a terminal): what they say, and that piped output carries no escape codes."""

from __future__ import annotations

import io
import json
import logging
from pathlib import Path

import pytest
from rich.console import Console

from deploy.launch.run_board import (
    BoardView,
    LiveBoard,
    ProcessView,
    board_line,
    lag_text,
    link_text,
    render_board,
)
from deploy.report.verdict import announce, print_verdict, read_verdict, verdict_json

ESC = "\x1b"
BOUNDS = {"rho": 0.0999, "delta": 0.0199}
PROGRESS = {
    "state": "running", "t_s": 12.0, "max_estimator_error_m": 0.012, "max_abs_e_rho_m": 0.25,
    "max_abs_e_delta": 0.004,
    "links": {"count": 12, "silent": ["f3->f0"], "min_delivered": 0.8,
              "min_delivered_link": "f0->f1", "max_age_ms": 41.5, "max_age_link": "f2->f3"},
}


def plain_console(width: int = 120) -> tuple[Console, io.StringIO]:
    buf = io.StringIO()
    return Console(file=buf, width=width), buf


def view(n_followers: int = 4, **kw: object) -> BoardView:
    procs = [ProcessView("sim", "up", "running"), ProcessView("recorder", "up", "running")]
    procs += [ProcessView(f"follower-{i}", "up", "running") for i in range(n_followers)]
    procs[3] = ProcessView("follower-1", "restarting", "", 1)
    args: dict[str, object] = {
        "title": "enclose run paper", "elapsed_s": 21.0, "t_s": 12.0, "duration_s": 24.0,
        "bounds": BOUNDS, "progress": PROGRESS, "processes": tuple(procs),
        "events": ("11.0 s follower-1 died signal=SIGKILL",), "live_url": "ws://127.0.0.1:8765",
    }
    args.update(kw)
    return BoardView(**args)  # type: ignore[arg-type]


def test_the_board_shows_time_errors_against_bounds_processes_links_and_live_url() -> None:
    console, buf = plain_console()
    console.print(render_board(view()))
    text = buf.getvalue()
    assert ESC not in text  # not a terminal: plain text
    assert "t = 12.0 / 24 s" in text and "elapsed 21 s" in text
    rows = {line.split()[0]: line for line in text.splitlines() if line.strip()}
    assert "0.012 m" in rows["estimator"] and "< 0.0999 m" in rows["estimator"]
    assert rows["estimator"].rstrip().endswith("ok")
    assert rows["radius"].rstrip().endswith("over")  # 0.25 m is above 0.0999 m
    assert "restarting" in rows["follower-1"] and "sim" in rows
    assert "worst delivered 0.80 (f0->f1)" in text and "silent 1: f3->f0" in text
    assert "live view: ws://127.0.0.1:8765" in text and "died signal=SIGKILL" in text


def test_a_big_swarm_shows_followers_as_one_row_plus_the_unhealthy_ones() -> None:
    console, buf = plain_console()
    console.print(render_board(view(n_followers=16)))
    names = [line.split()[0] for line in buf.getvalue().splitlines() if line.strip()]
    assert "follower-1" in names  # restarting: listed on its own
    assert "follower-5" not in names and "followers" in names


def test_piped_board_is_one_plain_line_per_period(caplog: pytest.LogCaptureFixture) -> None:
    line = board_line(view(progress={}))
    assert ESC not in line and "\n" not in line
    assert "estimator |r-LAP| -" in line and "no link counters yet" in line
    console, buf = plain_console()
    with caplog.at_level(logging.INFO, "enclose.run"), LiveBoard(view, 60.0, console) as board:
        assert not board.tty
        board.tick()
        board.tick()  # within the period: no second line
    assert buf.getvalue() == ""  # nothing drawn: lines go to the log
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("t = ")]
    assert len(lines) == 1 and "radius |e_rho| 0.25 m OVER" in lines[0]


def test_on_a_terminal_the_board_is_redrawn_in_place() -> None:
    buf = io.StringIO()
    console = Console(file=buf, width=100, force_terminal=True)
    with LiveBoard(view, console=console) as board:
        board._next_s = 0.0
        board.tick()
    text = buf.getvalue()
    assert text.count("enclose run paper") >= 2  # drawn, then drawn again...
    assert f"{ESC}[2K" in text and f"{ESC}[1A" in text  # ...over itself (erase, cursor up)


def write_run(run_dir: Path, radius_m: float = 0.02, **launch: object) -> Path:
    run_dir.mkdir()
    metrics = {"steady_from_s": 12.0, "estimator_error_m": 0.011, "radius_error_m": radius_m,
               "angle_error": 0.003, "settle_time_s": 6.5, "command_jump_m_s": 0.1,
               "links": {"f0->f1": {"delivered_ratio": 0.97, "age_p99_ms": 30.0},
                         "f1->f0": {"delivered_ratio": 1.0, "age_p99_ms": 12.5}}}
    (run_dir / "metrics.json").write_text(json.dumps(metrics))
    (run_dir / "run.json").write_text(json.dumps({"eps_rho_m": 0.0999, "eps_delta": 0.0199}))
    (run_dir / "performance.png").write_bytes(b"png")
    if launch:
        (run_dir / "launch.json").write_text(json.dumps(launch))
    return run_dir


EVENTS = [
    {"t_s": 5.0, "process": "follower-1", "event": "fault", "action": "kill"},
    {"t_s": 5.0, "process": "follower-1", "event": "died", "signal": "SIGKILL"},
    {"t_s": 6.0, "process": "follower-1", "event": "restarted", "pid": 7},
]


def test_the_verdict_is_short_and_says_bounds_settling_deaths_links_and_files(
    tmp_path: Path,
) -> None:
    run = write_run(tmp_path / "run", events=EVENTS, live_url="ws://127.0.0.1:8765",
                    processes={"sim": {"exit_code": 0}, "target-0": {"exit_code": 1}})
    console, buf = plain_console()
    v = read_verdict(run, "enclose run paper")
    print_verdict(console, v)
    lines = buf.getvalue().rstrip("\n").splitlines()
    assert ESC not in buf.getvalue() and len(lines) <= 12
    assert lines[0].startswith("enclose run paper: INSIDE the paper's bounds")
    assert "0.02 m" in lines[2] and "< 0.0999 m" in lines[2] and lines[2].rstrip().endswith("ok")
    assert "< 0.0199" in lines[3]
    text = buf.getvalue()
    assert "settle time  6.5 s" in text
    assert "follower-1: died 1x, fault 1x, restarted 1x" in text and "exit code 1" in text
    assert "delivered >= 0.970 (worst f0->f1)" in text and "ws://127.0.0.1:8765" in text
    assert f"{run}/ (metrics.json, performance.png, launch.json)" in text
    doc = verdict_json(v)
    assert doc["verdict"]["inside_bounds"] is True and doc["radius_error_m"] == 0.02
    assert doc["verdict"]["checks"]["angle_error"] == {"value": 0.003, "bound": 0.0199,
                                                      "inside": True}


def test_the_processes_line_sums_what_the_processes_refused(tmp_path: Path) -> None:
    status = {"follower-0": {"state": "done", "tokens_rejected": 3},
              "recorder-0": {"state": "done", "statuses_rejected": 40,
                             "rejected_from_follower-2": 40}}
    run = write_run(tmp_path / "run", processes={"sim": {"exit_code": 0}}, status=status,
                    launcher={"statuses_rejected": 2, "rejected_from_follower-2": 2})
    console, buf = plain_console()
    v = read_verdict(run, "enclose run paper")
    print_verdict(console, v)
    assert ("processes    none died, restarted or failed; refused 42 statuses, 3 tokens "
            "(from follower-2 42 seen by 2)") in buf.getvalue()
    assert verdict_json(v)["verdict"]["refused"] == {"statuses": 42, "tokens": 3,
                                                     "from": {"follower-2": 42},
                                                     "seen_by": {"follower-2": 2}}


def test_a_metric_over_its_bound_or_no_metrics_says_so(tmp_path: Path) -> None:
    console, buf = plain_console()
    print_verdict(console, read_verdict(write_run(tmp_path / "a", radius_m=0.2), "run"))
    assert "run: OUTSIDE the paper's bounds" in buf.getvalue()
    assert "0.2 m" in buf.getvalue() and "OVER" in buf.getvalue()
    assert "processes" not in buf.getvalue()  # no launch.json: not a networked run
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "metrics.json").write_text(json.dumps({"error": "no truth received"}))
    console, buf = plain_console()
    v = read_verdict(tmp_path / "b", "run", note="interrupted")
    print_verdict(console, v)
    assert "run: NO VERDICT (no truth received)  [interrupted]" in buf.getvalue()
    assert v.inside is False and verdict_json(v)["verdict"]["inside_bounds"] is False


def test_a_follower_that_sent_no_state_makes_the_run_incomplete_not_inside(
    tmp_path: Path,
) -> None:
    run = write_run(tmp_path / "run")
    doc = json.loads((run / "metrics.json").read_text())
    doc.update(silent_followers=[2], followers={str(i): {} for i in range(4)})
    (run / "metrics.json").write_text(json.dumps(doc))
    console, buf = plain_console()
    v = read_verdict(run, "enclose run paper")
    print_verdict(console, v)
    text = buf.getvalue()
    # Every metric is within its bound, but over three of the four followers only.
    assert all(c.inside for c in v.checks) and v.inside is False
    assert text.startswith("enclose run paper: INCOMPLETE (follower 2 (0-based) sent no state)")
    assert "estimator error over the other 3" in text
    assert verdict_json(v)["verdict"]["silent_followers"] == [2]


def test_json_goes_alone_to_stdout_for_scripts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = write_run(tmp_path / "run")
    announce(run, "enclose run paper", as_json=True)
    out, err = capsys.readouterr()
    assert json.loads(out)["verdict"]["inside_bounds"] is True
    assert "INSIDE the paper's bounds" in err and ESC not in out + err
    announce(run, "enclose run paper", as_json=False)
    out, _ = capsys.readouterr()
    assert out.startswith("enclose run paper: INSIDE") and ESC not in out


def test_process_health_and_state_as_the_board_shows_them(tmp_path: Path) -> None:
    from deploy.launch.run_monitor import process_views
    from deploy.launch.status_board import StatusBoard
    from deploy.procs.supervisor import Child
    from transport.messages import Header, ProcessStatus

    kids = [Child(n, [], tmp_path / f"{n}.log") for n in ("sim", "follower-0", "follower-1",
                                                         "follower-2", "target-0")]
    kids[2].exit_code, kids[3].exit_code, kids[4].exit_code = -9, 0, -9
    board = StatusBoard(frozenset())
    for role, i, state in (("sim", 0, "running"), ("follower", 0, "running")):
        board.latest[f"{role}-{i}"] = ProcessStatus(Header(role, 0, 1.0), role, i, state, {})
    views = process_views(kids, board, paused={"follower-0"}, pending={"target-0"})
    assert [(v.name, v.health, v.state) for v in views] == [
        ("sim", "up", "running"), ("follower-0", "paused", "running"),
        ("follower-1", "killed (9)", ""), ("follower-2", "exited 0", ""),
        ("target-0", "restarting", "")]


def test_a_long_list_of_silent_links_is_cut_to_a_few_names() -> None:
    silent = [f"f{i}->f{i + 1}" for i in range(30)]
    text = link_text({"links": {"count": 48, "silent": silent}})
    assert "silent 30: f0->f1, f1->f2, f2->f3, f3->f4 (+26 more)" in text
    assert "f4->f5" not in text


def test_a_recorder_far_behind_the_bus_says_so_on_the_board_and_the_line() -> None:
    behind = {**PROGRESS, "recorder_behind_s": 6.27}
    console, buf = plain_console()
    console.print(render_board(view(progress=behind)))
    assert "recorder 6.3 s behind (live figures lag)" in buf.getvalue()
    assert board_line(view(progress=behind)).endswith("recorder 6.3 s behind (live figures lag)")


@pytest.mark.parametrize("progress", [
    {**PROGRESS, "recorder_behind_s": 0.4},  # the usual: under the threshold
    {**PROGRESS, "recorder_behind_s": None},  # nothing processed yet
    {**PROGRESS, "state": "done", "recorder_behind_s": 9.0},  # after the stop no input is due
])
def test_a_recorder_keeping_up_or_done_says_nothing_of_lag(progress: dict[str, object]) -> None:
    assert lag_text(progress) is None
    console, buf = plain_console()
    console.print(render_board(view(progress=progress)))
    assert "behind" not in buf.getvalue() and "behind" not in board_line(view(progress=progress))


def test_a_recorder_that_lost_messages_says_so_and_a_whole_recording_says_nothing(
    tmp_path: Path,
) -> None:
    run = write_run(tmp_path / "run")
    console, buf = plain_console()
    print_verdict(console, read_verdict(run, "enclose run paper"))
    assert "recording" not in buf.getvalue()
    doc = json.loads((run / "metrics.json").read_text())
    doc["recorder"] = {"decoder": {"accepted": 140703, "seq_gap": 28129,
                                   "drop_rejected_future_stamp": 4305}}
    (run / "metrics.json").write_text(json.dumps(doc))
    console, buf = plain_console(width=200)
    v = read_verdict(run, "enclose run paper")
    print_verdict(console, v)
    assert ("recording    83.3 % of the messages sent were recorded (28129 missing, 4305 of "
            "them refused)") in buf.getvalue()
    assert verdict_json(v)["verdict"]["recording"] == v.recording
    doc["recorder"]["decoder"]["seq_gap"] = 1000  # 0.7 %: within what a run may lose
    (run / "metrics.json").write_text(json.dumps(doc))
    assert read_verdict(run, "enclose run paper").recording is None
