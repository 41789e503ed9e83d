"""`enclose run`'s live view options, and how the launcher learns the view's URL.

The recorder serves the view (deploy.recording.live_server); the launcher asks it for one
with `--live-port`, learns the URL it got from `progress.json` ("live_url", written before
the recorder declares its liveliness token, so it is there once all are linked), prints it
and keeps it in launch.json ("live_url", null when off).  A restarted recorder is given the
port its predecessor had, so a client's reconnect finds it again.
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urlparse

from deploy.recording.live_defaults import DEFAULT_HOST, DEFAULT_PORT, PROGRESS_FILE

log = logging.getLogger("enclose.run")
URL_WAIT_S = 2.0


def add_live_arguments(p: Any) -> None:
    p.add_argument("--no-live", action="store_true",
                   help="no live view (by default the recorder serves one for Foxglove)")
    p.add_argument("--live-port", type=int, default=DEFAULT_PORT, metavar="PORT",
                   help=f"live view port, or the next free one (default {DEFAULT_PORT})")
    p.add_argument("--live-host", default=DEFAULT_HOST, metavar="ADDR",
                   help="address the live view listens on (default 127.0.0.1: this machine "
                   "only; the view has no authentication, so another address shows the run "
                   "to anyone who can reach it)")


@dataclass(frozen=True)
class LiveOptions:
    """Where the recorder serves the live view (the port, or the next free one)."""

    port: int = DEFAULT_PORT
    host: str = DEFAULT_HOST

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> LiveOptions | None:
        """None with --no-live."""
        return None if args.no_live else cls(args.live_port, args.live_host)


def recorder_live_argv(live: LiveOptions | None) -> list[str]:
    if live is None:
        return []  # `enclose host` has no live view: its recorder may be in a namespace
    return ["--live-port", str(live.port), "--live-host", live.host]


def read_live_url(run_dir: Path, wait_s: float = URL_WAIT_S) -> str | None:
    """The recorder's live URL from progress.json (None if it serves none)."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            url = json.loads((run_dir / PROGRESS_FILE).read_text()).get("live_url")
            return url if isinstance(url, str) else None
        except (OSError, ValueError, AttributeError):
            if time.monotonic() > deadline:
                return None
        time.sleep(0.05)


def announce_live_url(live: LiveOptions | None, run_dir: Path) -> str | None:
    """Once all are linked: the live URL, logged with how to open it (None when off)."""
    if live is None:
        return None
    url = read_live_url(run_dir)
    if url is None:
        log.warning("no live view: the recorder serves none (see logs/recorder.log)")
    else:
        log.info("live view: %s (Foxglove: Open connection -> Foxglove WebSocket -> this URL; "
                 "layout docs/foxglove-layout.json)", url)
    return url


def pin_live_port(argv: list[str], url: str | None) -> None:
    """Point a restarting recorder's `--live-port` at the port its predecessor served."""
    port = urlparse(url).port if url else None
    if port is not None and "--live-port" in argv:
        argv[argv.index("--live-port") + 1] = str(port)
