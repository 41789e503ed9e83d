"""What a process refused on its MAVLink link reaches the verdict and the live view."""

from __future__ import annotations

import io
import json
from pathlib import Path

from rich.console import Console

from deploy.refusals import refusal_lines, refusal_text, refusals, vehicle_owner
from deploy.verdict import print_verdict, read_verdict

SIM = {"state": "done", "ticks": 900, "signing_rejected_unsigned": 2500,
       "signing_rejected_wrong_key": 20, "signing_wrong_key_vehicle_3": 20,
       "mav_budget_spent": 4, "peers_refused": 0}
FOLLOWER = {"state": "done", "signing_rejected_bad_signature": 91000, "mav_flood_drops": 2,
            "mav_kernel_drops": 17}


def test_only_nonzero_refusal_counters_count() -> None:
    assert refusals(SIM) == {"signing_rejected_unsigned": 2500, "signing_rejected_wrong_key": 20,
                             "signing_wrong_key_vehicle_3": 20}
    assert refusals({"state": "done", "ticks": 5, "signing_rejected_replay": True}) == {}
    assert refusal_text({"ticks": 9}, 4) is None


def test_the_wrong_keys_owner_is_named() -> None:
    assert vehicle_owner(3, 4) == "follower-2" and vehicle_owner(6, 4) == "target-1"
    assert refusal_text(SIM, 4) == ("refused 2520 MAVLink frames (unsigned 2500, wrong_key 20: "
                                    "follower-2's key)")
    assert refusal_text(FOLLOWER, 4) == (
        "refused 91000 MAVLink frames (bad_signature 91000), 2 datagrams cut at the parse "
        "budget, 17 dropped unread by the kernel")


def test_the_verdict_shows_each_refusing_process(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.json").write_text(json.dumps({"estimator_error_m": 0.01,
                                                  "radius_error_m": 0.02, "angle_error": 0.003}))
    status = {"sim-0": SIM, "follower-0": FOLLOWER, "follower-1": {"state": "done"},
              "follower-2": {}, "follower-3": {}, "recorder-0": "garbage"}
    (run / "launch.json").write_text(json.dumps({"status": status}))
    v = read_verdict(run, "enclose run paper")
    assert v.processes == refusal_lines(status) and len(v.processes) == 2
    buf = io.StringIO()
    print_verdict(Console(file=buf, width=400), v)
    assert "follower-0: refused 91000 MAVLink frames (bad_signature 91000)" in buf.getvalue()
    assert "sim-0: refused 2520 MAVLink frames" in buf.getvalue()
    assert refusal_lines(["not", "a", "dict"]) == ()
