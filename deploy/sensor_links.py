"""The simulator's target sensing, delivered on each follower's own host.

On a drone a follower's sensing is on board: a partition of the swarm's network between
hosts does not blind it, as it does not cut the MAVLink link to its autopilot.  The
simulator stands in for both, so under a deployment over several hosts it publishes the
observations of the followers on another host through a Zenoh session of its own,
a client of that host's router at its sensing endpoint (deploy.deployment), instead of
through its own host's router and the link between the routers.  The path is the same
message, key, codec and access control as on one machine; only the route differs, and
a cut between hosts exempts it (deploy.netns.cut), as it exempts MAVLink.

    python -m deploy.swarm_sim ... --sensor-link tls/10.77.0.2:7448=2,3
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from agents.process_options import BusOptions
from transport.bus import Bus
from transport.credentials import Identity
from transport.errors import ConfigError
from transport.network_schema import NetworkConfig
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

FLAG = "--sensor-link"


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


@contextlib.contextmanager
def sensor_buses(links: Sequence[SensorLink], opts: BusOptions,
                 network: NetworkConfig) -> Iterator[dict[int, Bus]]:
    """Each linked follower's bus (one session per link, as the simulator's identity),
    all closed on exit; a follower not linked publishes on the simulator's own bus."""
    check_disjoint(links)
    identity = None if opts.credentials is None else Identity.load(opts.credentials)
    with contextlib.ExitStack() as stack:
        buses: dict[int, Bus] = {}
        for link in links:
            bus = stack.enter_context(ZenohBus(ZenohConfig(
                mode="client", connect=(link.endpoint,), user_config_path=opts.zenoh_config,
                identity=identity, runtime=network.zenoh_runtime,
                lease_s=network.zenoh_lease_s)))
            buses.update(dict.fromkeys(link.followers, bus))
        yield buses
