"""What a control law is to enclose: what it reads, what it publishes, what it commands.

A law is a class with a `name`, a parameter check `from_params(table, scenario)`, the
fields it publishes (`fields`), and three methods on a state of its own:
`start(setup)` makes one follower's state, `step(state, inputs)` advances it and says
what to fly, `regroup(state, old, new)` carries it across a change of the member set.
The same law object runs in every follower process and in the lock-step engine; it must
not keep per-follower data on itself (that is what its state is for), nor do I/O.

Plane vectors are complex numbers x + iy (ENU metres, m/s): cheap, and `abs`, `*` by
`1j` (a quarter turn) and `.conjugate()` are the geometry a planar law needs.

A step reads (`Inputs`):
- `now_s`: the follower's clock, the one every stamp it is handed is on (`Sample.stamp_s`):
  compare stamps with it, extrapolate with it (`sample.held(now_s, ...)`).  Its origin is
  the engine's: 0 at the start lock-step, but networked the follower's bus clock, whose 0
  is not the run's start;
- `t_s`: the time since the run's start (its start word), on the same clock: 0 at the
  start lock-step and networked, and in a replay what the run had.  Schedule with it
  (gain schedules, finite-time references, anything "20 s into the run");
- `dt_s`: the time since this law's last step (0 at the first, at most
  `setup.max_gap_s`: a paused process does not integrate a jump);
- `command`: True on a control tick (its `u_m_s` is flown); False on an estimator step
  between control ticks (the scenario's `estimator_rate_hz`), whose command is ignored;
- `setup` (`Setup`): this follower's place in the swarm formed by the current members:
  index, neighbours, successor, observed targets and their weights, edge fractions,
  desired angle to the successor, periods, hold and staleness limits;
- `own`: its vehicle's position and velocity, at the telemetry's stamp;
- `targets`: each observed target heard so far (position at its stamp, and the platform's
  velocity estimate of it, as a `Sample`);
- `peers`: the latest message of each neighbour and of the successor (`Peer`): its
  estimate r and rate, its vehicle's position and velocity, and the law's declared fields;
- `rebase_to`: where this follower's estimate should continue from, or None (below).

A step returns (`Output`): the velocity command `u_m_s`, the law's estimate of the targets'
centre `r_m` and its rate `dr_m_s` (recorded and published: the run's metrics judge it,
and neighbours see it in `Peer.r`), and `fields`: the values of its declared fields.

What a law gets for free (the platform does it, the same for every law):
- Inputs, checked: every message is decoded, checked (finite, bounded, from its key's
  owner, not from the future) and mapped onto this follower's clock before a law sees it;
  a message with an undeclared field, or a field of the wrong kind or beyond its bound,
  is dropped and counted.  Only the newest message per neighbour is kept.
- Hold and extrapolation: `Peer.r`, `Peer.pos` and every declared field with a `rate` are
  `Sample`s at their stamp: `sample.held(now_s, setup.hold_s)` extrapolates by the rate,
  held after the hold limit; `setup.stale_s` says when an input counts as missing.
- Readiness: the first step waits until every observed target, neighbour and successor
  was heard; afterwards a peer not heard yet (a new link) stands in as this follower's own
  last estimate, at an age past every limit.
- Targets: their velocity comes from the platform's filter over the sensor's samples.
- Membership: the member set follows the processes alive (Zenoh liveliness); the ring,
  the graph, observers, weights and angles are re-formed (agents.membership.ring) and the law
  gets a new `Setup` through `regroup`, whose default starts afresh.  Subscriptions,
  forgotten peers and link statistics are the platform's.
- Continuity (`rebase_to`): after a change of members, or when this follower (re)joins a
  running swarm, the platform gives the estimate to continue from (its own last estimate
  held to now; on a join, its neighbours' mean) until every observed target was heard.
  A law may use it to keep its estimate continuous (the paper's law carries the jump and
  lets it decay) or ignore it.
- Failsafes: the vehicle holds (zero velocity) while its telemetry is missing, before the
  start, and whenever the law raises, returns a non-finite command or a field it did not
  declare; the follower counts that (`law_failures` in its status), logs the traceback
  once (then rate-limited), keeps ticking and takes the law's next good output.  The
  altitude is held by the platform; a law commands the plane only.
- Publishing: index, estimate, own position and velocity, command, stamps and sequence
  numbers; the law's fields ride along, versioned and checked like the rest.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Generic, NamedTuple, TypeVar

from errors import ScenarioError
from transport.law_fields import FieldSpec, check_specs

if TYPE_CHECKING:
    from agents.scenario.model import Scenario

# A law author imports from this module only: ScenarioError is what `from_params` raises.
__all__ = ["FieldSpec", "Inputs", "Law", "Output", "Peer", "Sample", "ScenarioError", "Setup",
           "Value", "reference"]

S = TypeVar("S")

# A declared field's value as a law sees it: "scalar" a float, "vec2" a complex, "per_link"
# a complex (the entry addressed to this follower; a law publishes one complex per
# `setup.neighbours`, in that order); a field with a `rate` is received as a Sample of
# value and rate.
Value = Any


class Sample(NamedTuple):
    """A stamped plane vector x + iy with its rate (a position and velocity, r and dr/dt)."""

    value: complex
    rate: complex
    stamp_s: float

    def at(self, t_s: float) -> complex:
        """Extrapolated to `t_s` by its rate, however far."""
        return self.value + self.rate * (t_s - self.stamp_s)

    def held(self, t_s: float, limit_s: float) -> complex:
        """Extrapolated to `t_s`, but by at most `limit_s` past its stamp: held after."""
        return self.value + self.rate * (min(t_s, self.stamp_s + limit_s) - self.stamp_s)

    def held_rate(self, t_s: float, limit_s: float) -> complex:
        """Its rate while extrapolating it is allowed, then zero."""
        return self.rate if t_s - self.stamp_s <= limit_s else 0j


class Peer(NamedTuple):
    """A neighbour's (or the successor's) latest message, as this follower keeps it."""

    r: Sample  # its estimate r_j and dr_j/dt, at its message's stamp (our clock)
    pos: Sample  # its vehicle's position and velocity, at that telemetry's stamp
    # Its declared fields by name, at r.stamp_s: a field with a rate as a Sample; a
    # per_link field as the entry addressed to us (absent if it sent us none).
    fields: Mapping[str, Value]


@dataclass(frozen=True)
class Setup:
    """Follower `index`'s place in the swarm formed by `members` (agents.membership.ring)."""

    index: int
    members: tuple[int, ...]
    neighbours: tuple[int, ...]  # sorted
    successor: int  # the next member along the ring (itself when alone)
    peers: tuple[int, ...]  # neighbours and successor, sorted: whose messages a step gets
    observed: tuple[int, ...]  # targets with a non-zero weight
    weights: tuple[tuple[int, float], ...]  # (target, weight): p~_i = sum weight * target
    nbr_fractions: tuple[float, ...]  # per neighbour: 1 / max(deg_i, deg_j)
    angle_rad: float  # desired angle from this follower to its successor, about the centre
    rho_d_m: float  # desired radius (the scenario's pattern)
    w_d_rad_s: float  # desired angular rate
    period_s: float  # control period
    est_period_s: float  # estimator period (= period_s without a faster estimator)
    hold_s: float  # longest extrapolation of any input
    stale_s: float  # an input older than this counts as missing
    max_gap_s: float  # longest dt of one step


