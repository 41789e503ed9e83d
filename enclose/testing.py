"""The pytest plugin of enclose (entry point `pytest11`): fixtures for users' own tests.

- `enclose_sim`: the vehicle simulator as a process on ports of its own, stopped after the
  test; yields its `enclose.simulator.SimEndpoints` (a client connects to
  `enclose_sim[0].mavsdk_address`). Configure with
  `@pytest.mark.enclose_sim(vehicles=2, flavour="ardupilot", signing=True)`.
- `enclose_swarm`: a short networked run (`enclose.run`) into the test's temporary folder,
  as its `enclose.Run`. Configure with
  `@pytest.mark.enclose_swarm(scenario="paper", duration_s=10.0, **run_overrides)`.

Both take the next free port block (deploy.launch.port_slots) when a port of one is held, by any
process, the test's own included (a connection a failed test's traceback keeps open): one
failure does not fail every later test.  DeployError names the ports only when no block
is free.

An installed enclose loads it by its entry point; from a source tree, `-p enclose.testing`.
"""

from __future__ import annotations

import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from enclose.results import Run
from enclose.simulator import SimEndpoints, running_sim

SWARM_DURATION_S = 10.0


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "enclose_sim(vehicles=1, flavour='px4', signing=False): the simulator "
        "the enclose_sim fixture starts")
    config.addinivalue_line(
        "markers", "enclose_swarm(scenario='paper', duration_s=10.0, **overrides): the run "
        "the enclose_swarm fixture makes (overrides: enclose.run's)")


def _marker_kwargs(request: pytest.FixtureRequest, name: str) -> dict[str, Any]:
    marker = request.node.get_closest_marker(name)
    return dict(marker.kwargs) if marker is not None else {}


@pytest.fixture
def enclose_sim(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[SimEndpoints]:
    """The simulator with the marker's vehicles, flavour and signing, stopped after the test."""
    with running_sim(workdir=tmp_path / "enclose-sim",
                     **_marker_kwargs(request, "enclose_sim")) as sim:
        yield sim


@pytest.fixture
def enclose_swarm(request: pytest.FixtureRequest, tmp_path: Path) -> Run:
    """A networked run of the marker's scenario (default: the paper's case, 10 s)."""
    from deploy.launch.port_slots import port_slot
    from deploy.launch.ports import ports_held
    from enclose.api import run

    kwargs = _marker_kwargs(request, "enclose_swarm")
    scenario = kwargs.pop("scenario", None)
    kwargs.setdefault("duration_s", SWARM_DURATION_S)
    kwargs.setdefault("out", tmp_path / "enclose-run")
    kwargs.setdefault("swarm", f"pytest-{secrets.token_hex(4)}")
    # The ports no other run or simulator on this machine takes, and no process holds: a
    # socket an earlier test left open sends this run to the next block.
    with port_slot(held=lambda ports: ports_held(ports, tcp=True)) as slot:
        kwargs.setdefault("port_range", slot.flag)
        return run(scenario, **kwargs)
