"""The simulator's target sensing, delivered on each follower's own host.

On a drone a follower's sensing is on board: a partition of the swarm's network between
hosts does not blind it, as it does not cut the MAVLink link to its autopilot.  The
simulator stands in for both, so under a deployment over several hosts it publishes the
observations of the followers on another host through a Zenoh session of its own,
a client of that host's router at its sensing endpoint (deploy.hosts.deployment), instead of
through its own host's router and the link between the routers.  The path is the same
message, key, codec and access control as on one machine; only the route differs, and
a cut between hosts exempts it (deploy.hosts.host_cut), as it exempts MAVLink.

    python -m sim_backend.swarm_sim ... --sensor-link tls/10.77.0.2:7448=2,3
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace

from agents.shell.process_options import BusOptions
from errors import ConfigError, TransportError
from transport.bus import BusBase, Congestion, Publisher
from transport.credentials import Identity
from transport.network_schema import NetworkConfig
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

log = logging.getLogger("enclose.sim")
FLAG = "--sensor-link"
OPEN_TRY_MS = 1000  # each try to open a sensing link waits this long for its router
LOG_EVERY_TRIES = 30
RETRY_S = 0.25


@dataclass(frozen=True)
class SensorLink:
    """Where the observations of `followers` (0-based) are published from."""

    endpoint: str  # a host's sensing endpoint, e.g. tls/10.77.0.2:7448
    followers: tuple[int, ...]

    def argv(self) -> list[str]:
        return [FLAG, f"{self.endpoint}={','.join(map(str, self.followers))}"]


def parse_sensor_link(text: str, n: int) -> SensorLink:
    """`ENDPOINT=I,J,...` (0-based followers of an n-follower swarm)."""
    endpoint, sep, listed = text.rpartition("=")
    if not sep or "/" not in endpoint:
        raise ConfigError(FLAG, f"{text!r} is not ENDPOINT=I,J (e.g. tls/10.0.0.2:7448=2,3)")
    try:
        followers = tuple(int(i) for i in listed.split(","))
    except ValueError:
        raise ConfigError(FLAG, f"{listed!r} is not a list of follower indexes") from None
    bad = [i for i in followers if not 0 <= i < n]
    if bad or not followers:
        raise ConfigError(FLAG, f"{text!r}: followers must be in 0..{n - 1}")
    return SensorLink(endpoint, followers)


def check_disjoint(links: Sequence[SensorLink]) -> None:
    seen: set[int] = set()
    for link in links:
        twice = seen.intersection(link.followers)
        if twice:
            raise ConfigError(FLAG, f"follower {min(twice)} given two sensor links")
        seen.update(link.followers)


class LinkBus(BusBase):
    """A sensing link's session, opened in the background: the simulator's vehicles must
    not wait for another host, whose router may come up minutes after this one (hosts are
    started separately: docs/multihost.md), or its targets time out waiting for their
    vehicles.  Observations put before the link is up are dropped and counted: nobody on
    that host listens yet."""

    def __init__(self, cfg: ZenohConfig) -> None:
        super().__init__()
        self.dropped = 0
        self._bus: ZenohBus | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._open, args=(cfg,), name="sensor-link",
                                        daemon=True)
        self._thread.start()

    def _open(self, cfg: ZenohConfig) -> None:
        tried = 0
        while not self._stop.is_set():
            try:
                bus = ZenohBus(replace(cfg, connect_timeout_ms=OPEN_TRY_MS))
            except TransportError as exc:
                tried += 1
                if tried % LOG_EVERY_TRIES == 1:
                    log.info("sensing link %s not up yet: %s", cfg.connect, exc)
                self._stop.wait(RETRY_S)  # a try refused at once must not spin
                continue
            with self._lock:
                if not self._stop.is_set():
                    self._bus = bus
                    log.info("sensing link %s up", cfg.connect)
                    return
            bus.close()

    def wait_open(self, timeout_s: float) -> bool:
        """True once the link is up (tests)."""
        deadline = time.monotonic() + timeout_s
        while self._bus is None and time.monotonic() < deadline:
            time.sleep(0.02)
        return self._bus is not None

    def declare_publisher(self, key: str,
                          congestion: Congestion = Congestion.DROP) -> Publisher:
        return _LinkPublisher(self, key, congestion)

    def put(self, key: str, payload: bytes, congestion: Congestion) -> None:
        bus = self._bus
        if bus is None:
            self.dropped += 1
            return
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._publishers[key] = bus.declare_publisher(key, congestion)
        pub.put(payload)

    def close(self) -> None:
        with self._lock:
            self._stop.set()
            bus, self._bus = self._bus, None
        self._thread.join(timeout=OPEN_TRY_MS / 1000.0 + 5.0)
        self._publishers.clear()
        if bus is not None:
            bus.close()


@dataclass
class _LinkPublisher:
    link: LinkBus
    key: str
    congestion: Congestion

    def put(self, payload: bytes) -> None:
        self.link.put(self.key, payload, self.congestion)

    def matched(self) -> bool:
        pub = self.link._publishers.get(self.key)
        return pub is not None and pub.matched()

    def close(self) -> None:
        """The link's publishers close with it."""


@contextlib.contextmanager
def sensor_buses(links: Sequence[SensorLink], opts: BusOptions,
                 network: NetworkConfig) -> Iterator[dict[int, LinkBus]]:
    """Each linked follower's bus (one session per link, as the simulator's identity,
    opened in the background: LinkBus), all closed on exit; a follower not linked
    publishes on the simulator's own bus."""
    check_disjoint(links)
    identity = None if opts.credentials is None else Identity.load(opts.credentials)
    with contextlib.ExitStack() as stack:
        buses: dict[int, LinkBus] = {}
        for link in links:
            bus = stack.enter_context(LinkBus(ZenohConfig(
                mode="client", connect=(link.endpoint,), user_config_path=opts.zenoh_config,
                identity=identity, runtime=network.zenoh_runtime,
                lease_s=network.zenoh_lease_s)))
            buses.update(dict.fromkeys(link.followers, bus))
        yield buses
