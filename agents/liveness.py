"""Who is alive: followers' Zenoh liveliness tokens and their heartbeats, as a member set.

A follower is a member while its liveliness token is alive and its status (published
about once a second from its loop: `agents.process.StatusReporter`) was heard within
`SILENCE_S`.  A token vanishes ~11 ms after a crash or SIGKILL (and on a clean exit);
the silence rule catches a process that is alive but stuck.

SILENCE_S = 5 s: the status period (1 s) plus the longest ordinary stall a member must
ride through (a 2 s SIGSTOP or scheduling pause) plus 2 s of margin for a loaded host.
Shorter would drop and re-add members on every such pause (each change restarts the
affected estimator links); longer only delays noticing a hung process, which Zenoh's
own lease (10 s) would also remove.  Every observer applies the same rule to the same
status stream, so they agree on the set up to one status delivery.

`LivenessTracker` is pure (time is an argument); `MembershipWatch` feeds it from a Bus.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from transport.bus import Bus
from transport.keys import SwarmKeys, parse_key

SILENCE_S = 5.0


@dataclass
class LivenessTracker:
    """Tokens and last-heard times of followers; `members(now)` is the live set."""

    silence_s: float = SILENCE_S
    tokens: set[int] = field(default_factory=set)
    heard_s: dict[int, float] = field(default_factory=dict)
    last_eval_s: float | None = None
    # Every follower asks every tick, and the set changes a few times a run: the last
    # answer stands until a token comes or goes, a silent follower is heard again, or the
    # first member could have fallen silent (ring64: 64 checks a tick, each of 64).
    _last: frozenset[int] | None = None
    _last_until_s: float = -math.inf

    def token(self, index: int, alive: bool, now_s: float) -> None:
        self._last = None
        if alive:
            self.tokens.add(index)
            self.heard_s[index] = max(self.heard_s.get(index, now_s), now_s)
        else:
            self.tokens.discard(index)
            self.heard_s.pop(index, None)

    def heard(self, index: int, now_s: float) -> None:
        if index in self.tokens:
            self.heard_s[index] = max(self.heard_s.get(index, now_s), now_s)
            if self._last is not None and index not in self._last:
                self._last = None

    def members(self, now_s: float) -> frozenset[int]:
        """Followers with a live token heard within `silence_s` of `now_s`.

        If the observer itself did not evaluate for over half the silence time (it was
        paused), everyone's silence is counted from its return: its own stall must not
        make the others look silent.
        """
        if self.last_eval_s is not None and now_s - self.last_eval_s > 0.5 * self.silence_s:
            for i in self.heard_s:
                self.heard_s[i] = max(self.heard_s[i], now_s)
            self._last = None
        elif self.last_eval_s is not None and now_s < self.last_eval_s:
            self._last = None  # a clock that steps back: judge afresh
        self.last_eval_s = now_s
        if self._last is not None and now_s <= self._last_until_s:
            return self._last
        self._last = frozenset(
            i for i in self.tokens if now_s - self.heard_s.get(i, now_s) <= self.silence_s
        )
        # Heard times only move later while the set stands, so this bound is safe.
        self._last_until_s = min((self.heard_s.get(i, now_s) for i in self._last),
                                 default=math.inf) + self.silence_s
        return self._last


class MembershipWatch:
    """The follower member set as seen through one Bus: tokens plus status heartbeats.

    When the mesh re-forms around a restarted process (the simulator is everyone's
    rendezvous), a token's reappearance may not reach a watch that saw it vanish; a
    status from a follower with no known token then re-declares the watch, whose
    history gives the tokens alive now (at most once per REFRESH_S).
    """

    REFRESH_S = 1.0

    def __init__(self, bus: Bus, keys: SwarmKeys, silence_s: float = SILENCE_S) -> None:
        self.bus, self.keys = bus, keys
        self.tracker = LivenessTracker(silence_s)
        self.watch = bus.watch_alive(keys.alive_of("follower"))
        self.status = bus.subscribe(keys.status_of("follower"), capacity=256)
        self.refreshes = 0
        self._refreshed_s = -1e18

    def members(self, now_s: float) -> frozenset[int]:
        for ev in self.watch.drain_events():
            info = parse_key(ev.key)
            if info is not None and info.index is not None:
                self.tracker.token(info.index, ev.alive, now_s)
        unknown = False
        for rec in self.status.drain():
            # The key names the sender; a forged or garbled payload cannot add a member
            # (only a token can), it can at most keep a token-holder counted as heard.
            info = parse_key(rec.key)
            if info is not None and info.index is not None:
                self.tracker.heard(info.index, now_s)
                unknown |= info.index not in self.tracker.tokens
        if unknown and now_s - self._refreshed_s >= self.REFRESH_S:
            self._refreshed_s = now_s
            self.refreshes += 1
            self.watch.close()
            self.watch = self.bus.watch_alive(self.keys.alive_of("follower"))
        return self.tracker.members(now_s)

    def close(self) -> None:
        self.watch.close()
        self.status.close()
