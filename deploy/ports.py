"""Free loopback ports for a run: one TCP port for Zenoh, blocks of UDP ports for MAVLink."""

from __future__ import annotations

import socket

from agents.errors import DeployError

HOST = "127.0.0.1"


def free_tcp_port(host: str = HOST) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


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


def mavlink_bases(count: int, preferred: tuple[int, int] = (14580, 14540)) -> tuple[int, int]:
    """(vehicle listen base, adapter base): PX4 SITL's when free, else the first free pair."""
    candidates = [preferred] + [(b, b + 500) for b in range(20000, 60000, 1000)]
    for vehicle_base, adapter_base in candidates:
        if udp_block_free(vehicle_base, count) and udp_block_free(adapter_base, count):
            return vehicle_base, adapter_base
    raise DeployError(f"no free UDP port blocks for {count} vehicles on {HOST}")
