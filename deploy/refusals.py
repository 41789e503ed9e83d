"""What each process refused on its MAVLink link, read from its status counters: the one
place that knows which counters say so, for the verdict's processes line and the live
view's status.

- `signing_rejected_<reason>`: frames refused by their signature (unsigned, bad_signature,
  wrong_key, future, replay, malformed; agents.mavlink.signing);
- `signing_wrong_key_vehicle_<sysid>`: of those, the ones signed with vehicle sysid's key
  (the sender, as far as a vehicle can tell: whoever holds that vehicle's key);
- `mav_flood_drops`: datagrams cut at a tick's parse budget; `mav_kernel_drops`: datagrams the
  kernel dropped on a full socket buffer (agents.mavlink.rx_gate, agents.mavlink.udp);
- `peers_refused`: signed senders refused a place in a vehicle's full peer table.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

REJECTED = "signing_rejected_"
WRONG_KEY = "signing_wrong_key_vehicle_"
DROPS = {"mav_flood_drops": "datagrams cut at the parse budget",
         "mav_kernel_drops": "dropped unread by the kernel",
         "peers_refused": "signed peers refused (table full)"}


def _count(v: Any) -> int:
    return v if isinstance(v, int) and not isinstance(v, bool) and v > 0 else 0


def refusals(counters: Mapping[str, Any]) -> dict[str, int]:
    """The nonzero refusal counters of one process's status, by their name."""
    return {k: _count(v) for k, v in counters.items()
            if (k.startswith((REJECTED, WRONG_KEY)) or k in DROPS) and _count(v)}


def vehicle_owner(sysid: int, n_followers: int) -> str:
    """The agent that holds vehicle `sysid`'s key: follower i flies sysid i+1, target j
    sysid n+j+1 (deploy.run_secrets)."""
    index = sysid - 1
    return f"follower-{index}" if index < n_followers else f"target-{index - n_followers}"


def refusal_text(counters: Mapping[str, Any], n_followers: int) -> str | None:
    """`refused 2520 MAVLink frames (unsigned 2500, wrong_key 20: follower-2's key), ...`;
    None when the process refused nothing."""
    found = refusals(counters)
    reasons = {k[len(REJECTED):]: v for k, v in found.items() if k.startswith(REJECTED)}
    owners = [vehicle_owner(int(k[len(WRONG_KEY):]), n_followers) for k in found
              if k.startswith(WRONG_KEY) and k[len(WRONG_KEY):].isdigit()]
    parts = []
    if reasons:
        why = ", ".join(f"{k} {v}" for k, v in sorted(reasons.items()))
        keys = f": {', '.join(sorted(owners))}'s key" if owners else ""
        parts.append(f"refused {sum(reasons.values())} MAVLink frames ({why}{keys})")
    parts += [f"{found[k]} {label}" for k, label in DROPS.items() if k in found]
    return ", ".join(parts) or None


def refusal_lines(status: Any) -> tuple[str, ...]:
    """One line per process of launch.json's `status` that refused anything."""
    if not isinstance(status, dict):
        return ()
    n = sum(1 for name in status if isinstance(name, str) and name.startswith("follower-"))
    lines = []
    for name, counters in sorted(status.items()):
        text = refusal_text(counters, n) if isinstance(counters, dict) else None
        if text is not None:
            lines.append(f"{name}: {text}")
    return tuple(lines)
