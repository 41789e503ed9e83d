"""A follower's node: all of one follower's state and its loop body, on a given bus and vehicle.

Apart from `agents.follower`, the process around it (command line, impaired bus, the
vehicle loop of agents.vehicle_loop), so that the node runs on whatever bus and vehicle
it is handed: tests/unit/test_liveness.py builds it on an in-memory bus.
"""

from __future__ import annotations

import logging
import math
import time

from agents.follower_fast import (
    FastSetup,
    FollowerMemory,
    PeerView,
    Sample,
    estimator_tick,
    follower_tick,
    link_flows,
    observe_target,
    peer_view,
    ready,
)
from agents.follower_fast_membership import join_running, regroup, standing_estimate, with_missing
from agents.liveness import MembershipWatch
from agents.mavlink.adapter import MavlinkAdapter, VehicleState
from agents.process import StatusReporter
from agents.scenario.model import Scenario
from transport.bus import Bus, Subscription
from transport.checks import DEFAULT_LIMITS, newer
from transport.codec import encode
from transport.decoder import Decoder
from transport.impairment import ImpairedBus
from transport.keys import SwarmKeys
from transport.link_stats import AgeHistogram, LinkDecoder
from transport.messages import FollowerState, RunControl, Stamper, TargetObservation, vec2

log = logging.getLogger("enclose.follower")
ALTITUDE_GAIN_PER_S = 1.0
# Only a peer's newest state is used, so its queue need only outlast a tick or a short
# pause; kept small so that a flood on one peer's key (a process holding that peer's
# credentials) costs each tick at most this many decodes and never delays the others.
PEER_QUEUE = 8
# A follower first running this long after the start joins a running swarm
# (agents.follower_membership.join_running); at the start all begin together from p~.
JOIN_AFTER_S = 1.0


# The follower runs agents.follower_fast, the twin of agents.follower_logic with plane
# vectors as complex x + iy (held to it by tests/unit/test_follower_fast.py): numpy's
# per-call cost was most of a step's.
def _xy(vec: complex) -> tuple[float, float]:
    return (vec.real, vec.imag)


