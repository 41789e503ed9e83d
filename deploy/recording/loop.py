"""The recorder's single loop: drain the bus, record it raw, decode, feed the assembler.

Side effects live here only: the MCAP file, progress.json, the recorder's ProcessStatus and
liveliness token, and at the end the run's outputs.  Every sample on a known key is recorded
as it arrived; follower states and observations are decoded later, in batches
(deploy.recording.intake).  Bad payloads are counted by the `Decoder` and never reach the
series; the MCAP holds refused states and observations as they came (readers check them).
"""

from __future__ import annotations

import logging
import math
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

from agents.loading.law_loader import make_law
from agents.membership.liveness import MembershipWatch
from agents.scenario.model import Scenario
from deploy.json_files import write_json_atomic
from deploy.procs.forked import trim_heap
from deploy.recording.assembler import RunAssembler
from deploy.recording.intake import Intake, Slot
from deploy.recording.links import followers_pending
from deploy.recording.live_defaults import PROGRESS_FILE
from deploy.recording.live_server import LiveServer
from deploy.recording.mcap_log import DEFAULT_CHUNK_BYTES, McapLog
from deploy.recording.queues import DRAIN_PIECE, drain_pieces, queue_capacities
from deploy.recording.recorder_report import MCAP_FILE, counters, progress, status_counters
from deploy.recording.resume import carry_on
from deploy.recording.view import DEFAULT_SCENE_HZ, LiveView
from deploy.recording.view_feed import ViewFeed
from deploy.report.link_history import LinkHistory
from deploy.report.rundir import RunInfo
from errors import CodecError, TransportError
from transport.access import sender_ids
from transport.bus import Bus, Congestion, Received
from transport.codec import encode
from transport.decoder import Decoder
from transport.key_exprs import SwarmKeys
from transport.message_checks import RECORDER_LIMITS
from transport.messages import FollowerState, Message, ProcessStatus, Stamper

log = logging.getLogger(__name__)

ROLE = "recorder"
# After a busy stretch its memory (decoded samples, Zenoh's buffers) is free but still
# resident: hand it back, at most this often.
TRIM_EVERY_S = 10.0
OVERDUE_GRACE_S = 30.0  # stop on our own this long after the planned end if no "stop" came
FINAL_STATUS_WAIT_S = 2.0  # after the stop, for the followers' "done" counters (links)
# The loop's nap when nothing is queued.  Every wake-up costs a step over all the rings
# whether anything came or not: at 5 ms the paper's case (~240 messages a second) woke
# 200 times a second for about one message each.  20 ms still shows the live view's
# 10 Hz scene on time; what arrives meanwhile waits in its ring, and its receive stamp
# (the MCAP's log time) is taken when it is drained, at most this much later.
POLL_S = 0.02
PEEK_S = 0.1  # the newest states decoded for the live view and progress (its scene rate)


