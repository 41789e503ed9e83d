"""A stand-in child for supervisor tests: `sleep S`, `ready S` (prints "ready", then
sleeps), `exit CODE`, `print TEXT`, or `has MODULE` (prints whether MODULE is imported).

Runs as `python -m tests.child_proc ...` (bound to its launcher's life first, as every
entry point: agents.shell.lifeline) or forked (deploy.procs.forked calls `main(argv)`)."""

import sys
import time
from collections.abc import Sequence

from agents.shell.lifeline import die_with_launcher


def main(argv: Sequence[str]) -> int:
    if argv[0] == "ready":
        print("ready", flush=True)
    if argv[0] in ("sleep", "ready"):
        time.sleep(float(argv[1]))
    if argv[0] == "print":
        print(argv[1])
    if argv[0] == "has":
        print(argv[1] in sys.modules)
    return int(argv[1]) if argv[0] == "exit" else 0


if __name__ == "__main__":
    die_with_launcher()
    sys.exit(main(sys.argv[1:]))
