#!/usr/bin/env bash
# Create .venv beside the repo and install enclose; fast when already done.
#   bootstrap.sh        what `enclose` needs to run (deploy/enclose.sh)
#   bootstrap.sh --dev  also the test tools and clients, and iproute2/nftables for the
#                       --netns tests (deploy/test.sh); `enclose run --netns` installs
#                       those two itself when first used
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$repo/.venv"
python="${PYTHON:-python3}"
dev=0
[ "${1:-}" = "--dev" ] && dev=1
if [ ! -x "$venv/bin/python" ]; then
  echo "bootstrap: creating $venv" >&2
  "$python" -m venv "$venv"
fi
# The project's own bytecode, once: where PYTHONDONTWRITEBYTECODE is set every process
# would compile them from source again, which costs each interpreter ~50 ms and leaves a
# forked follower ~2 MB larger (BENCHMARKS.md, issue 15).  Up to date, this takes ~30 ms.
"$venv/bin/python" -m compileall -q "$repo/agents" "$repo/transport" "$repo/deploy" \
  "$repo/sim_backend" >/dev/null 2>&1 || true
# Reinstall only when the dependency list changed since the last install of that kind;
# a dev install covers a plain one.
stamp="$venv/.enclose-installed-dev"
target="$repo[dev]"
if [ "$dev" -eq 0 ]; then
  if [ -f "$stamp" ] && [ ! "$repo/pyproject.toml" -nt "$stamp" ]; then
    exit 0
  fi
  stamp="$venv/.enclose-installed"
  target="$repo"
fi
if [ ! -f "$stamp" ] || [ "$repo/pyproject.toml" -nt "$stamp" ]; then
  echo "bootstrap: installing enclose$([ "$dev" -eq 1 ] && echo ' and its test tools')" \
    "(about a minute on a fresh machine)" >&2
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --upgrade pip >&2
  # The dependencies' bytecode is compiled once here, on every core: where
  # PYTHONDONTWRITEBYTECODE is set, a first import never writes it, and every process of
  # every run compiled numpy, Zenoh's wrapper and the rest from source again (0.6 s of
  # the launcher's start alone; ~20 s here, once per install).
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-compile \
    -e "$target" >&2
  "$venv/bin/python" -m compileall -q -j 0 "$("$venv/bin/python" -c \
    'import sysconfig; print(sysconfig.get_paths()["purelib"])')" >/dev/null 2>&1 || true
  touch "$stamp"
fi
# The --netns tests need `ip` and `nft`, the terminal test `tmux`; install them once if we
# may (those tests skip without).
if [ "$dev" -eq 1 ] && [ "$(id -u)" -eq 0 ]; then
  missing=""
  command -v ip >/dev/null 2>&1 || missing="$missing iproute2"
  command -v nft >/dev/null 2>&1 || missing="$missing nftables"
  command -v tmux >/dev/null 2>&1 || missing="$missing tmux"
  if [ -n "$missing" ]; then
    echo "bootstrap: installing$missing for the --netns and terminal tests" >&2
    # shellcheck disable=SC2086
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q $missing >/dev/null 2>&1 \
      || echo "bootstrap: could not install$missing; the tests that need them will skip" >&2
  fi
fi
