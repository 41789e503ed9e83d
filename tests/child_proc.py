"""A stand-in child for supervisor tests: `sleep S` or `exit CODE`."""

import sys
import time

if __name__ == "__main__":
    if sys.argv[1] == "sleep":
        time.sleep(float(sys.argv[2]))
    sys.exit(int(sys.argv[2]) if sys.argv[1] == "exit" else 0)
