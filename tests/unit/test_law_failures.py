"""A law's bad day in flight: a follower node on the in-memory bus flying a law that raises,
commands a NaN, or publishes a field it did not declare.  The vehicle holds on that tick,
the follower counts it (`law_failures`), logs the traceback once, keeps ticking and flies
the law's next good output."""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from typing import cast

import pytest

from agents.follower.node import FollowerNode
from agents.law.interface import Inputs, Output
from agents.law.paper import PaperLaw, PaperState
from agents.loading.scenario_file import load_scenario
from tests.still_vehicle import StillVehicle
from transport.codec import decode, encode
from transport.key_exprs import SwarmKeys
from transport.memory_bus import MemoryBus, MemoryHub
from transport.messages import FollowerState, Header, TargetObservation

KEYS = SwarmKeys("bad")
PAPER = load_scenario("paper")
pytestmark = pytest.mark.timeout(60)


class Flaky(PaperLaw):
    """The paper's law, but on the steps listed in `bad` it fails in the way named there."""

    def __init__(self, bad: Mapping[int, str]) -> None:
        base = PaperLaw.from_params({}, PAPER)
        super().__init__(base.estimator, base.control, base.robust, base.lead_s)
        self.bad, self.steps = dict(bad), 0

    def step(self, state: PaperState, inputs: Inputs) -> tuple[PaperState, Output]:
        how = self.bad.get(self.steps)
        self.steps += 1
        new, out = super().step(state, inputs)
        if how == "raise":
            raise ZeroDivisionError("the law divided by zero")
        if how == "nan":
            return new, out._replace(u_m_s=complex(math.nan, 0.0))
        if how == "undeclared":
            return new, out._replace(fields={**out.fields, "secret": 1.0})
        if how == "wrong_kind":
            return new, out._replace(fields={**out.fields, "link_sums_m": "north"})
        if how == "nan_field":
            sums = (complex(math.nan, 0.0), *out.fields["link_sums_m"][1:])
            return new, out._replace(fields={**out.fields, "link_sums_m": sums})
        if how == "not_an_output":
            return new, cast(Output, None)
        return new, out


def fly(bad: Mapping[int, str], ticks: int = 8) -> tuple[FollowerNode, StillVehicle, list[int]]:
    """Follower 0 of the paper's case flying Flaky(bad) for `ticks` ticks, its neighbours
    1 and 3 and its target heard before each; returns how many states it published by
    each tick."""
    hub = MemoryHub()
    bus, peers = MemoryBus(hub, "f0"), MemoryBus(hub, "peers")
    for i in range(4):
        peers.declare_token(KEYS.alive("follower", i))
    vehicle = StillVehicle((8.0, 0.0, 10.0))  # fresh, at (8, 0) at 10 m
    node = FollowerNode(PAPER, 0, bus, vehicle, "bad", law=Flaky(bad))
    out = peers.subscribe(KEYS.follower_state(0))
    node.start_s = bus.now_s() - 5.0  # running, at the start together with its ring
    published: list[int] = []
    for k in range(ticks):
        now = bus.now_s()
        for j in (1, 3):
            law = {"link_sums_m": ((0, 0.1 * k, 0.0),),
                   "link_rates_m_s": ((0, 0.1, 0.0),)}
            msg = FollowerState(Header(f"follower-{j}", k, now), j, (float(j), 1.0),
                                (0.0, 0.0), (5.0, 5.0 * j), (0.0, 0.0), (0.0, 0.0), now, law)
            peers.publish(KEYS.follower_state(j), encode(msg))
        obs = TargetObservation(Header("sim-0", k, now), 0, 0, (0.5 * k, 0.0), now)
        peers.publish(KEYS.sensor_targets(0), encode(obs))
        node.tick(now)
        published.append(len(out.drain()) + (published[-1] if published else 0))
    return node, vehicle, published


def test_a_good_law_flies_every_tick() -> None:
    node, vehicle, published = fly({})
    assert node.counters()["law_failures"] == 0
    assert all(math.hypot(x, y) > 0.0 for x, y, _ in vehicle.setpoints)
    assert published == list(range(1, 9))
    node.close()


@pytest.mark.parametrize("how", ["raise", "nan", "undeclared", "wrong_kind", "nan_field",
                                 "not_an_output"])
def test_each_failure_holds_the_vehicle_for_that_tick_only(how: str) -> None:
    node, vehicle, published = fly({3: how})
    assert node.counters()["law_failures"] == 1
    hold = [k for k, (x, y, _) in enumerate(vehicle.setpoints) if x == 0.0 and y == 0.0]
    assert hold == [3]  # and the next good output is flown
    assert all(math.isfinite(v) for sp in vehicle.setpoints for v in sp)
    sent = [b - a for a, b in zip([0, *published], published, strict=False)]
    # A NaN command leaves its estimate and fields good: they are published; any other
    # failure publishes nothing that tick (its neighbours hold its last state).
    assert sent == [1, 1, 1, int(how == "nan"), 1, 1, 1, 1]
    node.close()


def test_the_traceback_is_logged_once_then_rate_limited(caplog: pytest.LogCaptureFixture,
                                                        ) -> None:
    with caplog.at_level(logging.ERROR, logger="enclose.follower"):
        node, _, _ = fly({1: "raise", 2: "raise", 4: "undeclared", 5: "nan"})
    assert node.counters()["law_failures"] == 4
    records = [r for r in caplog.records if "law 'paper' failed" in r.getMessage()]
    assert len(records) == 1  # the first, with its traceback; the rest within 10 s: counted
    assert "ZeroDivisionError: the law divided by zero" in records[0].getMessage()
    assert "Traceback" in records[0].getMessage()
    node.close()


def test_published_law_fields_carry_the_declared_values() -> None:
    """What the node publishes decodes to the law's declared fields, checked by a receiver
    that knows the law."""
    hub = MemoryHub()
    bus, other = MemoryBus(hub, "f0"), MemoryBus(hub, "f1")
    node = FollowerNode(PAPER, 0, bus, StillVehicle((8.0, 0.0, 10.0)), "bad")
    sub = other.subscribe(KEYS.follower_state(0))
    node.tick(bus.now_s())  # before the start: its standing estimate, no law fields
    (received,) = sub.drain()
    msg = decode(received.payload)
    assert isinstance(msg, FollowerState) and msg.law == {}
    assert set(node.runner.declared) == {"link_sums_m", "link_rates_m_s"}
    node.close()
