"""Helper process for the Zenoh transport integration test.

`python -m tests.integration.transport_peer --swarm S --listen tcp/127.0.0.1:P`
declares liveliness token alive/echo/0, echoes every FollowerState it gets on
follower/0/state back on follower/1/state, and publishes its decoder counters on
status/echo/0.  SIGTERM closes the bus and exits 0; it gives up after --max-s.
"""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
import time
from types import FrameType

from transport.codec import encode
from transport.decoder import Decoder
from transport.key_exprs import SwarmKeys
from transport.messages import FollowerState, ProcessStatus, Stamper
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

_stop = False


def _on_term(_sig: int, _frame: FrameType | None) -> None:
    global _stop
    _stop = True


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--swarm", required=True)
    parser.add_argument("--listen", required=True)
    parser.add_argument("--max-s", type=float, default=60.0)
    args = parser.parse_args()
    signal.signal(signal.SIGTERM, _on_term)
    keys = SwarmKeys(args.swarm)
    echo_stamper, status_stamper = Stamper("echo-0"), Stamper("echo-0")
    decoder = Decoder(expect=(FollowerState,))
    deadline = time.monotonic() + args.max_s
    with ZenohBus(ZenohConfig(listen=(args.listen,))) as bus:
        sub = bus.subscribe(keys.follower_state(0))
        echo = bus.declare_publisher(keys.follower_state(1))
        status = bus.declare_publisher(keys.status("echo", 0))
        bus.declare_token(keys.alive("echo", 0))
        while not _stop and time.monotonic() < deadline:
            for inbound in decoder.drain(sub):
                msg = inbound.message
                assert isinstance(msg, FollowerState)
                echo.put(encode(dataclasses.replace(msg, header=echo_stamper.header(), index=1)))
            state = ProcessStatus(status_stamper.header(), "echo", 0, "running", decoder.counters())
            status.put(encode(state))
            time.sleep(0.005)
    return 0


if __name__ == "__main__":
    sys.exit(main())