class Inputs(NamedTuple):
    """What one step of a law reads (see the module docstring)."""

    now_s: float
    dt_s: float
    command: bool
    setup: Setup
    own: Sample
    targets: Mapping[int, Sample]
    peers: Mapping[int, Peer]
    rebase_to: complex | None
    # Last: a law that builds or unpacks Inputs positionally keeps working.
    t_s: float = 0.0


class Output(NamedTuple):
    """What one step of a law gives: the command, its estimate, its published fields."""

    u_m_s: complex
    r_m: complex
    dr_m_s: complex
    # Declared names only (any may be left out): "scalar" a float, "vec2" a complex,
    # "per_link" a sequence of complex, one per setup.neighbours in that order.
    fields: Mapping[str, Value]


class Law(Generic[S]):
    """Base of every law.  Subclasses set `name` and `fields` (or set `self.fields` in
    `__init__` when they depend on the parameters), and implement `start` and `step`."""

    name: ClassVar[str] = ""
    fields: tuple[FieldSpec, ...] = ()

    @classmethod
    def from_params(cls, table: Mapping[str, object], scenario: Scenario) -> Law[Any]:
        """The law for a scenario's `[law]` table (its name and module keys removed);
        ScenarioError naming `law.<key>` for an unknown or bad parameter.  This default
        takes no parameters."""
        for key in table:
            raise ScenarioError(f"law.{key}", f"unknown parameter of law {cls.name!r}")
        return cls()

    def start(self, setup: Setup) -> S:
        """A new follower's state, before its first step."""
        raise NotImplementedError

    def step(self, state: S, inputs: Inputs) -> tuple[S, Output]:
        """One step: the new state and what to fly and publish."""
        raise NotImplementedError

    def regroup(self, state: S, old: Setup, new: Setup) -> S:
        """The state carried across a change of members from `old` to `new`.  Default:
        start afresh (the estimate stays continuous only through `Inputs.rebase_to`)."""
        return self.start(new)

    def declared(self) -> dict[str, FieldSpec]:
        """`fields` by name; ScenarioError naming the law if the declaration is unusable."""
        try:
            return check_specs(self.fields)
        except ValueError as exc:
            raise ScenarioError("law", f"{self.name or type(self).__name__}: {exc}") from None


def reference(setup: Setup, targets: Mapping[int, Sample], now_s: float,
              ) -> tuple[complex, complex]:
    """This follower's weighted target position p~_i = sum of weight * target, each held
    to `now_s` (a target not heard yet counts as zero), and its rate (zero past the hold)."""
    p, rate, hold = 0j, 0j, setup.hold_s
    for j, w in setup.weights:
        track = targets.get(j)
        if track is not None:
            value, track_rate, stamp = track
            p += w * (value + track_rate * (min(now_s, stamp + hold) - stamp))
            if now_s - stamp <= hold:
                rate += w * track_rate
    return p, rate
