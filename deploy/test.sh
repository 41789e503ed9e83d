#!/usr/bin/env bash
# The project's test command (README, .ci/run): bootstrap, lint, then the whole suite in two
# stages.  First the tests marked `serial` (they measure time or load, or load the machine
# themselves), two at a time in fixed lanes (their `xdist_group`), with mypy and the unit
# tests marked `realtime` (threads, processes, sockets, sleep) beside them on one worker at
# idle priority (SCHED_IDLE): the lanes leave about a core idle, and one idle-priority
# worker takes it without moving their figures.  Then the other real swarms side by side
# (pytest-xdist; each run takes a port slot of its own): they mostly wait on real time, so
# four workers per two cores keep the cores ~90 % busy; on a slower machine fewer run at
# once (each real swarm waits for room: tests/admission.py).  The other unit tests run
# beside them at idle priority, where tests/realtime_guard.py refuses them real time.
# Arguments go to every pass, e.g. `bash deploy/test.sh tests/unit`.
# ENCLOSE_TEST_WORKERS sets the number of swarm workers.
set -uo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
bash deploy/bootstrap.sh --dev || exit 1
# The suite's interpreters keep the bytecode they compile.  Where the environment sets
# PYTHONDONTWRITEBYTECODE (this project's CI machines do), each of the ~300 it starts would
# compile the project's modules a test changed, or a file the bootstrap's compile missed,
# from source again: ~1.5 s of CPU for a recorder's end-of-run imports alone when the
# dependencies were left to their first import (the swarm tests took 4.3 min, not 3.6).
unset PYTHONDONTWRITEBYTECODE
bin="$repo/.venv/bin"
"$bin/ruff" check . || exit 1
pytest=("$bin/python" -m pytest -q -p no:cacheprovider)
# Idle priority where the kernel and util-linux offer it, the lowest nice value otherwise.
idle=(chrt --idle 0)
"${idle[@]}" true 2>/dev/null || idle=(nice -n 19)
# A real swarm starts when the machine has room for it (tests/admission.py), but its
# figures still depend on the machine's moment (a shared VM's speed was seen to vary
# fourfold from minute to minute): a failed swarm test runs once more, after a pause, and
# the summary counts and names it ("RERUN").  One that fails twice fails the suite.
rerun=(--reruns 1 --reruns-delay 5 -rR)
beside="$(mktemp -d)"
trap 'rm -rf "$beside"' EXIT
# The unit tests' timeouts are five times their own beside the timed tests, ten times beside
# the swarms (tests/conftest.py): they take what the others leave, and a unit test of 4 s
# was seen to take over 60 s beside three swarms.  A timeout there still catches a hang; it
# does not measure speed.
(
  "${idle[@]}" "$bin/mypy" >"$beside/mypy.log" 2>&1
  echo $? >"$beside/mypy.rc"
  ENCLOSE_TEST_TIMEOUT_SCALE=5 "${idle[@]}" "${pytest[@]}" -n 1 \
    -m "realtime and not integration and not serial" "$@" >"$beside/realtime.log" 2>&1
  echo $? >"$beside/realtime.rc"
) &
beside_pid=$!
"${pytest[@]}" -n 2 --dist loadgroup -m serial "${rerun[@]}" "$@"
alone=$?
wait "$beside_pid"
cat "$beside/mypy.log" "$beside/realtime.log"
types="$(cat "$beside/mypy.rc")"
realtime="$(cat "$beside/realtime.rc")"
# The unit tests on no real time beside the swarms.  (Before the `realtime` split all unit
# tests ran there once: a stall guard's 0.2-s real-time bound, test_liveness, was starved
# past it; the guard now refuses such a test that pass, naming it.)
ENCLOSE_TEST_NO_REALTIME=1 ENCLOSE_TEST_TIMEOUT_SCALE=10 "${idle[@]}" "${pytest[@]}" -n 1 \
  -m "not integration and not serial and not realtime" "$@" >"$beside/unit.log" 2>&1 &
units_pid=$!
workers="${ENCLOSE_TEST_WORKERS:-$((2 * $(nproc)))}"
# --dist loadgroup hands each worker one test at a time (and one queued), in collection
# order: longest first (tests/conftest.py).
"${pytest[@]}" -n "$workers" --dist loadgroup -m "integration and not serial" "${rerun[@]}" "$@"
swarms=$?
wait "$units_pid"
units=$?
cat "$beside/unit.log"
[ "$types" -eq 0 ] || exit "$types"
# pytest exits 5 when it collected (or kept) no test: a pass may have nothing to run for
# the arguments given, but all empty is a broken suite here, not a pass.
if [ "$swarms" -eq 5 ] && [ "$units" -eq 5 ] && [ "$realtime" -eq 5 ] && [ "$alone" -eq 5 ]; then
  echo "test.sh: pytest collected no tests" >&2
  exit 1
fi
for code in "$swarms" "$units" "$realtime" "$alone"; do
  if [ "$code" -ne 0 ] && [ "$code" -ne 5 ]; then
    exit "$code"
  fi
done
exit 0
