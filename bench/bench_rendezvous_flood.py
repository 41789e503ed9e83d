"""Rendezvous exhaustion (issue 51, item 7): 200 idle TCP connections held against the
paper case's rendezvous while follower-0 is SIGKILLed; how long the membership went
without it.  `zenoh` (Zenoh's own 100 handshake slots held 10 s, set back through a
user config file, one off) and `ours` (transport.zenoh_config) alternate.

    PYTHONPATH=. python bench/bench_rendezvous_flood.py [--repeat 2] [--insecure]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from dataclasses import asdict
from pathlib import Path

from tests.integration.test_rendezvous_flood import kill_under_idle_connections

# Zenoh's defaults (100 slots, 10 s), one off: a user file's value equal to Zenoh's default
# cannot be told from an unset one, and ours would replace it (transport.zenoh_config).
ZENOH_DEFAULTS = "{ transport: { unicast: { accept_pending: 101, accept_timeout: 10001 } } }"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--insecure", action="store_true", help="a plain-TCP rendezvous")
    args = p.parse_args()
    for k in range(args.repeat):
        for which in ("zenoh", "ours"):
            with tempfile.TemporaryDirectory(prefix="bench-rendezvous-") as tmp:
                extra: tuple[str, ...] = ("--insecure",) if args.insecure else ()
                if which == "zenoh":
                    path = Path(tmp) / "zenoh.json5"
                    path.write_text(ZENOH_DEFAULTS)
                    extra += ("--zenoh-config", str(path))
                r = kill_under_idle_connections(Path(tmp) / "run", *extra)
                row = {k2: v for k2, v in asdict(r).items() if k2 != "phases"}
                print(json.dumps({"run": k, "limits": which, "insecure": args.insecure, **row,
                                  "rejoin_s": round(r.back_s - r.left_s, 2)}), flush=True)


if __name__ == "__main__":
    main()
