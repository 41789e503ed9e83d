"""The clock exchange of a swarm over hosts: one offset per other host, not per process.

A clock belongs to a host: every process on it reads the same one.  So only the hosts'
routers (deploy.hosts.router) probe each other: each publishes a probe every PERIOD_S on
`<swarm>/clock/router/<k>` that echoes the newest probe heard from every other router (its
stamp, our receive time), and each pair of routers gets NTP's four times from every probe
(transport.peer_clock).  Every other process only listens to the routers' probes
(`ClockListener`): it shares its own router's clock, so a probe from router b echoing our
router's probe is a four-time sample of host b's clock against ours (t1 our router's
send, t2 b's receive, t3 b's send, t4 our receive; the delay includes b -> us, not b ->
our router).  A process's book then maps each sender to its host's router
(`ClockBook.set_hosts`).  Cost: k routers' probes to every process (4k a second), where
probes between all n processes cost 4n^2 (18 000 deliveries a second at n = 69, more than
the ring's data: a 64-follower swarm over one router starved).

Receive times are taken as a probe arrives, on Zenoh's receiving thread
(`stamp_arrival`), not when it is read: a small thread (not the process loop, which may
block in start-up) reads the probes and publishes ours once every PERIOD_S, one wake-up
where polling every 10 ms for a prompt stamp cost each process 100 (6 900 a second at
n = 69).  Only the bus interface is
used: publisher `put` and subscription `drain` are safe from another thread in Zenoh;
nothing else is shared but the book.

The probes also say which hosts are in reach (`follower_out_of_reach`): a host whose
router has not been heard for REACH_S is cut off from us, and the bus hides its
followers' liveliness tokens (transport.zenoh_bus), as a cut at the receivers does
(transport.net_timeline).  Zenoh's own tokens cannot be trusted to show it: its 1.10.2
routers do not withdraw the tokens that came over a router link they lost (as in zenoh
issue 2602): in `--hosts 2` partitions the far side's tokens stayed alive for the whole
cut (or vanished only at the heal), and once the near side's own were withdrawn for 10 s
instead (docs/faults.md).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Collection

from errors import CodecError, ConfigError, TransportError
from transport.bus import Bus, Congestion
from transport.codec import decode, encode
from transport.key_exprs import SwarmKeys
from transport.messages import ClockProbe, Stamper
from transport.peer_clock import PROCESS_BOOK, ClockBook, exchange_sample

log = logging.getLogger(__name__)
PERIOD_S = 0.25
QUEUE = 256
# A host is out of reach after this long without its router's probe (8 probes): the
# routers' lease (transport.zenoh_config), after which Zenoh itself gives up the link.
REACH_S = 2.0


def format_clock_hosts(hosts: list[list[str]]) -> str:
    """The `--clock-hosts` argument: each host's sender ids, hosts in router order."""
    return ";".join(",".join(senders) for senders in hosts)


def clock_hosts_count(spec: str) -> int:
    """How many hosts (routers) a `--clock-hosts` argument names."""
    return spec.count(";") + 1


def parse_clock_hosts(spec: str) -> dict[str, str]:
    """Sender id -> its host's router (`router-<k>`, k its position in `spec`)."""
    out: dict[str, str] = {}
    for k, part in enumerate(spec.split(";")):
        for sender in filter(None, part.split(",")):
            if sender in out or sender.rpartition("-")[1] != "-":
                raise ConfigError("--clock-hosts", f"sender {sender!r} is twice in the "
                                  "list or not <role>-<index>")
            out[sender] = f"router-{k}"
    return out


class ClockListener:
    """What a received probe teaches a process on the host of router `own_clock_id`:
    a sample of the sender's clock against ours from its echo of our router's probe (the
    router itself is such a process, whose probes they are).  Only the swarm's routers
    (`routers`) are heard: any other sender is dropped and counted, so no table here or
    in the book grows with names a sender makes up."""

    def __init__(self, own_clock_id: str, book: ClockBook, routers: Collection[str]) -> None:
        self.own_clock_id, self.book = own_clock_id, book
        self.routers = frozenset(routers)

    def receive(self, probe: ClockProbe, t4_s: float) -> None:
        peer = probe.header.sender_id
        if peer == self.own_clock_id:
            return  # our own host's clock
        if peer not in self.routers:
            self.book.drop("sender", peer)
            return
        self.book.restart(peer, probe.epoch_s)
        for echoed, t1, t2 in probe.echoes:
            if echoed != self.own_clock_id:
                continue
            sample = exchange_sample(t1, t2, probe.header.stamp_s, t4_s)
            if sample is None:
                self.book.drop("times", peer)
            else:
                self.book.add(peer, probe.epoch_s, sample)


