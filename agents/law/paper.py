"""The paper's law for one follower: its LAP estimator (plain or robust, with the optional
velocity stage) and its enclosing controller, as a law of agents.law.interface.

Every input is a timestamped sample the platform keeps (agents.follower.inputs).  A step
extrapolates them to `now_s` with their rates (first order, held after `setup.hold_s`),
integrates the estimator over `dt_s`, and, on a control tick, computes the command on the
state predicted `lead_s` ahead.  A neighbour or successor older than `setup.stale_s` is
missing: its link carries no flow (neither end integrates on it, so a link's two flows
still cancel for the paper's estimator; the robust one keeps the neighbour's link sum as
last known), and a missing successor drops the spacing term (radius and rotation go on,
as if it were where it should be) instead of chasing a stale bearing.

The equations are agents.law's, each written once (consensus, velocity_stage, enclosing,
sig; the carry of agents.law.carry), and wired to the gains once (agents.law.paper_wiring:
the lock-step kernel compiles the same wiring);
plane vectors are complex x + iy
(numpy's per-call cost was most of a step's at 2-vectors, issue 15).  Its options come
from the scenario: [network] estimator ("paper" or "robust") and [gains] (estimator_order
2 adds the velocity stage, robust only; lead_s).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

from agents.law.carry import REBASE_TAU_S, next_carry
from agents.law.consensus import EstimatorParams, link_balance
from agents.law.enclosing import ControlGains
from agents.law.interface import FieldSpec, Inputs, Law, Output, Peer, Setup, reference
from agents.law.paper_wiring import command, estimator_flows, gains_of
from agents.law.scenario_params import control_gains, estimator_params
from agents.law.velocity_stage import fed_flow, lap_velocity
from errors import ScenarioError

if TYPE_CHECKING:
    from agents.scenario.model import Scenario

# The bounds a receiver holds these fields to: those of the platform's own positions,
# speeds and accelerations (transport.message_checks.Limits): beyond them, a forgery or a fault.
MAX_POS_M, MAX_SPEED_M_S, MAX_ACCEL_M_S2 = 1e5, 1e3, 1e4
# Time constant of the low-passed data ages that scale each link's step limit.
AGE_TAU_S = 0.5

ROBUST = (  # per link, the running sum of this follower's flow on it and its rate
    FieldSpec("link_sums_m", "per_link", MAX_POS_M, rate="link_rates_m_s", odd=True),
    FieldSpec("link_rates_m_s", "per_link", MAX_SPEED_M_S),
)
SECOND_ORDER = (  # the velocity stage: rv_i, and its link sums and their rates
    FieldSpec("rv_m_s", "vec2", MAX_SPEED_M_S),
    FieldSpec("vel_sums_m_s", "per_link", MAX_SPEED_M_S, rate="vel_rates_m_s2"),
    FieldSpec("vel_rates_m_s2", "per_link", MAX_ACCEL_M_S2),
)

# A NamedTuple built without its Python-level __new__: half the cost, same object.  The
# per-link sequences of a step are one per neighbour by construction: their zips are not
# strict (a strict zip costs a fifth of a microsecond, and a step makes several).
_new = tuple.__new__
Links = tuple[complex, ...]


@dataclass(frozen=True)
class Derived:
    """What a step needs of a Setup, worked out once per Setup."""

    nbr_steps: tuple[tuple[int, float], ...]  # (neighbour, edge fraction * estimator step)
    rotation: complex  # e^(i angle): a missing successor stands where it should be
    gains: tuple[float, ...]  # agents.law.paper_wiring.gains_of, at this estimator step

    @staticmethod
    def of(setup: Setup, estimator: EstimatorParams, control: ControlGains) -> Derived:
        step = setup.est_period_s
        return Derived(
            tuple((j, f * step) for j, f in zip(setup.neighbours, setup.nbr_fractions,
                                                strict=True)),
            complex(math.cos(setup.angle_rad), math.sin(setup.angle_rad)),
            gains_of(estimator, control, step))


class PaperState(NamedTuple):
    """One follower's estimator state; immutable (never mutate its maps)."""

    derived: Derived
    phi_m: complex = 0j
    phi_rate_m_s: complex = 0j
    peer_age_s: Mapping[int, float] = {}  # low-passed data age per peer
    link_sums_m: Links | None = None  # robust: per neighbour (setup order)
    link_rates_m_s: Links | None = None
    carry_m: complex = 0j  # agents.law.carry
    vel_sums_m_s: Links | None = None  # order 2
    vel_rates_m_s2: Links | None = None
    rv_m_s: complex = 0j