class FollowerNode:
    """All of one follower's state; `tick` is the loop body, the only place with side effects."""

    def __init__(
        self, scenario: Scenario, index: int, bus: Bus, vehicle: MavlinkAdapter, swarm: str,
        joining: bool = False,
    ) -> None:
        self.scenario = scenario
        self.setup = FastSetup.from_scenario(scenario, index)
        self.members = frozenset(range(scenario.n))
        self.index, self.bus, self.vehicle = index, bus, vehicle
        self.altitude_m = scenario.vehicle.altitude_m
        self.keys = SwarmKeys(swarm)
        self.liveness = MembershipWatch(bus, self.keys, scenario.n)
        self.subs = [
            bus.subscribe(self.keys.sensor_targets(index)),
            bus.subscribe(self.keys.control()),
        ]
        self.peer_subs: dict[int, Subscription] = {}
        self.est_subs: dict[int, Subscription] = {}
        # The estimator's own rate (issue 15): steps between control ticks, each published
        # on a second key so that an update crosses a link in an estimator period.
        self.est_steps = scenario.run.estimator_substeps > 1
        self._follow(set(self.setup.neighbours) | {self.setup.successor})
        self.out = bus.declare_publisher(self.keys.follower_state(index))
        self.stamper = Stamper(f"follower-{index}", bus.now_s)
        self.est_out = bus.declare_publisher(self.keys.follower_estimate(index))
        self.est_stamper = Stamper(f"follower-{index}", bus.now_s)
        self.est_phase_s = self.setup.est_period_s * scenario.tick_phase(index)
        self.last_state: VehicleState | None = None
        self.last_u = 0j
        # Checked, not trusted (transport.checks); + per-link rx and age (transport.link_stats)
        self.decoder: Decoder = LinkDecoder(limits=DEFAULT_LIMITS)
        self.status = StatusReporter(bus, self.keys, "follower", index)
        self.memory = FollowerMemory()
        self.peers: dict[int, PeerView] = {}
        self.start_s: float | None = None
        self.stop_s = math.inf
        # Neighbour-state age at use, whole run; a histogram, not samples: its percentiles
        # are read every second for the status, and np.percentile over 20 000 samples was
        # ~2 ms each time (transport.link_stats.AgeHistogram: 0.1-ms bins, 10-s range).
        self.nbr_ages = AgeHistogram()
        # Started into a running swarm (restarted, or back after a leave): publish nothing
        # until our first estimate continues the neighbours' (agents.follower_membership).
        self.joining = joining

    def _follow(self, peers: set[int]) -> None:
        """Subscribe to exactly the states of `peers` (neighbours and successor).

        Never to our own: alone in the member set (before the others' tokens arrived, at
        start-up) the ring makes us our own successor."""
        peers = peers - {self.index}
        for j in set(self.peer_subs) - peers:
            self.peer_subs.pop(j).close()
            if j in self.est_subs:
                self.est_subs.pop(j).close()
        for j in sorted(peers - set(self.peer_subs)):
            self.peer_subs[j] = self.bus.subscribe(self.keys.follower_state(j), PEER_QUEUE)
            if self.est_steps:
                self.est_subs[j] = self.bus.subscribe(self.keys.follower_estimate(j), PEER_QUEUE)

    def regroup(self, now_s: float) -> None:
        """Re-form around the followers alive now (agents.liveness, agents.membership).

        Not before the start word: the launcher sends it only once every follower is
        linked, so until then the planned ring is the member set.  The tokens seen before
        (followers finish take-off one after another) are partial sets whose links would
        only show up as spurious links in the run's report."""
        members = self.liveness.members(now_s) | {self.index}
        if self.start_s is None or members == self.members:
            return
        new = FastSetup.from_scenario(self.scenario, self.index, members)
        self.memory = regroup(self.memory, self.setup, new)
        # A departed peer's last state (and robust link sums) must not outlive it: if it
        # comes back, it is a new process whose links start from zero.
        self.peers = {j: v for j, v in self.peers.items() if j in members}
        for j in self.members - members:
            self.decoder.forget(self.keys.follower_state(j))
            self.decoder.forget(self.keys.follower_estimate(j))
        log.info(
            "members %s -> %s: neighbours %s, successor %d, angle %.1f deg",
            sorted(self.members), sorted(members), list(new.neighbours), new.successor,
            math.degrees(new.angle_rad),
        )
        self.setup, self.members = new, members
        self._follow(set(new.neighbours) | {new.successor})
        self.status.counters["membership_changes"] += 1
        self.status.counters["members"] = len(members)  # as this follower sees the swarm

    def ingest(self) -> None:
        for sub in [*self.subs, *self.peer_subs.values(), *self.est_subs.values()]:
            for inbound in self.decoder.drain(sub):
                self._apply(inbound.message)

    def _apply(self, msg: object) -> None:
        if isinstance(msg, TargetObservation) and msg.observer_index == self.index:
            self.memory = observe_target(
                self.memory,
                self.setup,
                msg.target_index,
                complex(msg.pos_m[0], msg.pos_m[1]),
                msg.observed_stamp_s,
            )
        elif isinstance(msg, FollowerState) and msg.index in self.peer_subs:
            known = self.peers.get(msg.index)
            if known is None or newer(msg.header.stamp_s, known.r.stamp_s, self.bus.now_s()):
                self.peers[msg.index] = peer_view(msg, self.index)
        elif isinstance(msg, RunControl):
            if msg.command == "start":
                self.start_s = msg.start_stamp_s
                self.stop_s = msg.start_stamp_s + msg.duration_s
            else:
                self.stop_s = min(self.stop_s, self.bus.now_s())

    def tick(self, now_s: float) -> None:
        self.regroup(now_s)
        self.ingest()
        state = self.vehicle.poll()
        # The law is computed for the instant its command leaves, not the tick's nominal
        # one: if we were descheduled since, our inputs are fresher than now_s.
        now_s = max(now_s, self.bus.now_s())
        pos, vel = state.pos_enu_m, state.vel_enu_m_s
        own = Sample(complex(pos[0], pos[1]), complex(vel[0], vel[1]), state.stamp_s)
        r: complex | None = None
        dr, u = 0j, 0j
        running = self.start_s is not None and now_s >= self.start_s
        late = self.start_s is not None and now_s > self.start_s + JOIN_AFTER_S
        if running and (self.joining or late):
            self.memory = join_running(self.memory, self.setup, self.peers, now_s)
        if running and (self.memory.last_r is not None or
                        ready(self.memory, self.setup, self.peers)):
            # The estimator needs no vehicle: it keeps running (and its estimate is what
            # we publish) while our vehicle's telemetry is missing; only the command waits.
            views = with_missing(self.peers, self.setup, self.memory, now_s)
            self.memory, out = follower_tick(self.memory, self.setup, own, views, now_s)
            r, dr, u = out.r_m, out.dr_m_s, out.u_m_s
            self.status.counters["stale_inputs"] += len(out.stale)
            for j in self.setup.neighbours:
                if j in self.peers:
                    self.nbr_ages.add(now_s - self.peers[j].r.stamp_s)
        elif running:
            self.status.counters["ticks_not_ready"] += 1
        if not state.link_ok:
            self.status.counters["ticks_without_vehicle"] += 1
            u = 0j  # hover until our vehicle is heard again
        if r is None:  # not flying the law (yet, or for a moment after a change)
            r = standing_estimate(self.memory, self.setup, now_s)
        self._command(state, u)
        self.last_state, self.last_u = state, u
        if self.joining and self.memory.last_r is None:
            self.status.counters["ticks_joining"] += 1  # p~ would throw the running ring
            return
        self._publish(now_s, state, r, dr, u)

    def idle(self, duration_s: float) -> None:
        """The wait between control ticks (the Ticker's sleep): estimator steps on the
        grid k * est_period + phase (neighbours half a period apart), the last one at
        least half a period before the control tick, which is an estimator step too."""
        until = self.bus.now_s() + duration_s
        period = self.setup.est_period_s
        while self.est_steps:
            now = self.bus.now_s()
            nxt = math.ceil((now - self.est_phase_s) / period) * period + self.est_phase_s
            if nxt > until - 0.5 * period:
                break
            time.sleep(max(nxt - now, 0.0))
            self.estimator_step(self.bus.now_s())
        time.sleep(max(until - self.bus.now_s(), 0.0))

    def estimator_step(self, now_s: float) -> None:
        """Advance the estimator alone and publish the state on the estimator key."""
        if self.last_state is None or self.memory.last_r is None or self.start_s is None:
            return  # the law is not running yet: nothing to advance
        self.ingest()
        views = with_missing(self.peers, self.setup, self.memory, now_s)
        self.memory = estimator_tick(self.memory, self.setup, views, now_s)
        r = self.memory.last_r
        if r is not None:
            self._publish(now_s, self.last_state, r.value, r.rate, self.last_u, estimate=True)

    def _command(self, state: VehicleState, u: complex) -> None:
        climb = ALTITUDE_GAIN_PER_S * (self.altitude_m - state.pos_enu_m[2])
        if not math.isfinite(climb):
            climb = 0.0
        if not self.vehicle.send_velocity_enu((u.real, u.imag, climb)):
            self.status.counters["setpoints_refused"] += 1

    def _publish(
        self, now_s: float, state: VehicleState, r: complex, dr: complex, u: complex,
        estimate: bool = False,
    ) -> None:
        if not (math.isfinite(r.real) and math.isfinite(r.imag)
                and all(math.isfinite(v) for v in state.pos_enu_m)):
            self.status.counters["states_not_published"] += 1
            return
        stamper = self.est_stamper if estimate else self.stamper
        msg = FollowerState(
            stamper.header(now_s),
            self.index,
            _xy(r),
            _xy(dr),
            _xy(self.memory.phi_m),
            vec2(state.pos_enu_m[:2]),
            vec2(state.vel_enu_m_s[:2]),
            _xy(u),
            state.stamp_s,
            link_flows(self.memory, self.setup),
            _xy(self.memory.rv_m_s),
            link_flows(self.memory, self.setup, velocity=True),
        )
        (self.est_out if estimate else self.out).put(encode(msg))

    def counters(self) -> dict[str, int]:
        """Decoder drops and gaps, and the age of neighbour states at use (p50, p99).

        Per link L (`f<j>`: follower j, 0-based; `sensor`): rx_L, rx_dup_L, seq_first_L,
        seq_last_L, age_p50_us_L, age_p99_us_L (transport.link_stats) and imp_<count>_L
        (transport.impairment); states_sent: FollowerStates this follower published, on
        both its keys (a link counts both: its rx and delivered ratio cover the two).
        """
        ages = {}
        p50, p99 = self.nbr_ages.percentile_s(50), self.nbr_ages.percentile_s(99)
        if p50 is not None and p99 is not None:
            ages = {"nbr_age_p50_us": round(p50 * 1e6), "nbr_age_p99_us": round(p99 * 1e6)}
        links = self.bus.counters() if isinstance(self.bus, ImpairedBus) else {}
        sent = self.stamper.next_seq + self.est_stamper.next_seq
        return {**self.decoder.counters(), **ages, **links, "states_sent": sent}

    def close(self) -> None:
        for sub in [*self.subs, *self.peer_subs.values(), *self.est_subs.values()]:
            sub.close()
        self.liveness.close()
        self.out.close()
        self.est_out.close()
