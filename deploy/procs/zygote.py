"""A fork server for the lean processes (issue 15: <= 50 MB per follower).

A forked child's RSS counts every page of its parent it inherited: a follower forked from
the launcher carries the launcher's numpy, pymavlink dialect and simulator modules even
though it never uses them.  So the launcher starts this small server early, in a fresh
interpreter that imports only the lean processes' modules, and asks it to fork them; the
children keep the fast start of a fork (no interpreter start, no imports) without the
launcher's pages.

The server double-forks, so that each child is orphaned at once and reparented to the
launcher, which marks itself a child subreaper (Linux prctl) while it starts children:
the launcher then waits for its followers by PID exactly as for the ones it forked itself
(deploy.procs.forked.ForkedProcess).  Protocol on the server's stdin/stdout: one JSON request
per line, `{"module", "argv", "log"}`, answered by the child's PID (or `error: ...`);
`exit` (or end of input) ends it.  The launcher's own forked children inherit its ends
of these pipes, so they close them (`fds`) and the launcher ends the server by `exit`,
not by closing its end alone.

python -m deploy.procs.zygote LAUNCHER_PID MODULE...
(started by deploy.procs.supervisor, not by hand)
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

from agents.shell.lifeline import die_with, set_subreaper
from deploy.procs.forked import ForkedProcess, fork_pid, trim_heap
from deploy.procs.pids import identify
from errors import DeployError


class Zygote:
    """The launcher's side: start the server, fork children through it, close it."""

    def __init__(self, modules: Sequence[str], log_path: Path) -> None:
        if not set_subreaper(True):
            raise DeployError("cannot become a child subreaper: no fork server")
        self.modules = frozenset(modules)
        with open(log_path, "ab") as log:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "deploy.procs.zygote", str(os.getpid()), *modules],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log,
                start_new_session=True, text=True, bufsize=1,
                env={**os.environ, "PYTHONUNBUFFERED": "1"},
            )
        self._ready = False
        self.ident = identify(self.proc.pid)

    def _answer(self) -> str:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline().strip()
        if not line or line.startswith("error"):
            raise DeployError(f"fork server: {line or 'exited'} (see its log)")
        return line

    def fork(self, module: str, argv: Sequence[str], log_path: Path) -> ForkedProcess:
        assert self.proc.stdin is not None
        if not self._ready:  # its imports ran while the launcher made credentials
            self._answer()
            self._ready = True
        request = {"module": module, "argv": list(argv), "log": str(log_path)}
        self.proc.stdin.write(json.dumps(request) + "\n")
        return ForkedProcess(int(self._answer()))

    def fds(self) -> tuple[int, ...]:
        """This process's ends of the server's pipes, which a child forked here must close."""
        return tuple(f.fileno() for f in (self.proc.stdin, self.proc.stdout) if f is not None)

    def close(self, timeout_s: float = 5.0) -> None:
        """End the server and stop adopting orphans."""
        with contextlib.suppress(OSError, ValueError):
            if self.proc.stdin is not None:
                self.proc.stdin.write("exit\n")
                self.proc.stdin.close()
        try:
            self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        set_subreaper(False)


def _double_fork(module: str, argv: list[str], log_path: Path, launcher: int) -> int:
    """Fork a middle process that forks the child and exits: the child's parent becomes
    the subreaper (the launcher) before we reap the middle one and answer; the child
    binds its life to the launcher's once adopted (agents.shell.lifeline)."""
    read_end, write_end = os.pipe()
    middle = os.fork()
    if middle == 0:
        os.close(read_end)
        try:
            pid = fork_pid(module, argv, log_path, close_fds=(write_end,), parent=launcher,
                           via=os.getpid())
            os.write(write_end, f"{pid}\n".encode())
        finally:
            os._exit(0)
    os.close(write_end)
    with os.fdopen(read_end, "rb") as answer:
        text = answer.readline()
    os.waitpid(middle, 0)
    return int(text)


def main(argv: Sequence[str]) -> int:
    # Killed with the launcher, whatever kills it: requests it had queued must not fork
    # followers that nobody will stop (an outside cleanup finds us in pids.json too).
    launcher = int(argv[0])
    die_with(launcher)
    for module in argv[1:]:
        importlib.import_module(module)
    trim_heap()
    print("ready", flush=True)
    for line in sys.stdin:
        if line.strip() == "exit":
            break
        try:
            req = json.loads(line)
            pid = _double_fork(str(req["module"]), [str(a) for a in req["argv"]],
                               Path(req["log"]), launcher)
        except (ValueError, KeyError, OSError) as exc:
            print(f"error: {type(exc).__name__}: {exc}", flush=True)
            continue
        print(pid, flush=True)
    return 0


if __name__ == "__main__":
    main(sys.argv[1:])
    # Nothing to flush or close: skip the interpreter's finalisation of every module
    # imported (a few hundred ms on a loaded machine, which the launcher would wait for).
    os._exit(0)
