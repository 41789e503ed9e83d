"""Start a swarm process as a fork of the launcher (issue 15: fast start).

`python -m agents.follower.main` spends most of its start-up importing (numpy, Zenoh,
pymavlink: ~0.4 s of CPU each; 16 followers on 2 cores queue for seconds).  The
launcher imports a process's module once, then forks: the child is its own OS process
(own PID, session, log, Zenoh session and sockets) that runs `module.main(argv)` at once,
its imported pages shared copy-on-write with its siblings.

Safe only while the launcher holds no threads but its own and no Zenoh session: the
launcher forks before it opens its bus, and restarts later start a fresh interpreter
(deploy.procs.supervisor).  numpy's OpenBLAS pool is restarted by OpenBLAS's own fork handler.
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import importlib
import logging
import os
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path

from agents.shell import phases
from agents.shell.lifeline import die_with
from errors import DeployError


def trim_heap() -> None:
    """Give the C heap's free pages back to the system before forking: each child counts
    every resident page it inherits in its RSS, free ones too, and a module compiled from
    source (no cached bytecode, PYTHONDONTWRITEBYTECODE) leaves megabytes of them behind
    when nothing imported after it reuses them.  glibc only; a no-op elsewhere."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).malloc_trim(0)


TASKS = Path("/proc/self/task")


def fork_is_safe() -> bool:
    """True while this process runs no thread but the main one and holds no Zenoh
    session.  Threads are counted by the kernel too (`only_thread`), not only Python's:
    Zenoh's runtime threads outlive the last Zenoh session a process closed (a process that ran
    `enclose.run` before, as a pytest worker does), and a child forked beside them inherits
    a runtime whose threads it does not have: its `zenoh.open` hangs for good."""
    from transport.zenoh_bus import ZenohBus

    return threading.active_count() == 1 and ZenohBus.open_sessions == 0 and only_thread()


def only_thread(tasks: Path = TASKS) -> bool:
    """The kernel lists one thread of this process (True where there is no /proc)."""
    try:
        return sum(1 for _ in tasks.iterdir()) == 1
    except OSError:
        return True


class ForkedProcess:
    """The part of `subprocess.Popen` the supervisor uses, for a forked child."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            with contextlib.suppress(ChildProcessError):
                pid, status = os.waitpid(self.pid, os.WNOHANG)
                if pid == self.pid:
                    self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def send_signal(self, signum: int) -> None:
        if self.poll() is None:
            os.kill(self.pid, signum)


def _child(run: Callable[[], int | None], log_path: Path | None, mode: int, parent: int,
           via: int | None) -> None:
    """In the child: bound to die with `parent` (agents.shell.lifeline), its own session and
    output, default signals, then `run`; never returns."""
    code: int | str | None = 1
    try:
        die_with(parent, via)
        os.setsid()  # like start_new_session: a terminal's Ctrl-C reaches only the launcher
        if log_path is not None:
            fd = os.open(log_path, os.O_WRONLY | os.O_CREAT | mode, 0o644)
            os.dup2(fd, 1)
            os.dup2(fd, 2)
            os.close(fd)
            # Fresh, line-buffered writers on the new fds (the launcher's may be wrapped).
            sys.stdout = open(1, "w", buffering=1, closefd=False)  # noqa: SIM115
            sys.stderr = open(2, "w", buffering=1, closefd=False)  # noqa: SIM115
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.close(null)
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_DFL)
        phases.reset()
        root = logging.getLogger()
        for handler in list(root.handlers):  # the launcher's: the child sets up its own
            root.removeHandler(handler)
        code = run()
    except SystemExit as exc:
        code = exc.code
    except BaseException:  # a child must never return into the launcher
        traceback.print_exc()
        code = 1
    finally:
        with contextlib.suppress(BaseException):
            logging.shutdown()
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(code if isinstance(code, int) else 1)


def _fork(run: Callable[[], int | None], log_path: Path | None, mode: int,
          parent: int | None = None, via: int | None = None) -> int:
    """Fork a child that dies with `parent` (default: this process; agents.shell.lifeline)."""
    parent = os.getpid() if parent is None else parent
    # What exists now is shared with the child: out of the collector's reach, its pages
    # stay shared instead of being copied when a collection touches every object.
    gc.freeze()
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:
        _child(run, log_path, mode, parent, via)
    return pid


def fork_pid(module: str, argv: Sequence[str], log_path: Path,
             close_fds: Sequence[int] = (), parent: int | None = None,
             via: int | None = None) -> int:
    """Fork a child that runs `module.main(argv)` with its output in `log_path` (new
    file), after closing `close_fds` (the caller's, which the child must not hold open).
    It dies with `parent` (default: this process), once `via` (if given) is gone."""
    def run() -> int:
        for fd in close_fds:
            os.close(fd)
        return int(importlib.import_module(module).main(list(argv)))

    return _fork(run, log_path, os.O_TRUNC, parent, via)


def fork_main(module: str, argv: Sequence[str], log_path: Path,
              import_in_child: bool = False, close_fds: Sequence[int] = ()) -> ForkedProcess:
    """Fork a child that runs `module.main(argv)` with its output in `log_path` (new file).

    The module is imported here, once, before the fork, unless `import_in_child`: then
    the child imports it, and what it alone needs stays out of this process (and of the
    children forked after it)."""
    if not import_in_child:
        importlib.import_module(module)
    return ForkedProcess(fork_pid(module, argv, log_path, close_fds))


def call_forked(fn: Callable[[], None], what: str,
                meanwhile: Callable[[], None] | None = None) -> None:
    """Run `fn` in a short-lived fork, so that what it imports (e.g. `cryptography`, to
    make credentials) does not stay in this process and in every child forked later;
    this process runs `meanwhile` in the mean time."""
    def run() -> int:
        fn()
        return 0

    pid = _fork(run, None, 0)
    try:
        if meanwhile is not None:
            meanwhile()
    finally:
        _, status = os.waitpid(pid, 0)
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise DeployError(f"{what} failed in its helper process (exit code {code})")
