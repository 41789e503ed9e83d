#!/usr/bin/env bash
# Create .venv beside the repo and install enclose with its test tools; fast when already done.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$repo/.venv"
stamp="$venv/.enclose-installed"
python="${PYTHON:-python3}"
if [ ! -x "$venv/bin/python" ]; then
  echo "bootstrap: creating $venv" >&2
  "$python" -m venv "$venv"
fi
# Reinstall only when the dependency list changed since the last install.
if [ ! -f "$stamp" ] || [ "$repo/pyproject.toml" -nt "$stamp" ]; then
  echo "bootstrap: installing enclose and its dependencies (about a minute on a fresh machine)" >&2
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --upgrade pip >&2
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -e "$repo[dev]" >&2
  touch "$stamp"
fi
# `enclose run --netns` needs `ip` and `nft`; install them once if we may (tests skip without).
if [ "$(id -u)" -eq 0 ] && ! { command -v ip && command -v nft; } >/dev/null 2>&1; then
  echo "bootstrap: installing iproute2 and nftables for --netns" >&2
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q iproute2 nftables >/dev/null 2>&1 \
    || echo "bootstrap: could not install iproute2/nftables; --netns tests will skip" >&2
fi
