"""Free loopback ports for a run: one port for Zenoh (TCP or UDP), blocks of UDP for MAVLink."""

from __future__ import annotations

import socket
from collections.abc import Sequence

from errors import DeployError
from transport.zenoh_config import loopback_endpoint

HOST = "127.0.0.1"
PX4_SITL_BASES = (14580, 14540)  # (vehicle, adapter): taken whenever free, e.g. in a fresh netns


def free_tcp_port(host: str = HOST) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


def free_udp_port(host: str = HOST) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


def _protocol(link: str, secure: bool) -> str:
    """An authenticated run's TCP is TLS (mTLS: transport.credentials)."""
    return "tls" if secure and link == "tcp" else link


def rendezvous_endpoint(link: str, avoid: Sequence[range] = (), secure: bool = False) -> str:
    """The endpoint the simulator listens on and everyone connects to, in the run's protocol
    (`tls` over a TCP port for an authenticated run).

    A UDP port must not fall in the MAVLink blocks (`avoid`), bound only later by the sim.
    """
    for _ in range(50):
        port = free_udp_port() if link == "udp" else free_tcp_port()
        if link != "udp" or not any(port in r for r in avoid):
            return loopback_endpoint(port, _protocol(link, secure))
    raise DeployError(f"no free {link} port on {HOST} outside the MAVLink blocks")


def udp_block_free(base: int, count: int, host: str = HOST) -> bool:
    socks = []
    try:
        for port in range(base, base + count):
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            socks.append(sock)
            sock.bind((host, port))
        return True
    except OSError:
        return False
    finally:
        for sock in socks:
            sock.close()


def ports_held(ports: range, tcp: bool = False, host: str = HOST) -> list[str]:
    """The ports of `ports` some process holds, as "UDP 15000" (and "TCP ..." with `tcp`,
    probed as a Zenoh listener binds: a connection in TIME_WAIT does not count)."""
    held = []
    kinds = [("UDP", socket.SOCK_DGRAM)] + ([("TCP", socket.SOCK_STREAM)] if tcp else [])
    for name, kind in kinds:
        for port in ports:
            with socket.socket(socket.AF_INET, kind) as sock:
                if kind == socket.SOCK_STREAM:
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                try:
                    sock.bind((host, port))
                except OSError:
                    held.append(f"{name} {port}")
    return held


def mavlink_bases(count: int, preferred: tuple[int, int] = PX4_SITL_BASES) -> tuple[int, int]:
    """(vehicle listen base, adapter base): PX4 SITL's when free, else the first free pair."""
    candidates = [preferred] + [(b, b + 500) for b in range(20000, 60000, 1000)]
    for vehicle_base, adapter_base in candidates:
        # PX4 SITL's blocks are 40 apart: more vehicles than that (ring64) would give a
        # vehicle and an agent the same port.
        if abs(vehicle_base - adapter_base) < count:
            continue
        if udp_block_free(vehicle_base, count) and udp_block_free(adapter_base, count):
            return vehicle_base, adapter_base
    raise DeployError(f"no free UDP port blocks for {count} vehicles on {HOST}")


def parse_port_range(text: str) -> range:
    """`"LO-HI"` (HI inclusive) as a range, for `enclose run --port-range`."""
    lo_text, sep, hi_text = text.partition("-")
    try:
        lo, hi = int(lo_text), int(hi_text)
    except ValueError:
        lo = hi = -1
    if not sep or not 1024 <= lo <= hi <= 65535:
        raise DeployError(f"--port-range must be LO-HI within 1024-65535, got {text!r}")
    return range(lo, hi + 1)


def ports_in_range(ports: range, count: int, link: str, secure: bool) -> tuple[int, int, str]:
    """(vehicle base, adapter base, rendezvous endpoint) packed at the start of `ports`: the
    range is this run's alone (a sweep hands one to each parallel cell), so nothing is
    searched; a port someone else holds is an error naming it."""
    need = 2 * count + 1
    if len(ports) < need:
        raise DeployError(
            f"--port-range {ports.start}-{ports.stop - 1} holds {len(ports)} ports; "
            f"{count} vehicles need {need}"
        )
    vehicle, adapter, rendezvous = ports.start, ports.start + count, ports.start + 2 * count
    for base in (vehicle, adapter):
        if not udp_block_free(base, count):
            raise DeployError(f"--port-range: UDP {base}-{base + count - 1} is in use")
    probe = socket.SOCK_DGRAM if link == "udp" else socket.SOCK_STREAM
    with socket.socket(socket.AF_INET, probe) as sock:
        # As the Zenoh listener binds (SO_REUSEADDR): the previous cell's connections in
        # TIME_WAIT do not keep the port from a new listener.
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((HOST, rendezvous))
        except OSError as exc:
            raise DeployError(f"--port-range: {link} port {rendezvous} is in use") from exc
    return vehicle, adapter, loopback_endpoint(rendezvous, _protocol(link, secure))


def run_ports(count: int, link: str, secure: bool,
              port_range: str | None = None) -> tuple[int, int, str]:
    """A run's (vehicle base, adapter base, rendezvous endpoint) for `count` vehicles:
    inside `port_range` (`--port-range`) when given (a parallel sweep's cell), else the
    first free ones."""
    if port_range:
        return ports_in_range(parse_port_range(port_range), count, link, secure)
    vehicle_base, adapter_base = mavlink_bases(count)
    blocks = [range(b, b + count) for b in (vehicle_base, adapter_base)]
    return vehicle_base, adapter_base, rendezvous_endpoint(link, blocks, secure)
