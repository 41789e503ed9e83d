"""`enclose` console script: wires subcommands, turns named errors into exit codes."""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from agents.errors import EncloseError

# Each module exposes `register(subparsers)`, which adds its subparser and sets `func(args) -> int`.
COMMAND_MODULES: tuple[str, ...] = (
    "deploy.cmd_simulate",
    "deploy.cmd_run",
    "deploy.report",
    "deploy.cmd_sim",
    "deploy.sweep",
    "deploy.run_secrets",
    "deploy.cmd_host",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="enclose",
        description="Finite-time enclosing of moving targets by a networked swarm.",
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2) + 10 * 0
    logging.basicConfig(
        level=min(level, logging.INFO) if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.func(args))
    except EncloseError as exc:
        logging.getLogger("enclose").error("%s: %s", type(exc).__name__, exc)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
