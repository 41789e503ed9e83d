#!/usr/bin/env bash
# The project's test command (README, .ci/run): bootstrap, lint, type-check, then the whole suite
# in two passes: the real swarms side by side (pytest-xdist; each run takes a port slot of its
# own) with the unit tests beside them, then the tests marked `serial` (they measure time or
# load) alone.  Arguments go to every pass, e.g. `bash deploy/test.sh tests/unit`.  Three
# swarm workers per two cores by default: a real swarm waits on real time at ~0.4 of a core,
# but four side by side on 2 cores starve each other out of the paper's bounds
# (ENCLOSE_TEST_WORKERS sets the number).
set -uo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
bash deploy/bootstrap.sh --dev || exit 1
bin="$repo/.venv/bin"
"$bin/ruff" check . || exit 1
# The first pass is two at once.  The real swarms (integration, not serial) side by side on
# `workers` (pytest-xdist), at the shell's priority: they wait on real time and leave most
# of a core idle.  Beside them mypy, then the unit tests on one worker per core, at a lower
# priority (nice 10): CPU-bound and not timed, they take what the swarms leave and do not
# delay a swarm's tick, as unit tests on the swarms' workers did; not the lowest, so that
# other work of the machine's own priority does not starve them past their timeouts.
# Their output follows the swarms'.
pytest=("$bin/python" -m pytest -q -p no:cacheprovider)
workers="${ENCLOSE_TEST_WORKERS:-$(((3 * $(nproc) + 1) / 2))}"
beside="$(mktemp -d)"
trap 'rm -rf "$beside"' EXIT
(
  nice -n 10 "$bin/mypy" >"$beside/mypy.log" 2>&1
  echo $? >"$beside/mypy.rc"
  nice -n 10 "${pytest[@]}" -n "$(nproc)" -m "not integration and not serial" "$@" \
    >"$beside/unit.log" 2>&1
  echo $? >"$beside/unit.rc"
) &
beside_pid=$!
# --dist loadgroup hands each worker one test at a time (and one queued), in collection
# order: longest first (tests/conftest.py).
"${pytest[@]}" -n "$workers" --dist loadgroup -m "integration and not serial" "$@"
swarms=$?
wait "$beside_pid"
cat "$beside/mypy.log" "$beside/unit.log"
types="$(cat "$beside/mypy.rc")"
units="$(cat "$beside/unit.rc")"
[ "$types" -eq 0 ] || exit "$types"
"${pytest[@]}" -m serial "$@"
alone=$?
# pytest exits 5 when it collected (or kept) no test: a pass may have nothing to run for
# the arguments given, but all empty is a broken suite here, not a pass.
if [ "$swarms" -eq 5 ] && [ "$units" -eq 5 ] && [ "$alone" -eq 5 ]; then
  echo "test.sh: pytest collected no tests" >&2
  exit 1
fi
for code in "$swarms" "$units" "$alone"; do
  if [ "$code" -ne 0 ] && [ "$code" -ne 5 ]; then
    exit "$code"
  fi
done
exit 0