class ClockExchange:
    """A router's part: what to send (echoes of every probe heard), and what a received
    probe teaches (ClockListener, on our own id; injected clock)."""

    def __init__(self, sender_id: str, clock: Callable[[], float], book: ClockBook,
                 routers: Collection[str]) -> None:
        self.sender_id, self.clock, self.book = sender_id, clock, book
        self.epoch_s = clock()
        self.stamper = Stamper(sender_id, clock)
        self.heard: dict[str, tuple[float, float]] = {}  # peer -> (its stamp t1, our t2)
        self.listener = ClockListener(sender_id, book, routers)

    def probe(self) -> ClockProbe:
        echoes = tuple((peer, t1, t2) for peer, (t1, t2) in sorted(self.heard.items()))
        return ClockProbe(self.stamper.header(), self.epoch_s, echoes)

    def receive(self, probe: ClockProbe, t4_s: float) -> None:
        peer = probe.header.sender_id
        if peer != self.sender_id and peer in self.listener.routers:
            self.heard[peer] = (probe.header.stamp_s, t4_s)
        self.listener.receive(probe, t4_s)

    def forget(self, peer: str) -> None:
        self.heard.pop(peer, None)


class ClockSync:
    """Runs the clock exchange on a bus in a thread; `close()` before the bus closes.

    `clock_id` is this host's router (`router-<k>`); `probe` is True on the router itself
    (it publishes probes), False on every other process of its host (it listens);
    `n_routers` is the number of hosts (router-0 .. router-<n-1>: whose probes count);
    `clock_of` maps every sender to its host's router."""

    def __init__(self, bus: Bus, keys: SwarmKeys, clock_id: str, probe: bool, n_routers: int,
                 clock_of: dict[str, str] | None = None, book: ClockBook = PROCESS_BOOK,
                 period_s: float = PERIOD_S) -> None:
        role, _, index = clock_id.rpartition("-")
        if role != "router" or not index.isdigit() or not 0 <= int(index) < n_routers:
            raise ConfigError("clock_id", f"{clock_id!r} is not router-<k>, k < {n_routers}")
        if clock_of is not None:
            book.set_hosts(clock_of)
        self.clock_id, self.clock_of = clock_id, dict(clock_of or {})
        self.heard_s: dict[str, float] = {}  # router -> when its last probe was read
        routers = [f"router-{k}" for k in range(n_routers)]
        self.exchange = ClockExchange(clock_id, bus.now_s, book, routers) if probe else None
        self.listener = (self.exchange.listener if self.exchange
                         else ClockListener(clock_id, book, routers))
        self.period_s = period_s
        self._bus = bus
        self._out = (bus.declare_publisher(keys.clock(role, int(index)), Congestion.DROP)
                     if probe else None)
        self._sub = bus.subscribe(keys.role_clocks(role), QUEUE, stamp_arrival=True)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="clock-sync", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                for rec in self._sub.drain():
                    t4_s = rec.recv_stamp_s if rec.arrival_s is None else rec.arrival_s
                    self._receive(rec.key, rec.payload, t4_s)
                if self._out is not None and self.exchange is not None:
                    self._out.put(encode(self.exchange.probe()))
            except TransportError as exc:  # closing, or a link down: try again next poll
                log.debug("clock sync: %s", exc)
            self._stop.wait(self.period_s)

    def _receive(self, key: str, payload: bytes, t4_s: float) -> None:
        # The subscription is `clock/router/*`: the key's last chunk names the router
        # (compared as text: a key is whatever a publisher chose, never parsed into a number).
        owner = "router-" + key.rpartition("/")[2]
        try:
            msg = decode(payload)
        except CodecError:
            self.listener.book.drop("sender", owner)
            return
        if not isinstance(msg, ClockProbe) or msg.header.sender_id != owner:
            self.listener.book.drop("sender", owner)
            return
        (self.listener if self.exchange is None else self.exchange).receive(msg, t4_s)
        self.heard_s[owner] = self._bus.now_s()

    def follower_out_of_reach(self, index: int, now_s: float) -> bool:
        """True when follower `index` is on another host whose router has not been heard
        for REACH_S (or not yet at all): a cut between the hosts."""
        router = self.clock_of.get(f"follower-{index}")
        if router is None or router == self.clock_id:
            return False
        heard = self.heard_s.get(router)
        return heard is None or now_s - heard > REACH_S

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