class Recorder:
    """Owns the subscription, decoder, assembler and MCAP file of one recording."""

    def __init__(self, bus: Bus, swarm: str, scenario: Scenario, run_dir: Path,
                 index: int = 0, period_s: float = 1.0,
                 final_status_wait_s: float = FINAL_STATUS_WAIT_S,
                 chunk_bytes: int = DEFAULT_CHUNK_BYTES, live: LiveServer | None = None,
                 scene_hz: float | None = DEFAULT_SCENE_HZ, record_sensor: bool = True,
                 figures: bool = True) -> None:
        self.bus, self.scenario, self.run_dir = bus, scenario, run_dir
        self.figures = figures  # drawn at the end (False: `enclose report` draws them later)
        run_dir.mkdir(parents=True, exist_ok=True)
        self.keys = SwarmKeys(swarm)
        self.index = index
        self.period_s = period_s
        self.final_status_wait_s = final_status_wait_s
        self.follower_status: dict[int, ProcessStatus] = {}  # latest, per follower index
        self.link_history = LinkHistory(run_dir)  # links.csv, links.png, progress.json "links"
        self.newest_stamp_s = -math.inf  # newest sender stamp processed: how far behind we are
        self.mcap = McapLog(run_dir / MCAP_FILE, chunk_size=chunk_bytes,
                            metadata={"swarm": swarm, "scenario": scenario.name})
        # Implausible messages, and any not from the process its key names, dropped,
        # counted; a state whose law fields are not what the scenario's law declares too,
        # as its followers drop it (transport.law_fields).
        self.decoder = Decoder(limits=RECORDER_LIMITS, senders=sender_ids(scenario.n, scenario.m),
                               law_fields=make_law(scenario).declared())
        self.decode_cpu_s = 0.0  # in the deferred batches
        senders = sender_ids(scenario.n, scenario.m)
        self.intake = Intake(self.mcap, self.decoder, senders, scenario.n)
        self.asm = RunAssembler(scenario.n, scenario.m, spill_dir=run_dir,  # rows on disk
                                recent_from_adds=False)
        self.state = "starting"
        self.stop_reason = ""
        self.info = RunInfo.from_scenario(scenario, "networked", scenario.run.duration_s)
        # The live view's frames go into the MCAP always (replay looks as live did) and to
        # the WebSocket server when there is one; scene_hz None turns the view off.
        self.feed = ViewFeed(self.mcap, None if scene_hz is None else LiveView(
            self.info, scene_hz, self.intake.arrivals), live)
        self._next_peek_s = -math.inf
        self._stamper = Stamper(f"{ROLE}-{index}", bus.now_s)
        self._status = bus.declare_publisher(self.keys.status(ROLE, index), Congestion.DROP)
        # Everything but the followers' estimator-rate states (issue 15): up to 400 per
        # second per follower, for their neighbours; the 50 Hz states carry the same estimate.
        # Without `record_sensor`, not the target observations either: noiseless, they are
        # the truth's target positions again, and in ring64 they were half of what the
        # recorder decoded (1 280 a second), where it fell seconds behind.
        self._subs = [bus.subscribe(k, capacity, hlc=False) for k, capacity in
                      queue_capacities(self.keys, scenario, record_sensor).items()]
        # After the subscription: what arrives while we read back waits in its queue.
        self.carried: Counter[str] = Counter()
        self._carry_on()
        # progress.json names the live URL before anyone sees us linked (deploy.launch.launcher).
        write_json_atomic(self.run_dir / PROGRESS_FILE, self.progress())
        self._token = bus.declare_token(self.keys.alive(ROLE, index))
        # Followers in and out, as they see it themselves (agents.membership.liveness): the phases
        # of the run's metrics and the marks on its figures.
        self.liveness = MembershipWatch(bus, self.keys, scenario.n)
        self.membership: list[tuple[float, frozenset[int]]] = []
        self.started_wall_s = bus.now_s()
        self._next_tick_s = 0.0
        self._set_state("linked")

    # ---- one iteration -------------------------------------------------------------------
    def step(self) -> int:
        """Empty the rings: record every sample, decode what is decoded now (deferred
        states once a batch waits); the number of samples taken."""
        # Membership first: its events must not wait behind a backlog of samples.
        now = self.bus.now_s()
        members = self.liveness.members(now)
        if members and (not self.membership or members != self.membership[-1][1]):
            self.membership.append((now, members))
        taken, shown = 0, False
        for sub in self._subs:
            for piece in drain_pieces(sub):
                taken += len(piece)
                shown |= self._decode_now(self.intake.take(piece))
        if self.intake.due(now):
            self.decode_deferred()
        if now >= self._next_peek_s:
            self._next_peek_s = now + PEEK_S
            for msg, recv_s in self.intake.peek():
                self.feed.add(msg, recv_s)
                if isinstance(msg, FollowerState):
                    self.asm.note_recent(msg)
                shown = True
        if shown:
            self.feed.show_new()
        if self.asm.start is not None and self.state == "linked":
            self.info = RunInfo.from_scenario(self.scenario, "networked",
                                               self.asm.start.duration_s)
            self._set_state("running")
        return taken

    def _decode_now(self, items: list[tuple[Slot, Received]]) -> bool:
        """Decode, record if accepted and use; True if any was."""
        shown = False
        for _, rec in items:
            inbound = self.decoder.decode(rec)
            if inbound is None:
                continue
            msg = inbound.message
            self.mcap.write(rec.key, msg, rec.recv_stamp_s)
            self._use(msg)
            self.feed.add(msg, rec.recv_stamp_s)
            shown = True
        return shown

    def decode_deferred(self) -> None:
        """The deferred states and observations waiting, decoded into the assembler."""
        t0 = time.process_time()
        for msg in self.intake.decoded():
            self._use(msg)
        self.decode_cpu_s += time.process_time() - t0

    def _use(self, msg: Message) -> None:
        if msg.header.sender_id != self._stamper.sender_id:  # our own status is always fresh
            self.newest_stamp_s = max(self.newest_stamp_s, msg.header.stamp_s)
        self.asm.add(msg)
        if isinstance(msg, ProcessStatus) and msg.role == "follower":
            self.follower_status[msg.index] = msg
            self.link_history.add(msg)

    def _carry_on(self) -> None:
        """A restarted recorder: take over what the dead one recorded (deploy.recording.resume)."""
        carry_on(self.run_dir, self.carried, self.mcap.write_raw, self._take_carried)

    def _take_carried(self, rec: Received) -> None:
        self._decode_now(self.intake.take([rec]))
        if self.carried["messages"] % 4096 == 0:  # in bounded batches here too
            self.decode_deferred()

    def tick(self) -> None:
        """Once a period: flush the MCAP, publish status, write progress.json."""
        now = self.bus.now_s()
        if now < self._next_tick_s:
            return
        self._next_tick_s = now + self.period_s
        self.feed.tick(now, self.membership[-1][1] if self.membership else None)
        self.mcap.flush()
        self._publish_status()
        write_json_atomic(self.run_dir / PROGRESS_FILE, self.progress())

    def overdue(self) -> bool:
        start = self.asm.start
        if start is None:
            return False
        return self.bus.now_s() > start.start_stamp_s + start.duration_s + OVERDUE_GRACE_S

    def run(self, stop_requested: Callable[[], bool], poll_s: float = POLL_S) -> str:
        """Loop until RunControl "stop", a signal (`stop_requested`) or overdue; the reason."""
        was_behind, trimmed_at = False, -math.inf
        while True:
            behind = self.step() >= DRAIN_PIECE  # then straight on, without the poll's nap
            if was_behind and not behind and time.monotonic() - trimmed_at >= TRIM_EVERY_S:
                trim_heap()
                trimmed_at = time.monotonic()
            was_behind = behind
            self.tick()
            if self.asm.stopped:
                self.stop_reason = "control_stop"
            elif stop_requested():
                self.stop_reason = "signal"
            elif self.overdue():
                self.stop_reason = "overdue"
            if self.stop_reason:
                break
            if not behind:
                time.sleep(poll_s)
        self.step()  # whatever arrived with the stop word (a full ring's worth at most)
        log.info("recording stops: %s", self.stop_reason)
        self.await_final_statuses(poll_s)
        return self.stop_reason

    def await_final_statuses(self, poll_s: float) -> bool:
        """Keep draining until every follower heard from has said "done" (bounded wait).

        Their final counters say what each link delivered.  Nothing is awaited when no
        follower status was ever heard (no followers on this bus).  True if all came.
        """
        deadline = time.monotonic() + self.final_status_wait_s
        while self.follower_status and (
                pending := followers_pending(self.follower_status, self.scenario.n)):
            if time.monotonic() > deadline:
                log.warning("no final status from followers %s: links use their last", pending)
                return False
            time.sleep(max(poll_s, 0.001))
            self.step()
        return True

    # ---- the end -------------------------------------------------------------------------
    def finish(self) -> bool:
        """Close the MCAP first (it must survive), then write outputs; True if metrics exist."""
        self._set_state("stopping")
        self.feed.stop()
        self.mcap.close()
        try:
            self.decode_deferred()  # the last batch
            # Imported here: it needs pyarrow and its figures matplotlib (~1 s of imports),
            # which would otherwise delay the recorder's start, and so every run's.
            from deploy.recording.outputs import write_final_outputs

            metrics = write_final_outputs(self.run_dir, self.scenario, self.asm, self.counters(),
                                          self.membership, self.link_history, self.figures)
        except Exception:
            log.exception("writing the run outputs failed")
            metrics = None
        finally:
            self.asm.close()
            self.link_history.close()
        self._set_state("done" if metrics is not None else "failed")
        write_json_atomic(self.run_dir / PROGRESS_FILE, self.progress())
        return metrics is not None

    # ---- reporting -----------------------------------------------------------------------
    def counters(self) -> dict[str, Any]:
        """The recorder's share of metrics.json."""
        return counters(self)

    def progress(self) -> dict[str, Any]:
        return progress(self)

    def _publish_status(self) -> None:
        msg = ProcessStatus(self._stamper.header(), ROLE, self.index, self.state,
                            status_counters(self), self.stop_reason)
        try:
            self._status.put(encode(msg))
        except (TransportError, CodecError):  # best effort: never ends the recording
            log.exception("status publish failed")

    def _set_state(self, state: str) -> None:
        if state != self.state:
            log.info("recorder %s", state)
            self.state = state
            self._publish_status()
