"""A follower's node: its loop on a given bus and vehicle, top to bottom.

`FollowerNode.tick` is the loop: re-form the ring if the members changed
(agents.membership.follower_place via agents.membership.liveness), receive
(agents.follower.inputs), run the law
(agents.follower.runner around an agents.law.interface law), command the vehicle, publish.
Apart from agents.follower.main, the process around it (command line, impaired bus, the
vehicle loop of agents.shell.vehicle_loop), so that the node runs on whatever bus and vehicle it
is handed: tests/unit/test_liveness.py builds it on an in-memory bus.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

from agents.follower.inputs import Latest
from agents.follower.lie import Liar, Published
from agents.follower.plausible import gate_limits, own_side
from agents.follower.runner import LawRunner
from agents.law.interface import Law, Output, Sample
from agents.loading.law_loader import make_law
from agents.mavlink.vehicle import Vehicle
from agents.mavlink.vehicle_types import VehicleState
from agents.membership.follower_place import setup_for, stand_ins
from agents.membership.liveness import MembershipWatch
from agents.membership.member_hold import MemberHold
from agents.scenario.model import Scenario
from agents.shell.process import StatusReporter
from agents.shell.tick_cost import NoCost, TickCost
from errors import CodecError
from transport.access import sender_ids
from transport.bus import Bus, Congestion, Subscription
from transport.codec import encode
from transport.decoder import Decoder
from transport.fastbuild import build
from transport.impairment import ImpairedBus
from transport.key_exprs import SwarmKeys
from transport.law_fields import NO_FIELDS, LawFields
from transport.link_stats import AgeHistogram, LinkDecoder
from transport.message_checks import DEFAULT_LIMITS
from transport.messages import FollowerState, RunControl, Stamper, TargetObservation

log = logging.getLogger("enclose.follower")
ALTITUDE_GAIN_PER_S = 1.0
# Only a peer's newest state is used, so its queue need only outlast a tick or a short
# pause; kept small so that a flood on one peer's key (a process holding that peer's
# credentials) costs each tick at most this many decodes and never delays the others.
PEER_QUEUE = 8
# The vehicle's sensing sends one observation per target per tick, and only the newest of
# each is used.  A queued sample holds Zenoh's whole receive batch (~8 KB): at 1024 (the
# bus's default) the observations sent during take-off, before the first tick drains them,
# were the follower's peak memory (+1.4 MB in the paper's case).
OBSERVATION_QUEUE_PER_TARGET = PEER_QUEUE
# A follower first running this long after the start joins a running swarm
# (LawRunner.join); at the start all begin together from p~.
JOIN_AFTER_S = 1.0


class FollowerNode:
    """All of one follower's state; `tick` is the loop body, the only place with side effects."""

    def __init__(
        self, scenario: Scenario, index: int, bus: Bus, vehicle: Vehicle, swarm: str,
        joining: bool = False, law: Law[Any] | None = None,
    ) -> None:
        self.scenario = scenario
        self.members = frozenset(range(scenario.n))
        self.runner = LawRunner(law or make_law(scenario), setup_for(scenario, index))
        self.latest = Latest(index, self.runner.declared,
                             gate_limits(scenario.pattern.rho_d_m))
        self.index, self.bus, self.vehicle = index, bus, vehicle
        self.altitude_m = scenario.vehicle.altitude_m
        self.keys = SwarmKeys(swarm)
        self.liveness = MembershipWatch(bus, self.keys, scenario.n)
        self.hold = MemberHold(decided=self.members)  # a partition's far side is held
        self.silent: frozenset[int] = frozenset()  # neighbours not heard for a hold
        self._alive: frozenset[int] | None = None  # the token set regroup last decided on
        self.subs = [
            bus.subscribe(self.keys.sensor_targets(index),
                          OBSERVATION_QUEUE_PER_TARGET * max(scenario.m, 1)),
            bus.subscribe(self.keys.control()),
        ]
        self.peer_subs: dict[int, Subscription] = {}
        self.est_subs: dict[int, Subscription] = {}
        # The estimator's own rate (issue 15): steps between control ticks, each published
        # on a second key so that an update crosses a link in an estimator period.
        self.est_steps = scenario.run.estimator_substeps > 1
        self._follow(set(self.runner.setup.peers))
        self.out = bus.declare_publisher(self.keys.follower_state(index), Congestion.DROP)
        self.stamper = Stamper(f"follower-{index}", bus.now_s)
        self.est_out = bus.declare_publisher(self.keys.follower_estimate(index),
                                             Congestion.DROP)
        self.est_stamper = Stamper(f"follower-{index}", bus.now_s)
        self.est_phase_s = self.runner.setup.est_period_s * scenario.tick_phase(index)
        self.last_state: VehicleState | None = None
        self.last_own: Sample | None = None
        self.last_u = 0j
        # Checked, not trusted (transport.message_checks, the law's declared fields);
        # + per-link rx and age (transport.link_stats)
        self.decoder: Decoder = LinkDecoder(limits=DEFAULT_LIMITS,
                                            senders=sender_ids(scenario.n, scenario.m),
                                            law_fields=self.runner.declared)
        self.status = StatusReporter(bus, self.keys, "follower", index)
        self.start_s: float | None = None
        self.stop_s = math.inf
        # Neighbour-state age at use, whole run; a histogram, not samples: its percentiles
        # are read every second for the status, and np.percentile over 20 000 samples was
        # ~2 ms each time (transport.link_stats.AgeHistogram: 0.1-ms bins, 10-s range).
        self.nbr_ages = AgeHistogram()
        # Started into a running swarm (restarted, or back after a leave): publish nothing
        # until our first estimate continues the neighbours' (LawRunner.join).
        self.joining = joining
        # Phase CPU of a tick (agents.shell.tick_cost), set by the loop when it is measured.
        self.cost: TickCost | NoCost = NoCost()
        # The `lie` fault: off unless the launcher's signal turns it on (agents.follower.lie).
        self.liar = Liar(self.runner.declared, seed=index)

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
        self.drained = [*self.subs, *self.peer_subs.values(), *self.est_subs.values()]

    def tick(self, now_s: float) -> None:
        """The loop body: members, receive, the law, the command, publish."""
        cost = self.cost
        self.regroup(now_s)
        cost.mark("members")
        self.ingest()
        cost.mark("receive")
        state = self.vehicle.poll()
        cost.mark("mav_in")
        # The law is computed for the instant its command leaves, not the tick's nominal
        # one: if we were descheduled since, our inputs are fresher than now_s.
        now_s = max(now_s, self.bus.now_s())
        pos, vel = state.pos_enu_m, state.vel_enu_m_s
        own = Sample(complex(pos[0], pos[1]), complex(vel[0], vel[1]), state.stamp_s)
        runner, counters = self.runner, self.status.counters
        running = self.start_s is not None and now_s >= self.start_s
        late = self.start_s is not None and now_s > self.start_s + JOIN_AFTER_S
        if running and (self.joining or late):
            runner.join(self.latest.peers, now_s)
        flying = running and (runner.last_r is not None or self.latest.ready(runner.setup))
        stepped = self._step(now_s, own, command=True) if flying else None
        cost.mark("law")
        if running and not flying:
            counters["ticks_not_ready"] += 1
        u = 0j if stepped is None else stepped[0].u_m_s  # a failed law: hold
        if not state.link_ok:
            counters["ticks_without_vehicle"] += 1
            u = 0j  # hover until our vehicle is heard again
        self._command(state, u)
        cost.mark("mav_out")
        self.last_state, self.last_own, self.last_u = state, own, u
        if self.joining and runner.last_r is None:
            counters["ticks_joining"] += 1  # p~ would throw the running ring
            return
        if stepped is not None:
            out, fields = stepped
            self._publish(now_s, state, out.r_m, out.dr_m_s, u, fields)
        elif not flying:  # not flying the law (yet, or for a moment after a change)
            r = runner.standing_estimate(self.latest.targets, now_s)
            self._publish(now_s, state, r, 0j, u, NO_FIELDS)
        # else the law failed: its neighbours keep its last state until it is stale
        cost.mark("publish")

    def _step(self, now_s: float, own: Sample, command: bool) -> tuple[Output, LawFields] | None:
        """One step of the law on the newest inputs; None if it failed (LawRunner)."""
        runner, latest = self.runner, self.latest
        setup = runner.setup
        self._heard_again(now_s)
        peers = stand_ins(latest.peers, setup, runner.last_r, now_s)
        stepped = runner.step(now_s, command, own, latest.targets, peers, self.cost)
        if stepped is not None:  # what the plausibility checks hold neighbours against
            gate = latest.gate
            armed = self.start_s is not None and now_s >= self.start_s + gate.limits.arm_after_s
            gate.own = own_side(runner.last_r, setup, latest.targets, now_s, stepped[1],
                                runner.declared, armed)
        if command and stepped is not None:
            self.status.counters["stale_inputs"] += latest.stale(setup, peers, now_s)
            for j in setup.neighbours:
                if j in latest.peers:
                    self.nbr_ages.add(now_s - latest.peers[j].r.stamp_s)
        return stepped

    def _heard_again(self, now_s: float) -> None:
        """A neighbour heard again after a silence longer than a hold (a healed cut, a
        held member back) may publish link sums that moved meanwhile (its end re-formed
        without us): the estimate is continued across it as across a change of members."""
        setup, peers = self.runner.setup, self.latest.peers
        silent = frozenset(j for j in setup.neighbours
                           if j in peers and now_s - peers[j].r.stamp_s > setup.hold_s)
        if (self.silent - silent) & set(setup.neighbours) and self.runner.continue_estimate():
            self.status.counters["heard_again"] += 1
        self.silent = silent

    def regroup(self, now_s: float) -> None:
        """Re-form around the followers alive now (agents.membership.liveness,
        agents.membership.ring).

        Not before the start word: the launcher sends it only once every follower is
        linked, so until then the planned ring is the member set.  The tokens seen before
        (followers finish take-off one after another) are partial sets whose links would
        only show up as spurious links in the run's report."""
        alive = self.liveness.members(now_s)
        if self.start_s is None:
            return
        hold = self.hold
        if alive is self._alive and not hold.pending and not hold.held:
            return  # the tokens and the held groups as on the last tick: no change
        self._alive = alive
        members = hold.members(alive | {self.index}, now_s)
        self.status.counters["far_sides_held"] = self.hold.holds
        if members == self.members:
            return
        new = setup_for(self.scenario, self.index, members)
        self.runner.regroup(new)
        self.latest.regroup(new)
        for j in self.members - members:
            self.decoder.forget(self.keys.follower_state(j))
            self.decoder.forget(self.keys.follower_estimate(j))
        log.info(
            "members %s -> %s: neighbours %s, successor %d, angle %.1f deg",
            sorted(self.members), sorted(members), list(new.neighbours), new.successor,
            math.degrees(new.angle_rad),
        )
        self.members = members
        self._follow(set(new.peers))
        self.status.counters["membership_changes"] += 1
        self.status.counters["members"] = len(members)  # as this follower sees the swarm

    def ingest(self) -> None:
        for sub in self.drained:
            for inbound in self.decoder.drain(sub):
                self._apply(inbound.message, inbound.received.recv_stamp_s)

    def _apply(self, msg: object, now_s: float) -> None:
        """`msg`, taken off its queue at `now_s`."""
        if isinstance(msg, TargetObservation) and msg.observer_index == self.index:
            self.latest.observe(self.runner.setup, msg.target_index,
                                complex(msg.pos_m[0], msg.pos_m[1]), msg.observed_stamp_s)
        elif isinstance(msg, FollowerState) and msg.index in self.peer_subs:
            self.latest.receive(msg, now_s)
        elif isinstance(msg, RunControl):
            if msg.command == "start":
                self.start_s = msg.start_stamp_s
                self.latest.gate.origin_s = msg.start_stamp_s
                if isinstance(self.bus, ImpairedBus):  # the network faults' time zero
                    self.bus.set_origin(msg.start_stamp_s)
                self.stop_s = msg.start_stamp_s + msg.duration_s
            else:
                self.stop_s = min(self.stop_s, self.bus.now_s())
            if self.start_s is not None:
                self.runner.window(self.start_s, self.stop_s)

    def idle(self, duration_s: float) -> None:
        """The wait between control ticks (the Ticker's sleep): estimator steps on the
        grid k * est_period + phase (neighbours half a period apart), the last one at
        least half a period before the control tick, which is an estimator step too."""
        until = self.bus.now_s() + duration_s
        period = self.runner.setup.est_period_s
        while self.est_steps:
            now = self.bus.now_s()
            nxt = math.ceil((now - self.est_phase_s) / period) * period + self.est_phase_s
            if nxt > until - 0.5 * period:
                break
            time.sleep(max(nxt - now, 0.0))
            self.estimator_step(self.bus.now_s())
        time.sleep(max(until - self.bus.now_s(), 0.0))

    def estimator_step(self, now_s: float) -> None:
        """Advance the law alone (no command) and publish on the estimator key."""
        state, own = self.last_state, self.last_own
        if state is None or own is None or self.runner.last_r is None or self.start_s is None:
            return  # the law is not running yet: nothing to advance
        self.ingest()
        stepped = self._step(now_s, own, command=False)
        if stepped is not None:
            out, fields = stepped
            self._publish(now_s, state, out.r_m, out.dr_m_s, self.last_u, fields, estimate=True)

    def _command(self, state: VehicleState, u: complex) -> None:
        climb = ALTITUDE_GAIN_PER_S * (self.altitude_m - state.pos_enu_m[2])
        if not math.isfinite(climb):
            climb = 0.0
        if not self.vehicle.send_velocity_enu((u.real, u.imag, climb)):
            self.status.counters["setpoints_refused"] += 1

    def _publish(
        self, now_s: float, state: VehicleState, r: complex, dr: complex, u: complex,
        fields: LawFields, estimate: bool = False,
    ) -> None:
        if not (math.isfinite(r.real) and math.isfinite(r.imag)
                and all(math.isfinite(v) for v in state.pos_enu_m)):
            self.status.counters["states_not_published"] += 1
            return
        stamper = self.est_stamper if estimate else self.stamper
        p, v = state.pos_enu_m, state.vel_enu_m_s
        pos, vel = (float(p[0]), float(p[1])), (float(v[0]), float(v[1]))
        if self.liar.mode is not None:
            told = self.liar.apply(now_s, Published(r, dr, pos, vel, fields))
            r, dr, pos, vel, fields = told.r, told.dr, told.pos, told.vel, told.fields
        # Built without the frozen __init__ (transport.fastbuild): one a tick.
        msg = build(FollowerState, {
            "header": stamper.header(now_s), "index": self.index, "r_m": (r.real, r.imag),
            "dr_m_s": (dr.real, dr.imag), "pos_m": pos, "vel_m_s": vel,
            "u_m_s": (u.real, u.imag), "vehicle_stamp_s": state.stamp_s, "law": fields})
        try:
            payload = encode(msg)
        except CodecError as exc:  # a law field not finite (the platform's fields are)
            self.runner.failed(f"its fields do not encode: {exc}")
            return
        (self.est_out if estimate else self.out).put(payload)

    def counters(self) -> dict[str, int]:
        """Decoder drops and gaps, the age of neighbour states at use (p50, p99), and how
        often the law failed (LawRunner: the vehicle held).

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
        return {**self.decoder.counters(), **self.liveness.counters(), **ages, **links,
                **self.latest.gate.all_counters(), "states_sent": sent,
                "law_failures": self.runner.failures, "states_lied": self.liar.lies,
                **self.cost.counters()}

    def close(self) -> None:
        for sub in self.drained:
            sub.close()
        self.liveness.close()
        self.out.close()
        self.est_out.close()
        if self.runner.journal is not None:
            self.runner.journal.close()
