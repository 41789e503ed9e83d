"""What each link of the swarm actually delivered: metrics.json "links" (pure, no I/O).

Followers are 0-based, as in process names and the "followers" table: `"f0->f2"` is what
follower 2 received from follower 0, `"sensor->f2"` what it received from the simulator's
sensor.  The receiving follower counts, after impairment (`transport.link_stats`,
`transport.impairment`); its final counters arrive in its "done" ProcessStatus (the last
status heard is used if that never comes, and `final` says which).  Per link:
- `rx`: unique messages received; `duplicates`: further copies received;
- `sent`: messages the sender published -- follower j's own `states_sent`, else the number
  of j's states the recorder heard (unimpaired) -- and for the sensor the span of sequence
  numbers the follower saw (the simulator publishes long before a follower listens);
- `sent_source`: "states_sent" | "recorder" | "seq_span";
An `rx_<x>` counter whose x names no link is skipped (counted by `unreadable_links`).
- `delivered_ratio` = rx / sent;
- `age_p50_ms`, `age_p99_ms`: age at delivery (receive stamp - sender stamp);
- `impairment`: what the impairment did (offered, dropped, duplicated, reordered, ...).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from transport.impairment import COUNTS
from transport.link_stats import SENSOR
from transport.messages import ProcessStatus

FINAL_STATES = ("done", "failed")
RX = "rx_"


def is_link(name: str) -> bool:
    """`sensor` or `f<j>` with j in ASCII digits: a status may carry any `rx_<x>` counter,
    and only these name a link (int() would take "f\u0663" or raise on "fx")."""
    return name == SENSOR or (name[:1] == "f" and name[1:].isascii() and name[1:].isdigit())


def _rx_names(c: Mapping[str, int]) -> list[str]:
    return [k[len(RX):] for k in c if k.startswith(RX) and not k.startswith("rx_dup")]


def unreadable_links(statuses: Mapping[int, ProcessStatus]) -> int:
    """How many `rx_<x>` counters of the followers' statuses name no link (skipped)."""
    return sum(not is_link(n) for s in statuses.values() for n in _rx_names(s.counters))


def _sent(
    link: str, c: Mapping[str, int], final: Mapping[int, ProcessStatus], recorded: Sequence[int]
) -> tuple[int | None, str]:
    if link == SENSOR:
        first, last = c.get(f"seq_first_{link}"), c.get(f"seq_last_{link}")
        return (None if first is None or last is None else last - first + 1), "seq_span"
    j = int(link[1:])
    sender = final.get(j)
    if sender is not None and "states_sent" in sender.counters:
        return int(sender.counters["states_sent"]), "states_sent"
    return (recorded[j] if 0 <= j < len(recorded) else None), "recorder"


def _ms(us: int | None) -> float | None:
    return None if us is None else us / 1000.0


def link_entry(
    link: str, c: Mapping[str, int], final: Mapping[int, ProcessStatus], recorded: Sequence[int]
) -> dict[str, Any]:
    rx = int(c[f"rx_{link}"])
    sent, source = _sent(link, c, final, recorded)
    return {
        "rx": rx,
        "duplicates": int(c.get(f"rx_dup_{link}", 0)),
        "sent": sent,
        "sent_source": source,
        "delivered_ratio": rx / sent if sent else None,
        "age_p50_ms": _ms(c.get(f"age_p50_us_{link}")),
        "age_p99_ms": _ms(c.get(f"age_p99_us_{link}")),
        "impairment": {k: int(c[f"imp_{k}_{link}"]) for k in COUNTS if f"imp_{k}_{link}" in c},
    }


def link_report(
    statuses: Mapping[int, ProcessStatus], recorded_states: Sequence[int]
) -> dict[str, Any]:
    """metrics.json "links" from each follower's latest status and the recorder's counts."""
    out: dict[str, Any] = {}
    for i, status in sorted(statuses.items()):
        c = status.counters
        for link in sorted(filter(is_link, _rx_names(c))):
            entry = link_entry(link, c, statuses, recorded_states)
            out[f"{link}->f{i}"] = {**entry, "final": status.state in FINAL_STATES}
    return out


def followers_pending(statuses: Mapping[int, ProcessStatus], n: int) -> list[int]:
    """The followers (of `n`) whose latest status is not a final one (or who sent none)."""
    return [i for i in range(n) if getattr(statuses.get(i), "state", "") not in FINAL_STATES]
