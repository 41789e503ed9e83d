#!/usr/bin/env bash
# The project's test command (README, .ci/run): bootstrap, lint, then the whole suite in two
# stages.  First the tests marked `serial` (they measure time or load, or load the machine
# themselves), two at a time in fixed lanes (their `xdist_group`) and nothing else: three
# side by side, or two with the unit tests beside them, missed the paper's bounds and the
# attack's counts.  Then the other real swarms side by side (pytest-xdist; each run takes a
# port slot of its own), with mypy and the unit tests beside them at a lower priority.
# Even the unit tests beside the timed ones at idle priority (SCHED_IDLE) cost the paper's
# run its command jump and its radius bound.  Arguments go to every pass, e.g. `bash
# deploy/test.sh tests/unit`.  Three swarm workers per two cores by default
# (ENCLOSE_TEST_WORKERS sets the number): a real swarm waits on real time at ~0.4 of a core,
# but four side by side with the unit tests put the sweep's paper cell out of its bounds.
set -uo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
bash deploy/bootstrap.sh --dev || exit 1
bin="$repo/.venv/bin"
"$bin/ruff" check . || exit 1
pytest=("$bin/python" -m pytest -q -p no:cacheprovider)
"${pytest[@]}" -n 2 --dist loadgroup -m serial "$@"
alone=$?
# Beside the swarms: mypy, then the unit tests on one worker per core, at nice 10.  CPU-bound
# and not timed, they take what the swarms leave and do not delay a swarm's tick; not the
# lowest, so that other work of the machine's own priority does not starve them past their
# timeouts.  Their timeouts are five times their own there (tests/conftest.py): at nice 10
# beside three swarms, a unit test of 4 s was seen to take over 60 s.  Their output follows
# the swarms'.
workers="${ENCLOSE_TEST_WORKERS:-$(((3 * $(nproc) + 1) / 2))}"
beside="$(mktemp -d)"
trap 'rm -rf "$beside"' EXIT
(
  nice -n 10 "$bin/mypy" >"$beside/mypy.log" 2>&1
  echo $? >"$beside/mypy.rc"
  ENCLOSE_TEST_TIMEOUT_SCALE=5 nice -n 10 "${pytest[@]}" -n "$(nproc)" \
    -m "not integration and not serial" "$@" >"$beside/unit.log" 2>&1
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
