"""A stand-in child for supervisor tests: `sleep S`, `exit CODE`, `print TEXT`, or
`has MODULE` (prints whether MODULE is imported).

Runs as `python -m tests.child_proc ...` or forked (deploy.forked calls `main(argv)`)."""

import sys
import time
from collections.abc import Sequence


def main(argv: Sequence[str]) -> int:
    if argv[0] == "sleep":
        time.sleep(float(argv[1]))
    if argv[0] == "print":
        print(argv[1])
    if argv[0] == "has":
        print(argv[1] in sys.modules)
    return int(argv[1]) if argv[0] == "exit" else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
