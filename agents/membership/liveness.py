"""Who is alive: the followers' Zenoh liveliness tokens, as a member set.

A follower is a member while its liveliness token is alive.  Zenoh withdraws a token
~11 ms after a crash or SIGKILL (and on a clean exit), and when its session's lease
(10 s without a word: a frozen, SIGSTOPped process) runs out; a process whose loop is stuck
while its Zenoh threads still run withdraws its own token (`StallGuard`, after STALL_S) and
declares it again when the loop runs.  Every observer sees the same set, carried by Zenoh,
with no traffic of ours.  A follower was once also dropped when its
~1-Hz status had not been heard for 5 s, so every follower heard every other's status:
O(n^2) messages, ~4000 a second at n = 64, as many as the ring's data, and on 2 cores the
share of a core that ring64's simulator and recorder were missing (BENCHMARKS.md).

STALL_S = 5 s: longer than the ordinary stalls a member must ride through (a 2-s pause, a
garbage collection, a slow start-up phase of a restarted vehicle), short enough that a
hung loop leaves the ring well before Zenoh's lease would notice a frozen process.

A token's return can fail to reach a watch that saw it vanish (when the mesh re-forms
around a restarted rendezvous), so while a scenario follower is missing the watch is
declared again, whose history gives the tokens alive now: after REFRESH_S, then at
doubling intervals up to REFRESH_MAX_S (a follower that died for good costs little).

Tokens are names anyone on the bus may declare where access control does not stop them
(`--insecure`, udp links, a router's certificate), so they are checked, not trusted:
- a token whose key is malformed or names no follower of the scenario (index >= n,
  a sign, a non-ASCII digit, a leading zero) is ignored and counted (`tokens_rejected`);
- a flapping token is rate-limited: the changes seen between two reads of the set (one
  loop tick) count as one, their net effect (a member that leaves and returns within it
  was never out), and a member changes at most FLAP_MAX_CHANGES times in FLAP_WINDOW_S;
  a further change is held back (`tokens_held`), the member kept in its last state, until
  the window allows one more -- then it takes its token's state of that moment.
FLAP_MAX_CHANGES = 4 in FLAP_WINDOW_S = 10 s: a crash and its restart are 2 changes, a
stalled loop's withdrawal and return 2 more, so one real incident is always seen at once;
each change costs every follower a regroup (a new ring, new subscriptions) and the swarm a
transient, and a token toggled as fast as a process can is seen at most 4 times in 10 s.

`TokenSet` is pure (time is an argument); `MembershipWatch` feeds it from a Bus.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from transport.bus import Bus, Token
from transport.key_exprs import SwarmKeys, parse_key
from transport.ratelog import RateLimitedLog

log = logging.getLogger(__name__)
STALL_S = 5.0
REFRESH_S = 2.0
REFRESH_MAX_S = 30.0
FLAP_WINDOW_S = 10.0
FLAP_MAX_CHANGES = 4


@dataclass
class TokenSet:
    """Followers with a live token, and when to ask Zenoh again for the ones missing."""

    expected: frozenset[int] = frozenset()  # the scenario's followers: no other is taken
    tokens: set[int] = field(default_factory=set)  # the members, as applied
    refresh_after_s: float = REFRESH_S
    _next_refresh_s: float | None = None
    raw: set[int] = field(default_factory=set)  # the tokens alive, as the bus says
    rejected: int = 0  # tokens naming no follower of the scenario
    held: int = 0  # token events not applied at once: the flap limit held their follower
    _changes: dict[int, deque[float]] = field(default_factory=dict)  # applied, per follower
    _pending: set[int] = field(default_factory=set)  # noted, not applied yet
    _held: set[int] = field(default_factory=set)  # pending for the flap limit

    def token(self, index: int, alive: bool, now_s: float = 0.0) -> None:
        """One token event, applied at once (as far as the flap limit allows)."""
        self.note(index, alive)
        self.settle(now_s)

    def note(self, index: int, alive: bool) -> None:
        """One token event, applied by the next `settle`."""
        if index not in self.expected:
            self.rejected += alive  # its vanishing is no second offence
            return
        (self.raw.add if alive else self.raw.discard)(index)
        self._pending.add(index)
        self.held += index in self._held

    def settle(self, now_s: float) -> None:
        """Apply the noted changes the flap limit allows; keep the others pending."""
        for index in sorted(self._pending):
            if self._apply(index, now_s):
                self._pending.discard(index)
                self._held.discard(index)
            elif index not in self._held:
                self._held.add(index)
                self.held += 1

    def _apply(self, index: int, now_s: float) -> bool:
        """True when `index`'s member state is its token's (now, or already)."""
        alive = index in self.raw
        if alive == (index in self.tokens):
            return True
        times = self._changes.setdefault(index, deque(maxlen=FLAP_MAX_CHANGES))
        if len(times) == FLAP_MAX_CHANGES and now_s - times[0] < FLAP_WINDOW_S:
            return False
        times.append(now_s)
        (self.tokens.add if alive else self.tokens.discard)(index)
        self.refresh_after_s = REFRESH_S  # a change: a missing one may be on its way back
        return True

    @property
    def pending_changes(self) -> bool:
        """Noted changes not applied yet (the flap limit holds them)."""
        return bool(self._pending)

    def due_refresh(self, now_s: float) -> bool:
        """True when the watch should be declared again (and the next time is set)."""
        if self.expected <= self.tokens:
            self._next_refresh_s = None
            return False
        if self._next_refresh_s is None:
            self._next_refresh_s = now_s + self.refresh_after_s
            return False
        if now_s < self._next_refresh_s:
            return False
        self.refresh_after_s = min(REFRESH_MAX_S, 2.0 * self.refresh_after_s)
        self._next_refresh_s = now_s + self.refresh_after_s
        return True


class MembershipWatch:
    """The follower member set as seen through one Bus: the followers' tokens."""

    def __init__(self, bus: Bus, keys: SwarmKeys, n_followers: int) -> None:
        self.bus, self.keys = bus, keys
        self.tracker = TokenSet(frozenset(range(n_followers)))
        self.watch = bus.watch_alive(keys.alive_of("follower"))
        self.refreshes = 0
        self.log = RateLimitedLog(log)
        self._members: frozenset[int] | None = None

    def members(self, now_s: float) -> frozenset[int]:
        """The member set; the same object as long as nothing changed (its readers
        recompute only on a new one: it is read every tick)."""
        events = self.watch.drain_events()
        tracker = self.tracker
        if not events and self._members is not None and not tracker.pending_changes \
                and tracker.expected <= tracker.tokens:
            return self._members  # the common tick: no event, all present, nothing held
        for ev in events:
            index = self._follower(ev.key)
            if index is not None:
                self.tracker.note(index, ev.alive)
            elif ev.alive:
                self.tracker.rejected += 1
                self.log.warning("token", "ignored a liveliness token on %r: no follower of "
                                          "this swarm", ev.key[:160])
        self.tracker.settle(now_s)
        if self.tracker.due_refresh(now_s):
            self.refreshes += 1
            self.watch.close()
            self.watch = self.bus.watch_alive(self.keys.alive_of("follower"))
        members = frozenset(self.tracker.tokens)
        if members != self._members:
            self._members = members
        assert self._members is not None
        return self._members

    def _follower(self, key: str) -> int | None:
        """The follower whose token `key` is, if it is one of the scenario's."""
        info = parse_key(key)
        if info is None or info.kind != "alive" or info.role != "follower" \
                or info.swarm != self.keys.swarm or info.index not in self.tracker.expected:
            return None
        return info.index

    def counters(self) -> dict[str, int]:
        """For the process's status: tokens ignored, and changes the flap limit held."""
        return {"tokens_rejected": self.tracker.rejected, "tokens_held": self.tracker.held}

    def close(self) -> None:
        self.watch.close()


