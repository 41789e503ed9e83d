"""Start, watch and stop the OS processes of a run, by PID, leaving none behind."""

from __future__ import annotations

import contextlib
import importlib
import logging
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from agents.shell.lifeline import launcher_env
from deploy.procs.forked import ForkedProcess, fork_is_safe, fork_main, trim_heap
from deploy.procs.pids import ProcessId, identify, write_pids
from deploy.procs.zygote import Zygote
from errors import DeployError

log = logging.getLogger(__name__)
Clock = Callable[[], float]
FORKED_MODULES = ("sim_backend.swarm_sim", "agents.target")
# Forked by a fork server that imported only these (deploy.procs.zygote): a follower must not
# inherit the launcher's numpy and simulator pages (issue 15: <= 50 MB per follower).
LEAN_MODULES = ("agents.follower.main",)


@dataclass
class Child:
    name: str
    argv: list[str]
    log_path: Path
    proc: subprocess.Popen[bytes] | ForkedProcess | None = None
    exit_code: int | None = None
    restarts: int = 0
    spawned_s: float | None = None  # CLOCK_MONOTONIC at the last spawn (agents.shell.phases)
    ident: ProcessId | None = None  # PID and start time of the last spawn (deploy.procs.pids)

    @property
    def pid(self) -> int | None:
        return None if self.proc is None else self.proc.pid

    def poll(self) -> int | None:
        if self.proc is not None and self.exit_code is None:
            self.exit_code = self.proc.poll()
        return self.exit_code

    def tail(self, lines: int = 12) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return "(no log)"


@dataclass
class Supervisor:
    """Owns the children of one run; every child runs in its own session so that a
    terminal's Ctrl-C reaches only the launcher, which then stops them in order."""

    log_dir: Path
    children: list[Child] = field(default_factory=list)
    clock: Clock = time.monotonic
    zygote: Zygote | None = None

    def start_fork_server(self) -> None:
        """Start the fork server of the lean processes as early as possible: its own
        interpreter start and imports then overlap with the launcher's work."""
        if self.zygote is None:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            try:
                self.zygote = Zygote(LEAN_MODULES, self.log_dir / "zygote.log")
            except DeployError as exc:  # not Linux: they are forked from here instead
                log.warning("%s", exc)
            self._write_pids()

    def preload(self) -> None:
        """Import the modules of the processes the launcher forks, before it forks them."""
        for module in FORKED_MODULES:
            importlib.import_module(module)
        trim_heap()

    def end_forks(self) -> None:
        """Every child is started: stop the fork server (restarts start interpreters)."""
        if self.zygote is not None:
            self.zygote.close()
            self.zygote = None
            self._write_pids()

    def start(self, name: str, module: str, args: Sequence[str], fork: bool = False,
              prefix: Sequence[str] = ()) -> Child:
        """Start `python -m module args`, after `prefix` (e.g. `ip netns exec NS env K=V`);
        with `fork` (and no prefix), as a fork of this process that runs `module.main(args)`
        (deploy.procs.forked: no interpreter start-up, no imports; a module not in FORKED_MODULES
        or LEAN_MODULES is imported by its child alone), when that is safe (no other
        thread, no Zenoh session here yet); a LEAN_MODULES one by the fork server when it
        runs (deploy.procs.zygote); else, and on a restart, a fresh interpreter."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        argv = [*prefix, sys.executable, "-m", module, *args]
        child = Child(name, argv, self.log_dir / f"{name}.log")
        if fork and not prefix and self.zygote is not None and module in self.zygote.modules:
            child.spawned_s = time.monotonic()
            child.proc = self.zygote.fork(module, args, child.log_path)
        elif fork and not prefix and fork_is_safe():
            child.spawned_s = time.monotonic()
            here = (*FORKED_MODULES, *LEAN_MODULES)  # no fork server: fast, if not lean
            child.proc = fork_main(module, list(args), child.log_path,
                                   import_in_child=module not in here,
                                   close_fds=() if self.zygote is None else self.zygote.fds())
        else:
            self._spawn(child, "wb")
        assert child.proc is not None
        child.ident = identify(child.proc.pid)  # ours, not reaped: the PID is still it
        self.children.append(child)
        self._write_pids()
        log.debug("started %s pid %d: %s", name, child.pid, " ".join(child.argv))
        return child

    def restart(self, child: Child) -> None:
        """Start an exited child again with the same command; its log goes on."""
        if child.poll() is None:
            raise ValueError(f"{child.name} is still running")
        self._spawn(child, "ab")
        assert child.proc is not None
        child.ident = identify(child.proc.pid)
        child.exit_code = None
        child.restarts += 1
        self._write_pids()
        log.info("restarted %s (restart %d) pid %d", child.name, child.restarts, child.pid)

    def _spawn(self, child: Child, mode: str) -> None:
        child.spawned_s = time.monotonic()
        with open(child.log_path, mode) as out:
            child.proc = subprocess.Popen(
                child.argv,
                stdout=out,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                start_new_session=True,
                env={**os.environ, "PYTHONUNBUFFERED": "1", **launcher_env()},
            )

    def _write_pids(self) -> None:
        """PIDs and start times on disk as soon as they exist, so that an outside cleanup
        can find them even if the launcher itself is killed (deploy.procs.pids)."""
        ids = {c.name: c.ident for c in self.children if c.ident is not None}
        if self.zygote is not None:
            ids["zygote"] = self.zygote.ident
        write_pids(self.log_dir, ids)

    def dead(self) -> list[Child]:
        """Children that exited with a non-zero code so far."""
        return [c for c in self.children if c.poll() not in (None, 0)]

    def running(self, names: Sequence[str] | None = None) -> list[Child]:
        pool = self.children if names is None else [c for c in self.children if c.name in names]
        return [c for c in pool if c.poll() is None]

    def wait(self, children: Sequence[Child], timeout_s: float) -> bool:
        """Poll until `children` have exited or the timeout passes; True when all exited."""
        deadline = self.clock() + timeout_s
        while any(c.poll() is None for c in children):
            if self.clock() >= deadline:
                return False
            time.sleep(0.05)
        return True

    def terminate(self, children: Sequence[Child], grace_s: float = 5.0) -> None:
        """SIGTERM, then SIGKILL whoever is still there after `grace_s`."""
        alive = [c for c in children if c.poll() is None]
        for c in alive:
            _signal(c, signal.SIGTERM)
        if not self.wait(alive, grace_s):
            for c in alive:
                if c.poll() is None:
                    log.warning("%s (pid %s) ignored SIGTERM; killing it", c.name, c.pid)
                    _signal(c, signal.SIGKILL)
            self.wait(alive, 2.0)

    def stop_all(self, grace_s: float = 5.0) -> None:
        self.end_forks()
        self.terminate(self.children, grace_s)


def _signal(child: Child, signum: int) -> None:
    """Through the child's own handle, which polls first: a child is ours until we reap
    it, so its PID cannot name another process here (restarts and faults signal the
    same way; a cleanup from outside goes by PID and start time: deploy.procs.pids)."""
    if child.proc is None:
        return
    with contextlib.suppress(ProcessLookupError):
        child.proc.send_signal(signum)