class PaperLaw(Law[PaperState]):
    """The paper's estimator and enclosing controller."""

    name = "paper"

    def __init__(self, estimator: EstimatorParams, control: ControlGains, robust: bool,
                 lead_s: float = 0.0) -> None:
        self.estimator, self.control, self.lead_s = estimator, control, lead_s
        self.robust = robust
        self.second_order = robust and estimator.order == 2
        # The paper's estimator needs nothing but r_j: its Phi_i stays its own.
        self.fields = (*(ROBUST if robust else ()), *(SECOND_ORDER if self.second_order else ()))

    @classmethod
    def from_params(cls, table: Mapping[str, object], scenario: Scenario) -> PaperLaw:
        """No parameters of its own: its gains are the scenario's [gains], its estimator
        [network] estimator."""
        for key in table:
            raise ScenarioError(f"law.{key}", "the paper's law takes its gains from [gains] "
                                "and its estimator from [network]; no [law] parameters")
        return cls(estimator_params(scenario), control_gains(scenario),
                   scenario.network.estimator == "robust", scenario.gains.lead_s)

    def start(self, setup: Setup) -> PaperState:
        return PaperState(Derived.of(setup, self.estimator, self.control))

    def regroup(self, state: PaperState, old: Setup, new: Setup) -> PaperState:
        """Ages of peers kept, link sums of links kept (a new link's start at zero)."""
        peers = set(new.peers)
        kept = {j: k for k, j in enumerate(old.neighbours)}

        def per_new_link(per_old: Links | None) -> Links | None:
            if per_old is None:
                return None
            return tuple(per_old[kept[j]] if j in kept else 0j for j in new.neighbours)

        s = state
        return s._replace(derived=Derived.of(new, self.estimator, self.control),
                          peer_age_s={j: a for j, a in s.peer_age_s.items() if j in peers},
                          link_sums_m=per_new_link(s.link_sums_m),
                          link_rates_m_s=per_new_link(s.link_rates_m_s),
                          vel_sums_m_s=per_new_link(s.vel_sums_m_s),
                          vel_rates_m_s2=per_new_link(s.vel_rates_m_s2))

    def step(self, state: PaperState, inputs: Inputs) -> tuple[PaperState, Output]:
        new, r, dr = self._estimate(state, inputs)
        fields = self._fields(new)
        if not inputs.command:
            return new, _new(Output, (0j, r, dr, fields))
        return new, _new(Output, (self._command(new, inputs, r, dr), r, dr, fields))

    def _estimate(self, state: PaperState, inputs: Inputs,
                  ) -> tuple[PaperState, complex, complex]:
        """The estimator over dt: its new state, r_i and dr_i/dt."""
        setup, peers, now_s, dt = inputs.setup, inputs.peers, inputs.now_s, inputs.dt_s
        ages = _ages(state.peer_age_s, setup, peers, now_s, dt)
        p_tilde, p_tilde_rate = reference(setup, inputs.targets, now_s)
        r_nbrs, fractions, live, their_sums, their_rates = _links(
            setup, state.derived, peers, now_s, ages)
        sums, rates = state.link_sums_m, state.link_rates_m_s
        if self.robust:
            zeros = (0j,) * len(r_nbrs)
            sums = tuple([s + dt * f for s, f in zip(sums or zeros, rates or zeros, strict=False)])
            phi = link_balance(sums, their_sums)
        else:
            phi = state.phi_m + dt * state.phi_rate_m_s
        carry = next_carry(state.carry_m, phi + p_tilde, inputs.rebase_to, dt)
        gains, r_own = state.derived.gains, phi + p_tilde + carry
        flows = estimator_flows(r_own, r_nbrs, fractions, gains)
        if not all(live):
            flows = [f if ok else 0j for f, ok in zip(flows, live, strict=False)]
        vel_sums, vel_rates, rv = state.vel_sums_m_s, state.vel_rates_m_s2, state.rv_m_s
        if self.second_order:
            vel_sums, vel_rates, rv = self._velocity_stage(state, inputs, dt, p_tilde_rate,
                                                           live, fractions)
            flows = [fed_flow(f, s) if ok else 0j
                     for f, s, ok in zip(flows, vel_sums, live, strict=False)]
        if self.robust:
            phi_rate = link_balance(flows, their_rates)
            rates = tuple(flows)
        else:
            phi_rate = sum(flows, 0j)
        r = phi + p_tilde + carry
        dr = phi_rate + p_tilde_rate - carry / REBASE_TAU_S
        new = _new(PaperState, (state.derived, phi, phi_rate, ages, sums, rates, carry,
                                vel_sums, vel_rates, rv))
        return new, r, dr

    def _velocity_stage(self, state: PaperState, inputs: Inputs, dt: float,
                        p_tilde_rate: complex, live: list[bool], fractions: list[float],
                        ) -> tuple[Links, Links, complex]:
        """Order 2: its link sums, new flows, and rv_i."""
        zeros = (0j,) * len(live)
        sums = tuple([s + dt * f for s, f in zip(state.vel_sums_m_s or zeros,
                                                 state.vel_rates_m_s2 or zeros, strict=False)])
        now_s, peers, hold = inputs.now_s, inputs.peers, inputs.setup.hold_s
        theirs, rv_nbrs = [], []
        for j, _ in state.derived.nbr_steps:
            fields = peers[j].fields
            flow = fields.get("vel_sums_m_s")
            if flow is None:
                theirs.append(0j)
            else:
                value, rate, stamp = flow
                theirs.append(value + rate * (min(now_s, stamp + hold) - stamp))
            rv_nbrs.append(fields.get("rv_m_s"))
        rv = lap_velocity(link_balance(sums, theirs), p_tilde_rate)
        flows = estimator_flows(rv, [rv if v is None else v for v in rv_nbrs], fractions,
                                state.derived.gains)
        return sums, tuple([f if ok else 0j for f, ok in zip(flows, live, strict=False)]), rv

    def _command(self, state: PaperState, inputs: Inputs, r: complex, dr: complex) -> complex:
        """The enclosing controller on the state predicted lead_s ahead."""
        setup, now_s, lead = inputs.setup, inputs.now_s, self.lead_s
        at_s = now_s + lead
        own_pos = inputs.own.held(at_s, setup.hold_s)
        r_at = r + dr * lead
        succ = inputs.peers[setup.successor].pos
        if now_s - succ.stamp_s <= setup.stale_s:
            succ_pos = succ.value + succ.rate * (at_s - succ.stamp_s)
        else:  # missing: where it should be, so that only radius and rotation act
            succ_pos = r_at + (own_pos - r_at) * state.derived.rotation
        return command(own_pos, succ_pos, r_at, dr, setup.angle_rad, state.derived.gains,
                       setup.period_s, state.peer_age_s[setup.successor])

    def _fields(self, state: PaperState) -> dict[str, object]:
        fields: dict[str, object] = {}
        if self.robust and state.link_sums_m is not None:
            fields["link_sums_m"], fields["link_rates_m_s"] = state.link_sums_m, \
                state.link_rates_m_s
        if self.second_order and state.vel_sums_m_s is not None:
            fields["rv_m_s"], fields["vel_sums_m_s"], fields["vel_rates_m_s2"] = \
                state.rv_m_s, state.vel_sums_m_s, state.vel_rates_m_s2
        return fields