class StallGuard:
    """This process's token, withdrawn by a watchdog thread while the loop is stuck.

    The loop calls `alive()` every iteration (and while it waits on its vehicle); after
    `stall_s` without one the thread withdraws the token, and the next `alive()` declares
    it again.  A frozen process needs no guard: its lease runs out."""

    def __init__(self, bus: Bus, key: str, stall_s: float = STALL_S,
                 clock: Callable[[], float] = time.monotonic, period_s: float = 1.0) -> None:
        self.bus, self.key, self.stall_s, self.clock = bus, key, stall_s, clock
        self.withdrawals = 0
        self._lock = threading.Lock()
        self._token: Token | None = bus.declare_token(key)
        self._last_s = clock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, args=(period_s,),
                                        name="stall-guard", daemon=True)
        self._thread.start()

    def alive(self) -> None:
        self._last_s = self.clock()
        if self._token is None:
            with self._lock:
                if self._token is None and not self._stop.is_set():
                    self._token = self.bus.declare_token(self.key)
                    log.warning("loop running again: %s declared again", self.key)

    def check(self) -> None:
        """One look of the watchdog (its thread calls this every period)."""
        stalled_s = self.clock() - self._last_s
        if stalled_s <= self.stall_s or self._token is None:
            return
        with self._lock:
            if self._token is not None:
                self._token.close()
                self._token = None
                self.withdrawals += 1
                log.warning("loop stalled %.1f s: %s withdrawn", stalled_s, self.key)

    def _watch(self, period_s: float) -> None:
        while not self._stop.wait(period_s):
            self.check()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        with self._lock:
            if self._token is not None:
                self._token.close()
                self._token = None
