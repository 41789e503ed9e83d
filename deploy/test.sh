#!/usr/bin/env bash
# The project's test command (README, .ci/run): bootstrap, lint, then the whole suite in two
# stages.  First the tests marked `serial` (they measure time or load, or load the machine
# themselves), two at a time in fixed lanes (their `xdist_group`), with only mypy and the
# unit tests beside them at idle priority: three side by side, or two with the unit tests
# beside them at nice 10, missed the paper's bounds and the attack's counts.  Then the other
# real swarms side by side (pytest-xdist; each run takes a port slot of its own).
# Arguments go to every pass, e.g. `bash deploy/test.sh tests/unit`.  Three swarm workers
# per two cores by default (ENCLOSE_TEST_WORKERS sets the number): a real swarm waits on
# real time at ~0.4 of a core, but four side by side on 2 cores starve each other.
set -uo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
bash deploy/bootstrap.sh --dev || exit 1
bin="$repo/.venv/bin"
"$bin/ruff" check . || exit 1
pytest=("$bin/python" -m pytest -q -p no:cacheprovider)
# Beside the timed tests: mypy, then the unit tests on one worker per core, as SCHED_IDLE
# (nice 19 where chrt cannot): they run only on what the two timed lanes leave idle and give
# way at once when a timed test's process wakes, so they do not delay its ticks.  Their
# timeouts are five times their own there (tests/conftest.py): starved, a unit test of 4 s
# was seen to take over 60 s.
idle=(nice -n 19)
chrt --idle 0 true 2>/dev/null && idle=(chrt --idle 0)
beside="$(mktemp -d)"
trap 'rm -rf "$beside"' EXIT
(
  "${idle[@]}" "$bin/mypy" >"$beside/mypy.log" 2>&1
  echo $? >"$beside/mypy.rc"
  ENCLOSE_TEST_TIMEOUT_SCALE=5 "${idle[@]}" "${pytest[@]}" -n "$(nproc)" \
    -m "not integration and not serial" "$@" >"$beside/unit.log" 2>&1
  echo $? >"$beside/unit.rc"
) &
beside_pid=$!
"${pytest[@]}" -n 2 --dist loadgroup -m serial "$@"
alone=$?
wait "$beside_pid"
cat "$beside/mypy.log" "$beside/unit.log"
types="$(cat "$beside/mypy.rc")"
units="$(cat "$beside/unit.rc")"
[ "$types" -eq 0 ] || exit "$types"
# Then the other swarms alone.  --dist loadgroup hands each worker one test at a time (and
# one queued), in collection order: longest first (tests/conftest.py).
workers="${ENCLOSE_TEST_WORKERS:-$(((3 * $(nproc) + 1) / 2))}"
"${pytest[@]}" -n "$workers" --dist loadgroup -m "integration and not serial" "$@"
swarms=$?
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
