"""What a run's processes refused from the bus, summed: one line for the verdict's
processes row, one object for the live view's status.

Every process counts its refusals in its status counters (transport.decoder:
`<kind>_rejected` and `rejected_from_<sender>` for its most rejected senders;
agents.membership.liveness: `tokens_rejected`, `tokens_held`); these sum them over processes.  A
sender is the process whose key the input came on: with access control on, the one that
put it, whatever it claimed.  On the MAVLink side (agents.mavlink.signing, .rx_gate):
frames refused by their signature (`signing_rejected_<reason>`), datagrams over a tick's
budget or dropped unread by the kernel, peers refused.  Clock probes dropped
(transport.peer_clock: `clock_probes_dropped_<why>`).  A frame signed with another
vehicle's key names the agent that holds that key (the simulator's
`rejected_from_<agent>`, sim_backend.swarm_sim).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
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


def _robust_total(counts: list[int]) -> int:
    """The witnesses' counts summed, the largest capped at the next largest: one process
    cannot make a sender weigh more than the others who refused it say (alone, it can)."""
    if len(counts) < 2:
        return sum(counts)
    second, top = sorted(counts)[-2:]
    return sum(counts) - top + second


def refusals(by_process: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """{label: total} of the non-zero rows over the processes' counters (`by_process`:
    process name -> its status counters), "from": {sender: total} of the SENDERS_SHOWN
    senders refused by the most processes, and "seen_by": {sender: how many processes}.

    A status is what its process says it saw: the launcher knows it came from that process
    (transport.message_checks) but not that it is true.  So a sender is ranked by how many
    processes refused it, then by its total with no single process's count above the
    others' (`_robust_total`), and a process's counters about itself are not counted.  A
    process that lies in its status adds one witness against each process it blames:
    never enough to rank one above a sender its neighbours and the recorder refused."""
    rows: Counter[str] = Counter()
    seen: dict[str, list[int]] = {}
    for process, c in by_process.items():
        if not isinstance(c, Mapping):
            continue
        for label, name in ROWS:
            rows[label] += _count(c.get(name))
        for name, v in c.items():
            sender = name[len(FROM_PREFIX):] if isinstance(name, str) \
                and name.startswith(FROM_PREFIX) else None
            if sender and sender != process and _count(v):
                seen.setdefault(sender, []).append(_count(v))
    out: dict[str, Any] = {label: rows[label] for label, _ in ROWS if rows[label]}
    ranked = sorted(seen, key=lambda s: (-len(seen[s]), -_robust_total(seen[s]), s))
    shown = ranked[:SENDERS_SHOWN]
    if shown:
        out["from"] = {s: sum(seen[s]) for s in shown}
        out["seen_by"] = {s: len(seen[s]) for s in shown}
    return out


def refusal_text(summed: Mapping[str, Any]) -> str | None:
    """`refused 12 statuses, 3 tokens (from follower-2 15 seen by 3)`; None when nothing
    was."""
    parts = [f"{summed[label]} {label}" for label, _ in ROWS if summed.get(label)]
    if not parts:
        return None
    src, seen = summed.get("from") or {}, summed.get("seen_by") or {}
    named = [f"{s} {n}" + (f" seen by {seen[s]}" if s in seen else "") for s, n in src.items()]
    by = f" (from {', '.join(named)})" if named else ""
    return f"refused {', '.join(parts)}{by}"


def launch_refusals(launch: Mapping[str, Any]) -> dict[str, Any]:
    """The sums over launch.json: every process's final status, and the launcher's own."""
    status = launch.get("status")
    procs = {str(k): v for k, v in status.items()} if isinstance(status, Mapping) else {}
    own = launch.get("launcher")
    return refusals({**procs, **({"launcher": own} if isinstance(own, Mapping) else {})})
