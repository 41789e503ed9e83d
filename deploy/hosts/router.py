"""A host's Zenoh router: the host's processes are its clients; it links to the other hosts'.

    python -m deploy.hosts.router --listen tls/10.0.0.5:7447 [--connect tls/10.0.0.6:7447 ...] \
        --credentials router-0.json --swarm NAME

There is no `zenohd` package on PyPI or Debian here; a zenoh-python session in router
mode is a router (notes/multihost.md).  Multicast scouting stays off and it listens only
on the endpoints given.  With credentials it speaks mTLS with the swarm's CA and enforces
the swarm's ACL on its ingress: a client may put only its own keys (transport.access);
other routers relay everyone's.  With `--clock-id router-<k>` it probes the other routers'
clocks for its host's processes (transport.clock_sync).  Runs until SIGTERM/SIGINT.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
from collections.abc import Sequence
from dataclasses import dataclass

from agents.shell.lifeline import die_with_launcher
from agents.shell.process import stop_on_signals
from errors import EncloseError
from transport.credentials import Identity
from transport.key_exprs import SwarmKeys
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

log = logging.getLogger("deploy.hosts.router")


@dataclass(frozen=True)
class RouterOptions:
    """A router's command line."""

    listen: tuple[str, ...]
    connect: tuple[str, ...] = ()
    credentials: str | None = None  # identity file
    swarm: str = "enclose"
    zenoh_config: str | None = None
    clock_id: str | None = None  # router-K: probe the other routers' clocks
    clock_routers: int = 1  # the swarm's routers, router-0..: whose probes count

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> RouterOptions:
        return cls(tuple(args.listen), tuple(args.connect), args.credentials, args.swarm,
                   args.zenoh_config, args.clock_id, args.clock_routers)


def parse_options(argv: Sequence[str] | None) -> RouterOptions:
    parser = argparse.ArgumentParser(prog="python -m deploy.hosts.router", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--listen", action="append", required=True, metavar="ENDPOINT")
    parser.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                        help="another host's router (repeatable)")
    parser.add_argument("--credentials", default=None, metavar="IDENTITY_JSON")
    parser.add_argument("--swarm", default="enclose",
                        help="swarm name (its key space, and the logs)")
    parser.add_argument("--zenoh-config", default=None, metavar="JSON5")
    parser.add_argument("--clock-id", default=None, metavar="router-K",
                        help="probe the other routers' clocks as this host's clock "
                        "(transport.clock_sync): for hosts whose clocks differ")
    parser.add_argument("--clock-routers", type=int, default=1, metavar="K",
                        help="with --clock-id: the swarm's routers are router-0..router-K-1 "
                        "(probes from any other name are dropped)")
    return RouterOptions.from_namespace(parser.parse_args(argv))


def main(argv: Sequence[str] | None = None) -> int:
    die_with_launcher()  # agents.shell.lifeline
    opts = parse_options(argv)
    logging.basicConfig(level=logging.INFO,
                        format="%(asctime)s %(levelname)s router: %(message)s")
    cfg = ZenohConfig(
        mode="router", listen=opts.listen, connect=opts.connect,
        user_config_path=opts.zenoh_config,
        identity=None if opts.credentials is None else Identity.load(opts.credentials))
    try:
        with stop_on_signals() as stop, ZenohBus(cfg) as bus:
            log.info("router %s of swarm %s: listen %s, connect %s", bus.zid, opts.swarm,
                     opts.listen, opts.connect)
            if opts.clock_id is not None:
                bus.start_clock_sync(SwarmKeys(opts.swarm), opts.clock_id, opts.clock_routers,
                                     probe=True)
            idle = threading.Event()
            while not stop.raised:
                idle.wait(0.2)
    except EncloseError as exc:
        log.error("%s: %s", type(exc).__name__, exc)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
