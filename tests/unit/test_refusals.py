"""What the MAVLink receivers refused reaches the verdict's processes line, with the agent
whose key signed frames for another vehicle named as the sender."""

from __future__ import annotations

import io
import json
from pathlib import Path

from rich.console import Console

from agents.mavlink.signing_keys import agent_of_vehicle
from deploy.report.refusals import launch_refusals, refusal_text
from deploy.report.verdict import print_verdict, read_verdict
from sim_backend.swarm_sim import wrong_key_senders

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
                      "MAVLink datagrams the kernel dropped": 17, "from": {"follower-2": 20},
                      "seen_by": {"follower-2": 1}}
    buf = io.StringIO()
    print_verdict(Console(file=buf, width=600), read_verdict(run, "enclose run paper"))
    assert refusal_text(summed) in buf.getvalue()
    assert "(from follower-2 20 seen by 1)" in buf.getvalue()


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


# The paper case's ring: follower-2 lies, its neighbours follower-1 and follower-3 and the
# recorder refuse what it puts, and it reports inflated refusals "from" others in its own
# status, to push itself out of the senders shown.
HONEST = {
    "follower-1": {"state": "done", "states_rejected": 40, "rejected_from_follower-2": 40},
    "follower-3": {"state": "done", "states_rejected": 38, "rejected_from_follower-2": 38},
    "recorder-0": {"state": "done", "states_rejected": 41, "rejected_from_follower-2": 41},
    "follower-0": {"state": "done"},
}
BLAME = {"state": "done", "states_rejected": 10**9, "rejected_from_follower-0": 10**9,
         "rejected_from_follower-1": 10**9, "rejected_from_follower-3": 10**9,
         "rejected_from_sim-0": 10**9, "rejected_from_follower-2": 10**9}


def test_a_process_inflating_its_own_counters_cannot_shift_the_blame() -> None:
    before = launch_refusals({"status": HONEST})
    assert before["from"] == {"follower-2": 119} and before["seen_by"] == {"follower-2": 3}
    after = launch_refusals({"status": {**HONEST, "follower-2": BLAME}})
    # Still first, with what the three who refused it saw; its claim about itself is not
    # counted, and each process it blames has it alone as a witness.
    assert next(iter(after["from"])) == "follower-2" and after["from"]["follower-2"] == 119
    assert after["seen_by"]["follower-2"] == 3
    assert all(n == 1 for s, n in after["seen_by"].items() if s != "follower-2")
    text = refusal_text(after)
    assert text is not None and "(from follower-2 119 seen by 3, " in text


def test_one_process_cannot_outweigh_the_others_who_refused_a_sender() -> None:
    """Two senders each refused by two processes: the one with the larger count from the
    honest witness ranks first, however much a single other witness claims."""
    status = {
        "follower-1": {"rejected_from_follower-2": 50},
        "recorder-0": {"rejected_from_follower-2": 60, "rejected_from_follower-0": 1},
        "follower-2": {"rejected_from_follower-0": 10**9},
    }
    summed = launch_refusals({"status": status})
    assert list(summed["from"]) == ["follower-2", "follower-0"]
    assert summed["seen_by"] == {"follower-2": 2, "follower-0": 2}


def test_a_status_naming_no_process_or_holding_garbage_is_skipped() -> None:
    summed = launch_refusals({"status": {"follower-1": "garbage", "follower-3": {
        "rejected_from_": 5, "rejected_from_follower-2": -3, "rejected_from_sim-0": True}},
        "launcher": {"rejected_from_follower-2": 2}})
    assert summed == {"from": {"follower-2": 2}, "seen_by": {"follower-2": 1}}
