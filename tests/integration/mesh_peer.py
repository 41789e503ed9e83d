"""Helper process for tests/integration/test_zenoh_mesh.py: one Zenoh peer of a mesh.

`python -m tests.integration.mesh_peer --swarm S --index I --listen EP [--connect EP]
[--zenoh-config FILE]` opens a peer session as every enclose process does
(transport.zenoh_config), declares the liveliness token alive/mesh/I, and holds its
session until SIGTERM (exit 0) or --max-s.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from types import FrameType

from transport.key_exprs import SwarmKeys
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

_stop = threading.Event()


def _on_term(_sig: int, _frame: FrameType | None) -> None:
    _stop.set()


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--swarm", required=True)
    parser.add_argument("--index", type=int, required=True)
    parser.add_argument("--listen", required=True)
    parser.add_argument("--connect", default=None)
    parser.add_argument("--zenoh-config", default=None)
    parser.add_argument("--max-s", type=float, default=60.0)
    args = parser.parse_args()
    signal.signal(signal.SIGTERM, _on_term)
    connect = () if args.connect is None else (args.connect,)
    cfg = ZenohConfig(listen=(args.listen,), connect=connect,
                      user_config_path=args.zenoh_config)
    with ZenohBus(cfg) as bus:
        bus.declare_token(SwarmKeys(args.swarm).alive("mesh", args.index))
        _stop.wait(args.max_s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
