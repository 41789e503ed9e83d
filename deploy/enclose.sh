#!/usr/bin/env bash
# Run the enclose CLI from a fresh clone: bootstraps .venv on first use, then passes arguments on.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$repo/deploy/bootstrap.sh"
exec "$repo/.venv/bin/enclose" "$@"
