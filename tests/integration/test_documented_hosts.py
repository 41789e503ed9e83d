"""docs/multihost.md followed to the letter, on two namespaced hosts of this machine: one
deployment file, `enclose keys creds/ --deployment deployment.toml`, then on each host
`enclose host deployment.toml --host NAME --credentials creds/NAME/` as a process of its
own (tests.integration.two_hosts).  The companion holds no launcher and needs none of its
files; the ground's simulator does not wait for the companion's sensing link, so its
targets find their vehicles whichever host is up first.  The run ends inside the paper's
bounds, and no host's output or process log holds a traceback."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from deploy.hosts.namespaced_hosts import unavailable
from tests.integration.real_time import judged
from tests.integration.runs import wait_for
from tests.integration.two_hosts import COMPANION, GROUND, two_hosts

pytestmark = pytest.mark.integration
REASON = unavailable()
DURATION_S = 30.0


@pytest.mark.skipif(REASON is not None, reason=f"two hosts: {REASON}")
@pytest.mark.timeout(300)
@pytest.mark.serial  # a swarm and two routers on two cores, as test_hosts_run
@pytest.mark.parametrize("first", [COMPANION, GROUND])
def test_the_documented_two_host_start_flies_the_paper_case(tmp_path: Path,
                                                            first: str) -> None:
    with two_hosts(tmp_path) as hosts:
        args = {COMPANION: [], GROUND: ["--duration", str(DURATION_S), "--out", "runs/field"]}
        second = GROUND if first == COMPANION else COMPANION
        hosts.start_host(first, *args[first])
        # The second a little later, as a person would start it: once the first host's
        # session to its router is open.
        wait_for(lambda: "linked 0/" in hosts.output(first), 60.0, f"{first} to start")
        hosts.start_host(second, *args[second])
        hosts.wait_all(DURATION_S + 180.0)
        codes = {name: p.returncode for name, p in hosts.procs.items()}
        outputs = {name: hosts.output(name) for name in hosts.procs}
        assert hosts.tracebacks() == [], outputs
    assert codes == {COMPANION: 0, GROUND: 0}, outputs
    run = tmp_path / "runs" / "field"
    metrics = json.loads((run / "metrics.json").read_text())
    launch = json.loads((run / "launch.json").read_text())
    assert launch["events"] == [], launch["events"]
    assert {n for n in launch["status"] if n.startswith("follower-")} == {
        f"follower-{i}" for i in range(4)}
    with judged(run):
        assert metrics["estimator_error_m"] < 0.0999
        assert metrics["radius_error_m"] < 0.0999
        assert metrics["angle_error"] < 0.0199
    # The companion's part ran on its own folder: no launcher, simulator or CA key there.
    held = {p.name for p in (tmp_path / "creds" / COMPANION).iterdir()}
    assert not {"launcher.key", "sim.key", "ca.key", "mavlink-secret.bin"} & held
