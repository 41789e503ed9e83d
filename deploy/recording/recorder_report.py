"""What the recorder reports: its share of metrics.json, progress.json, its status counters."""

from __future__ import annotations

from collections import Counter
from typing import Any, Protocol

from agents.membership.liveness import MembershipWatch
from deploy.recording.assembler import RunAssembler
from deploy.recording.intake import Intake
from deploy.recording.links import link_report, unreadable_links
from deploy.recording.mcap_log import McapLog
from deploy.recording.progress import behind_s, live_errors
from deploy.recording.view_feed import ViewFeed
from deploy.report.link_history import LinkHistory
from deploy.report.rundir import RunInfo
from transport.bus import Bus
from transport.decoder import Decoder
from transport.messages import ProcessStatus

MCAP_FILE = "recording.mcap"


class Recorder(Protocol):
    """What a report reads of the recorder (deploy.recording.loop.Recorder)."""

    bus: Bus
    decoder: Decoder
    asm: RunAssembler
    mcap: McapLog
    intake: Intake
    feed: ViewFeed
    liveness: MembershipWatch
    link_history: LinkHistory
    follower_status: dict[int, ProcessStatus]
    carried: Counter[str]
    info: RunInfo
    state: str
    stop_reason: str
    decode_cpu_s: float
    started_wall_s: float
    newest_stamp_s: float


def counters(rec: Recorder) -> dict[str, Any]:
    """The recorder's share of metrics.json."""
    dropped = dict(rec.decoder.dropped) | {
        f"assembler_{k}": v for k, v in rec.asm.drops.items()
    }
    if skipped := unreadable_links(rec.follower_status):
        dropped["link_counters_unreadable"] = skipped
    return {
        "recorder": {
            # In the MCAP, per key: every sample on a known key (deploy.recording.intake).
            "messages_per_topic": dict(sorted(rec.mcap.messages.items())),
            "messages_total": sum(rec.mcap.messages.values()),
            "dropped": dropped,
            # States and observations recorded, then decoded in batches: how many, the
            # largest wait for a batch and the CPU the batches took.
            "deferred": {"decoded": rec.intake.deferred_decoded,
                         "peak_mb": round(rec.intake.peak_bytes / 2**20, 2),
                         "decode_cpu_s": round(rec.decode_cpu_s, 3)},
            "decoder": rec.decoder.counters(),
            "stop_reason": rec.stop_reason,
            "wall_s": rec.bus.now_s() - rec.started_wall_s,
            "mcap_file": MCAP_FILE,
            # Read back from a dead predecessor's MCAP (deploy.recording.resume).
            "carried_on": dict(rec.carried),
            "live": {"url": rec.feed.url, "frames_sent": rec.feed.frames_sent,
                     "frames_per_topic": dict(sorted(rec.mcap.frames.items())),
                     "view_errors": rec.feed.errors},
        },
        "links": link_report(rec.follower_status, rec.asm.state_counts()),
    }


def progress(rec: Recorder) -> dict[str, Any]:
    """progress.json.  Follower states count as they are decoded (in batches)."""
    now = rec.bus.now_s()
    return {
        "state": rec.state,
        "t_s": rec.asm.latest_experiment_time_s(),
        "duration_s": None if rec.asm.start is None else rec.asm.start.duration_s,
        **live_errors(rec.asm, rec.info),
        "truth_samples": rec.asm.truth_count,
        "follower_states": rec.asm.state_counts(),
        "messages_total": sum(rec.mcap.messages.values()),
        "dropped_total": rec.decoder.dropped_total,
        "links": rec.link_history.summary(),
        "recorder_behind_s": behind_s(now, rec.newest_stamp_s),
        "wall_stamp_s": now,
        "live_url": rec.feed.url,
    }


def status_counters(rec: Recorder) -> dict[str, int]:
    out = {**rec.decoder.counters(), **rec.liveness.counters()}
    out["truth"] = rec.asm.truth_count
    out["mcap_messages"] = sum(rec.mcap.messages.values())
    return out
