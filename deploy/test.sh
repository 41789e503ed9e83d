#!/usr/bin/env bash
# The project's test command (README, .ci/run): bootstrap, lint, type-check, then the whole suite.
set -uo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
bash deploy/bootstrap.sh --dev || exit 1
bin="$repo/.venv/bin"
"$bin/ruff" check . || exit 1
"$bin/mypy" || exit 1
"$bin/python" -m pytest -q -p no:cacheprovider "$@"
code=$?
# pytest exits 5 when it collected no test: that is a broken suite here, not a pass.
if [ "$code" -eq 5 ]; then
  echo "test.sh: pytest collected no tests" >&2
  exit 1
fi
exit "$code"