def _ages(old: Mapping[int, float], setup: Setup, peers: Mapping[int, Peer], now_s: float,
          dt: float) -> dict[int, float]:
    """Each peer's data age, low-passed (AGE_TAU_S), at most the staleness limit."""
    gain = 1.0 - math.exp(-dt / AGE_TAU_S)
    ages = dict(old)
    limit = setup.stale_s
    for j in setup.peers:
        age = min(now_s - peers[j].r.stamp_s, limit)
        prev = ages.get(j)
        ages[j] = age if prev is None else prev + gain * (age - prev)
    return ages


def _links(setup: Setup, derived: Derived, peers: Mapping[int, Peer], now_s: float,
           ages: Mapping[int, float],
           ) -> tuple[list[complex], list[float], list[bool], list[complex], list[complex]]:
    """Per neighbour: r_j carried to now_s, the step-limited edge fraction (it shrinks with
    the age of the data), whether it is live, and (robust) its link sum and rate towards us."""
    hold, limit, step = setup.hold_s, setup.stale_s, setup.est_period_s
    r_nbrs, fractions, live, sums, rates = [], [], [], [], []
    for j, f_step in derived.nbr_steps:
        peer = peers[j]
        value, rate, stamp = peer.r
        r_nbrs.append(value + rate * (min(now_s, stamp + hold) - stamp))
        fractions.append(f_step / max(ages[j], step))
        live.append(now_s - stamp <= limit)
        flow = peer.fields.get("link_sums_m")
        if flow is None:
            sums.append(0j)
            rates.append(0j)
        else:
            value, rate, stamp = flow
            sums.append(value + rate * (min(now_s, stamp + hold) - stamp))
            rates.append(rate if now_s - stamp <= hold else 0j)
    return r_nbrs, fractions, live, sums, rates
