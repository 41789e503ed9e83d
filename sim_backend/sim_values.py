"""The values at the simulator's edges: its configuration and the vehicles' spawn points
going in, snapshots of the fleet and the loop's counters coming out.

Apart from the loop (sim_backend.runtime), which takes and hands out these values, so
that the loop's module holds the loop alone; sim_backend.runtime re-exports them, where
the launchers, tests and benchmarks import them from.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass

import numpy as np

from agents.frames import enu_to_ned
from agents.mavlink.signing_keys import vehicle_key
from agents.scenario.model import Scenario
from errors import ConfigError


@dataclass(frozen=True)
class SimConfig:
    """Loop rate and PX4 SITL ports: vehicle i listens on listen_base+i, sends to send_base+i."""

    rate_hz: float = 50.0
    telemetry_hz: float = 50.0
    flavour: str = "px4"
    host: str = "127.0.0.1"
    listen_base_port: int = 14580
    send_base_port: int = 14540
    # Vehicles enforce MAVLink 2 signing: each with its own key derived from this run
    # secret (agents.mavlink.signing.vehicle_key), or all with one key.  At most one of them.
    signing_secret: bytes | None = None
    signing_key: bytes | None = None
    # The address each vehicle's agent sends from, one per vehicle, where the deployment
    # knows it: vehicle i then takes datagrams from (peer_hosts[i], send_base+i) alone (a
    # connected socket: the kernel drops anyone else's before they count against the
    # vehicle's receive budget) and streams its telemetry there.  Empty: any sender, as PX4
    # SITL (third-party ground stations: `enclose sim`).
    peer_hosts: tuple[str, ...] = ()

    def vehicle_key(self, sysid: int) -> bytes | None:
        """The key vehicle `sysid` signs and verifies with; None: unsigned."""
        if self.signing_secret is not None:
            return vehicle_key(self.signing_secret, sysid)
        return self.signing_key


def parse_peer_hosts(text: str | None) -> tuple[str, ...]:
    """`--mav-peers`: comma-separated IPv4 addresses, one per vehicle (SimConfig.peer_hosts);
    ConfigError names a bad one."""
    if not text:
        return ()
    out = []
    for item in text.split(","):
        try:
            out.append(str(ipaddress.IPv4Address(item.strip())))
        except ValueError:
            raise ConfigError("mav_peers", f"{item!r} is not an IPv4 address") from None
    return tuple(out)


@dataclass(frozen=True)
class Snapshot:
    """A copy of every vehicle's state at one tick, safe to keep."""

    sim_time_s: float
    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray
    yaw_rad: np.ndarray
    armed: tuple[bool, ...]
    modes: tuple[str, ...]


@dataclass
class LoopStats:
    ticks: int = 0
    overruns: int = 0  # ticks that ended after the next tick was due
    catch_ups: int = 0  # times the loop woke up more than a tick late and caught up
    caught_up_ticks: int = 0  # physics sub-steps run without telemetry while catching up
    resyncs: int = 0  # stalls over runtime.MAX_CATCHUP_S: the rest of the time was dropped
    max_late_s: float = 0.0


def spawn_points_ned(scenario: Scenario) -> np.ndarray:
    """Followers then targets, on the ground at their scenario (x, y), in NED."""
    xy = list(scenario.follower_pos_m) + [t.initial_pos_m for t in scenario.targets]
    return enu_to_ned(np.array([[x, y, 0.0] for x, y in xy]))


def grid_spawn_ned(n: int, spacing_m: float = 5.0) -> np.ndarray:
    side = max(1, int(np.ceil(np.sqrt(n))))
    return np.array([[(k // side) * spacing_m, (k % side) * spacing_m, 0.0] for k in range(n)])
