"""A run's processes die with their launcher, however it dies (SIGKILL included).

Each child asks the kernel for SIGKILL when its parent dies (Linux prctl
PR_SET_PDEATHSIG), then checks that its parent is still the launcher: one that died
before the request was made has already handed its children to init, and the check
catches it.  SIGKILL and not SIGTERM: a run whose launcher died is lost anyway, and
SIGKILL also ends a process that is stopped (a `pause` fault: a stopped process never
handles SIGTERM) or stuck; the recording survives it (the MCAP is written in chunks).

The request names the parent *thread*: the launcher starts every child from its main
thread (deploy.procs.supervisor), whose end is the process's end.  How each kind of child gets
here:
- started as `python -m ...` by the supervisor: the launcher's PID in the environment
  (LAUNCHER_PID_ENV, `launcher_env`), read by `die_with_launcher` first thing in the
  process's main (an inner launcher in a namespace too: deploy.netns.netns_run);
- forked by the launcher (deploy.procs.forked): `die_with` in the child, before anything else;
- forked by the fork server (deploy.procs.zygote), which double-forks so that its children
  are reparented to the launcher: the request would fire when the middle process exits,
  so the child waits until it is the launcher's (`via`), then asks.
Outside a run (a process started by hand) there is nothing to die with.
"""

from __future__ import annotations

import ctypes
import os
import signal
import time

PR_SET_PDEATHSIG, PR_SET_CHILD_SUBREAPER = 1, 36  # linux/prctl.h
LAUNCHER_PID_ENV = "ENCLOSE_LAUNCHER_PID"
EXIT_ORPHANED = 75  # the launcher was gone before this process could bind to it
ADOPTION_TIMEOUT_S = 5.0  # a zygote's middle process exits at once; this is a backstop


def prctl(option: int, value: int) -> bool:
    """Linux prctl(2); False where it is missing or refused."""
    try:
        return int(ctypes.CDLL(None, use_errno=True).prctl(option, value, 0, 0, 0)) == 0
    except (OSError, AttributeError):
        return False


def set_subreaper(on: bool) -> bool:
    """Adopt (or stop adopting) this process's orphaned descendants; False where unsupported."""
    return prctl(PR_SET_CHILD_SUBREAPER, int(on))


def launcher_env() -> dict[str, str]:
    """The environment entry that binds a child started now to this process."""
    return {LAUNCHER_PID_ENV: str(os.getpid())}


def die_with(parent_pid: int, via: int | None = None) -> None:
    """SIGKILL this process when `parent_pid` dies; SystemExit(EXIT_ORPHANED) if it is not
    our parent (any more).  `via`: a middle process that forked us and is exiting, whose
    death must not count (we wait, briefly, until we are `parent_pid`'s)."""
    if via is not None:
        deadline = time.monotonic() + ADOPTION_TIMEOUT_S
        while os.getppid() == via and time.monotonic() < deadline:
            time.sleep(0.001)
    prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent_pid:
        raise SystemExit(EXIT_ORPHANED)


def die_with_launcher() -> None:
    """`die_with` the launcher named in the environment, if any (then removed from it:
    this process's own children are bound to this process, by their own entry)."""
    raw = os.environ.pop(LAUNCHER_PID_ENV, None)
    if raw is not None and raw.isascii() and raw.isdigit():
        die_with(int(raw))
