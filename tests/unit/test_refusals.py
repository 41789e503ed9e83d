"""What the MAVLink receivers refused reaches the verdict's processes line, with the agent
whose key signed frames for another vehicle named as the sender."""

from __future__ import annotations

import io
import json
from pathlib import Path

from rich.console import Console

from deploy.refusals import launch_refusals, refusal_text
from deploy.run_secrets import agent_of_vehicle
from deploy.swarm_sim import wrong_key_senders
from deploy.verdict import print_verdict, read_verdict

SIM = {"state": "done", "ticks": 900, "signing_rejected_unsigned": 2500,
       "signing_rejected_wrong_key": 20, "signing_wrong_key_vehicle_3": 20,
       "mav_budget_spent": 4, "peers_refused": 0}
FOLLOWER = {"state": "done", "signing_rejected_bad_signature": 91000, "mav_flood_drops": 2,
            "mav_kernel_drops": 17}


def test_vehicles_are_flown_by_followers_then_targets() -> None:
    assert [agent_of_vehicle(s, 4) for s in (1, 4, 5, 6)] == [
        "follower-0", "follower-3", "target-0", "target-1"]


def test_a_wrong_key_names_the_agent_that_holds_it() -> None:
    assert wrong_key_senders(SIM, 4) == {"rejected_from_follower-2": 20}
    assert wrong_key_senders({"signing_wrong_key_vehicle_x": 3, "ticks": 1}, 4) == {}


def test_the_verdict_sums_mavlink_refusals_and_names_the_sender(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.json").write_text(json.dumps({"estimator_error_m": 0.01,
                                                  "radius_error_m": 0.02, "angle_error": 0.003}))
    status = {"sim-0": {**SIM, **wrong_key_senders(SIM, 4)}, "follower-0": FOLLOWER,
              "follower-1": {"state": "done"}, "recorder-0": "garbage"}
    (run / "launch.json").write_text(json.dumps({"status": status}))
    summed = launch_refusals({"status": status})
    assert summed == {"unsigned MAVLink frames": 2500, "badly signed MAVLink frames": 91000,
                      "MAVLink frames signed with another vehicle's key": 20,
                      "MAVLink datagrams cut (each over a whole tick's budget)": 2,
                      "MAVLink datagrams the kernel dropped": 17, "from": {"follower-2": 20}}
    buf = io.StringIO()
    print_verdict(Console(file=buf, width=600), read_verdict(run, "enclose run paper"))
    assert refusal_text(summed) in buf.getvalue()
    assert "(from follower-2 20)" in buf.getvalue()


def test_dropped_clock_probes_are_summed_and_shown() -> None:
    follower = {"state": "done", "clock_probes_dropped_sender": 3,
                "clock_probes_dropped_step": 2}
    router_side = {"clock_probes_dropped_times": 1, "clock_probes_dropped_rate": 4,
                   "clock_probes_dropped_sender": 5}
    summed = launch_refusals({"status": {"follower-0": follower, "sim-0": router_side}})
    assert summed == {"clock probes from no router": 8,
                      "clock probes with impossible times": 1,
                      "clock probes too close together": 4,
                      "clock probes over the offset step": 2}
    text = refusal_text(summed)
    assert text is not None and "8 clock probes from no router" in text
