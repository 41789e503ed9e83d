"""The recorder process's memory stays flat over a run: it does not keep the run in memory.

A real recorder on loopback records a synthetic run at 250 Hz (truth and four follower
states a tick: five times the paper's message rate, so that a minute shows what five would).
Its resident memory, sampled twice a second from the 15th second to the last, must not
trend up: keeping every decoded message cost ~0.6 kB each, ~45 MB a minute here, in every
part of the run.  A backlog does not: on a loaded machine the recorder falls behind now and
then and its queues (bounded) grow to the largest backlog seen, a step of a few MB that
stays; the growth is therefore judged by its median over 5-s stretches, which a ramp
moves and a few steps do not.  The queues' rings are mapped as they first fill, within
their first lap (deploy.recording.queues.queue_capacities): at this rate, the first 25 s.
"""

from __future__ import annotations

import json
import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from agents.loading.scenario_file import load_scenario
from deploy.report.cpu_load import process_status_kb
from tests.integration.test_recorder_process import (
    publish_paced,
    pubs_keys,
    start_recorder,
    stop,
    wait_for,
)
from tests.integration.test_transport_zenoh import free_port
from tests.recorder_synth import SynthRun
from transport.bus import Congestion, wait_until_alive
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.messages import Stamper
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig, loopback_endpoint

pytestmark = pytest.mark.integration
RATE_HZ = 250.0
RUN_S = 40.0
FROM_S = 15.0  # after start-up
STRETCH_S = 5.0  # five stretches: a backlog's step moves one or two
# A quarter of what keeping the messages costs.
MAX_SLOPE_MB_MIN = 10.0


class RssSampler:
    """VmRSS of one process every `period_s`, stamped from the sampler's start."""

    def __init__(self, pid: int, period_s: float = 0.5) -> None:
        self.pid, self.period_s = pid, period_s
        self.samples: list[tuple[float, float]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> RssSampler:
        self._t0 = time.monotonic()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(5)

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            kb = process_status_kb(self.pid, "VmRSS")
            if kb is not None:
                self.samples.append((time.monotonic() - self._t0, kb / 1024))


def median_growth_mb_min(t_s: np.ndarray, mb: np.ndarray, stretch_s: float) -> float:
    """The median over consecutive `stretch_s` stretches of the RSS growth, MB a minute (RSS
    at each stretch's end: the last sample at or before it)."""
    ends = np.arange(t_s[0], t_s[-1] + 1e-9, stretch_s)
    at = mb[np.searchsorted(t_s, ends, side="right") - 1]
    return float(np.median(np.diff(at))) * 60.0 / stretch_s


@pytest.mark.timeout(210)
@pytest.mark.serial  # five times the paper's message rate, and a backlog moves the RSS
@pytest.mark.xdist_group("timed-c")
def test_recorder_rss_does_not_grow_with_the_run(tmp_path: Path) -> None:
    swarm, endpoint = f"mem{os.getpid()}", loopback_endpoint(free_port())
    keys, out = SwarmKeys(swarm), tmp_path / "run"
    scenario = load_scenario("paper")
    proc = start_recorder(swarm, out, endpoint)
    try:
        with ZenohBus(ZenohConfig(connect=(endpoint,))) as bus:
            wait_until_alive(bus.watch_alive(keys.all_alive()), {keys.alive("recorder", 0)}, 20)
            # BLOCK: a lossless feed (the recorder's keeping up is measured, not the transport's).
            pubs = [bus.declare_publisher(k, Congestion.BLOCK) for k in pubs_keys(keys)]
            wait_for(lambda: all(p.matched() for p in pubs), 10, "recorder subscription")
            run = SynthRun(scenario, keys, time.time() + 0.5, duration_s=RUN_S, rate_hz=RATE_HZ,
                           pre_s=0.0, post_s=0.0)
            control = Stamper("launcher-0")
            bus.publish(keys.control(), encode(run.control(control, "start")))
            with RssSampler(proc.pid) as rss:
                publish_paced(bus, run, garbage_at=-1, silent=None)
            bus.publish(keys.control(), encode(run.control(control, "stop")))
            wait_for(lambda: proc.poll() is not None, 90, "recorder to exit")
        assert proc.returncode == 0
    finally:
        stop(proc)
    t, mb = np.array(rss.samples).T
    flying = t >= FROM_S
    slope = median_growth_mb_min(t[flying], mb[flying], STRETCH_S)
    print(f"recorder RSS {mb[flying][0]:.1f} MB at {FROM_S:.0f} s, {mb[flying][-1]:.1f} MB at "
          f"{t[-1]:.0f} s: {slope:+.2f} MB a minute (median of {STRETCH_S:.0f}-s stretches)")
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["samples"] >= 0.95 * RUN_S * RATE_HZ  # it kept up: all of it was recorded
    assert slope < MAX_SLOPE_MB_MIN
