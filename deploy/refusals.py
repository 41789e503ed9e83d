"""What a run's processes refused from the bus, summed: one line for the verdict's
processes row, one object for the live view's status.

Every process counts its refusals in its status counters (transport.decoder:
`<kind>_rejected` and `rejected_from_<sender>` for its most rejected senders;
agents.liveness: `tokens_rejected`, `tokens_held`); these sum them over processes.  A
sender is the process whose key the input came on: with access control on, the one that
put it, whatever it claimed.  On the MAVLink side (agents.mavlink.signing, .rx_gate):
frames refused by their signature (`signing_rejected_<reason>`), datagrams over a tick's
budget or dropped unread by the kernel, peers refused.  Clock probes dropped
(transport.peer_clock: `clock_probes_dropped_<why>`).  A frame signed with another
vehicle's key names the agent that holds that key (the simulator's
`rejected_from_<agent>`, deploy.swarm_sim).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping
from typing import Any

# (label, status counter) in the order shown.
ROWS = (
    ("statuses", "statuses_rejected"),
    ("observations", "observations_rejected"),
    ("states", "states_rejected"),
    ("truth", "truth_rejected"),
    ("control words", "control_rejected"),
    ("tokens", "tokens_rejected"),
    ("token changes held", "tokens_held"),
    ("unsigned MAVLink frames", "signing_rejected_unsigned"),
    ("badly signed MAVLink frames", "signing_rejected_bad_signature"),
    ("MAVLink frames signed with another vehicle's key", "signing_rejected_wrong_key"),
    ("MAVLink frames stamped ahead", "signing_rejected_future"),
    ("replayed MAVLink frames", "signing_rejected_replay"),
    ("malformed MAVLink datagrams", "signing_rejected_malformed"),
    ("unreadable MAVLink frames", "signing_rejected_error"),
    ("MAVLink datagrams cut (each over a whole tick's budget)", "mav_flood_drops"),
    ("MAVLink datagrams the kernel dropped", "mav_kernel_drops"),
    ("MAVLink peers (table full)", "peers_refused"),
    ("MAVLink signing streams forgotten (table full)", "signing_streams_evicted"),
    ("clock probes from no router", "clock_probes_dropped_sender"),
    ("clock probes with impossible times", "clock_probes_dropped_times"),
    ("clock probes too close together", "clock_probes_dropped_rate"),
    ("clock probes over the offset step", "clock_probes_dropped_step"),
)
FROM_PREFIX = "rejected_from_"
SENDERS_SHOWN = 3


def _count(v: Any) -> int:
    return v if isinstance(v, int) and not isinstance(v, bool) and v > 0 else 0


def refusals(counters: Iterable[Mapping[str, Any]]) -> dict[str, Any]:
    """{label: total} of the non-zero rows, and "from": {sender: total} of the
    SENDERS_SHOWN senders most refused, over the processes' `counters`."""
    rows: Counter[str] = Counter()
    senders: Counter[str] = Counter()
    for c in counters:
        if not isinstance(c, Mapping):
            continue
        for label, name in ROWS:
            rows[label] += _count(c.get(name))
        for name, v in c.items():
            if isinstance(name, str) and name.startswith(FROM_PREFIX):
                senders[name[len(FROM_PREFIX):]] += _count(v)
    out: dict[str, Any] = {label: rows[label] for label, _ in ROWS if rows[label]}
    if senders:
        out["from"] = dict(senders.most_common(SENDERS_SHOWN))
    return out


def refusal_text(summed: Mapping[str, Any]) -> str | None:
    """`refused 12 statuses, 3 tokens (from follower-2 15)`; None when nothing was."""
    parts = [f"{summed[label]} {label}" for label, _ in ROWS if summed.get(label)]
    if not parts:
        return None
    src = summed.get("from") or {}
    by = f" (from {', '.join(f'{s} {n}' for s, n in src.items())})" if src else ""
    return f"refused {', '.join(parts)}{by}"


def launch_refusals(launch: Mapping[str, Any]) -> dict[str, Any]:
    """The sums over launch.json: every process's final status, and the launcher's own."""
    status = launch.get("status")
    procs = list(status.values()) if isinstance(status, Mapping) else []
    own = launch.get("launcher")
    return refusals([*procs, *([own] if isinstance(own, Mapping) else [])])
