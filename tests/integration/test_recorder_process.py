"""The recorder as a real process on loopback: a short synthetic run in, outputs out."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from functools import partial
from pathlib import Path

import pytest
from mcap.reader import make_reader

from agents.loading.scenario_file import load_scenario
from deploy.report.verdict import read_verdict
from tests.integration import runs
from tests.integration.test_transport_zenoh import free_port
from tests.recorder_synth import SynthRun
from transport.bus import Congestion, wait_until_alive
from transport.codec import decode, encode
from transport.key_exprs import SwarmKeys
from transport.messages import ProcessStatus, Stamper
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig, loopback_endpoint

pytestmark = pytest.mark.integration
REPO = Path(__file__).resolve().parents[2]


# runs.wait_for, polled faster: the recorder answers within milliseconds.
wait_for = partial(runs.wait_for, period_s=0.005)


def start_recorder(swarm: str, out: Path, endpoint: str) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-m", "deploy.recording.recorder", "--scenario", "paper", "--swarm", swarm,
         "--out", str(out), "--listen", endpoint], cwd=REPO)


def stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)


def pubs_keys(keys: SwarmKeys) -> list[str]:
    return [keys.control(), keys.truth(), *map(keys.follower_state, range(4))]


def publish_paced(bus: ZenohBus, run: SynthRun, garbage_at: int, silent: int | None) -> int:
    """Each message at its own sender stamp (wall clock), as the swarm would send it;
    nothing from follower `silent` (it died or starved before its first state)."""
    sent = 0
    for i, (key, msg) in enumerate(run.samples()):
        if silent is not None and key == run.keys.follower_state(silent):
            continue
        delay = msg.header.stamp_s - time.time()
        if delay > 0:
            time.sleep(delay)  # the publishing rate itself, not a synchronisation
        bus.publish(key, encode(msg))
        sent += 1
        if i == garbage_at:
            bus.publish(run.keys.truth(), b"\xc1 not msgpack")
    return sent


@pytest.mark.timeout(90)
@pytest.mark.parametrize("silent", [None, 3], ids=["all", "follower-3-silent"])
def test_recorder_process_records_a_run_and_writes_outputs(
    tmp_path: Path, silent: int | None
) -> None:
    swarm, endpoint = f"rec{os.getpid()}", loopback_endpoint(free_port())
    keys, out = SwarmKeys(swarm), tmp_path / "run"
    scenario = load_scenario("paper")
    proc = start_recorder(swarm, out, endpoint)
    try:
        with ZenohBus(ZenohConfig(connect=(endpoint,))) as bus:
            status = bus.subscribe(keys.status("recorder", 0))
            wait_until_alive(bus.watch_alive(keys.all_alive()), {keys.alive("recorder", 0)}, 20)
            # BLOCK: a lossless feed, every message counted below.
            pubs = [bus.declare_publisher(k, Congestion.BLOCK) for k in
                    (keys.control(), keys.truth(), *map(keys.follower_state, range(scenario.n)))]
            wait_for(lambda: all(p.matched() for p in pubs), 10, "recorder subscription")
            states: list[str] = []

            def recorder_states() -> list[str]:
                states.extend(m.state for m in (decode(r.payload) for r in status.drain())
                              if isinstance(m, ProcessStatus))
                return states

            wait_for(lambda: "linked" in recorder_states(), 10, "status linked")
            run = SynthRun(scenario, keys, time.time() + 0.3, duration_s=2.0)
            control = Stamper("launcher-0")
            bus.publish(keys.control(), encode(run.control(control, "start")))
            sent = publish_paced(bus, run, garbage_at=200, silent=silent)
            wait_for(lambda: (out / "progress.json").is_file(), 10, "progress.json")
            bus.publish(keys.control(), encode(run.control(control, "stop")))
            wait_for(lambda: proc.poll() is not None, 60, "recorder to exit")
            recorder_states()
        assert proc.returncode == 0
    finally:
        stop(proc)
    assert states[0] == "linked" and states[-3:] == ["running", "stopping", "done"]
    metrics = json.loads((out / "metrics.json").read_text())
    print("metrics:", json.dumps({k: metrics[k] for k in (
        "samples", "radius_error_m", "angle_error", "estimator_error_m",
        "state_age_p50_ms", "state_age_p99_ms")}))
    assert 95 <= metrics["samples"] <= 101
    assert metrics["radius_error_m"] < 1e-6 and metrics["angle_error"] < 1e-6
    assert metrics["estimator_error_m"] < 0.01 and metrics["filled_samples"] == 0
    # A follower that never spoke keeps the run (its truth and the others' states) and is
    # named, so that the verdict says INCOMPLETE rather than inside or no verdict.
    assert metrics["silent_followers"] == ([] if silent is None else [silent])
    rec = metrics["recorder"]
    assert rec["dropped"] == {"msgpack": 1} and rec["stop_reason"] == "control_stop"
    assert sum(rec["messages_per_topic"].get(k, 0) for k in pubs_keys(keys)) == sent + 2
    assert all(f["seq_gaps"] == 0 for f in metrics["followers"].values())
    if silent is not None:
        assert metrics["followers"][str(silent)]["states"] == 0
    for name in ("series.csv", "run.json", "performance.png", "trajectory.png"):
        assert (out / name).stat().st_size > 0, name
    with (out / "recording.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    topics = {c.topic for c in summary.channels.values()}
    assert {keys.truth(), keys.control(), keys.follower_state(0),
            keys.status("recorder", 0)} <= topics
    report = subprocess.run([sys.executable, "-m", "deploy.cli", "report", str(out)],
                            cwd=REPO, timeout=60, capture_output=True)
    assert report.returncode == 0, report.stderr.decode()
    assert read_verdict(out, "run").inside is (silent is None)


@pytest.mark.timeout(60)
def test_sigterm_without_truth_keeps_mcap_and_exits_nonzero(tmp_path: Path) -> None:
    swarm, endpoint = f"recterm{os.getpid()}", loopback_endpoint(free_port())
    keys, out = SwarmKeys(swarm), tmp_path / "run"
    proc = start_recorder(swarm, out, endpoint)
    try:
        with ZenohBus(ZenohConfig(connect=(endpoint,))) as bus:
            wait_until_alive(bus.watch_alive(keys.all_alive()), {keys.alive("recorder", 0)}, 20)
        proc.send_signal(signal.SIGTERM)
        wait_for(lambda: proc.poll() is not None, 30, "recorder to exit")
        assert proc.returncode == 1
    finally:
        stop(proc)
    assert "no truth" in json.loads((out / "metrics.json").read_text())["error"]
    with (out / "recording.mcap").open("rb") as f:
        assert make_reader(f).get_summary() is not None  # finished properly, not truncated
