"""`enclose sweep --cluster ADDRESS`: the cells on an existing Dask distributed cluster.

Dask distributed rather than Ray: a cell is one blocking Python call (run `enclose run`,
wait, pack its folder), which is exactly a Dask task; `distributed` is a pure-Python wheel
(~25 MB with dask) that starts a scheduler and workers in about a second, with plain
`dask scheduler` / `dask worker ADDRESS` commands on other machines, while Ray brings a
~200 MB platform (GCS, raylet, dashboard, object store) this does not use.  Dask cannot
interrupt a running task, so a stop travels as a named `distributed.Event` the worker's
runner polls.

Results travel over the wire: each worker runs its cell in a temporary folder on its own
machine and returns the exit code and the folder as a gzipped tar; the client unpacks it
into the sweep folder.  So the workers need no shared filesystem, only the same enclose
installed (`pip install 'enclose[cluster]'`), and the table is written by the client
alone, exactly as for a local sweep (resumable the same way).  A scenario given as a file
is sent with the task.
"""

from __future__ import annotations

import contextlib
import io
import logging
import secrets
import tarfile
import tempfile
import time
import traceback
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from deploy.sweep.cell_runner import CELL_LOG, STOP_GRACE_S, SubprocessRunner
from deploy.sweep.parallel import StopSignals
from errors import DeployError

log = logging.getLogger("enclose.sweep")
CONNECT_TIMEOUT_S = 30.0
POLL_S = 0.5
LOST_EXIT = 1  # the task raised or its worker was lost: the cell counts as failed
INTERRUPTED_EXIT = 130
NOT_SENT = ("credentials",)  # deploy.launch.run_secrets: keys of the finished run


@contextlib.contextmanager
def connect(address: str) -> Iterator[Any]:
    """A client of the scheduler at `address`, with at least one worker."""
    try:
        from distributed import Client
    except ImportError as exc:
        raise DeployError(
            "--cluster needs Dask distributed: pip install 'enclose[cluster]'"
        ) from exc
    try:
        client = Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise DeployError(f"--cluster {address}: cannot reach the scheduler: {exc}") from exc
    try:
        client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        yield client
    except TimeoutError as exc:
        raise DeployError(f"--cluster {address}: no worker joined in 30 s") from exc
    finally:
        client.close()


class ClusterRunner:
    """A CellRunner whose cells run as Dask tasks (`remote_cell`) on the workers."""

    def __init__(self, client: Any, signals: StopSignals) -> None:
        from distributed import Event

        self.client, self.signals = client, signals
        token = secrets.token_hex(4)
        self.stop_name, self.kill_name = (f"enclose-sweep-{token}-{w}" for w in ("stop", "kill"))
        self.stop_event = Event(self.stop_name, client=client)
        self.kill_event = Event(self.kill_name, client=client)

    def capacity(self) -> int:
        """Cells the cluster runs at a time: one per worker thread."""
        return max(1, sum(self.client.nthreads().values()))

    def run_cell(self, argv: Sequence[str], out_dir: Path, timeout_s: float) -> int:
        scenario_text = Path(argv[1]).read_text() if argv[1].endswith(".toml") else None
        future = self.client.submit(
            remote_cell, list(argv), timeout_s, scenario_text, self.stop_name, self.kill_name,
            key=f"enclose-cell-{out_dir.name}-{secrets.token_hex(4)}", pure=False,
        )
        try:
            code, blob = self._result(future, timeout_s + STOP_GRACE_S, stopping=False)
        except KeyboardInterrupt:
            log.warning("interrupted: asking the cluster to stop %s cleanly", out_dir.name)
            self.stop_event.set()
            code, blob = self._result(future, STOP_GRACE_S + 60.0, stopping=True)
            unpack(blob, out_dir)
            raise
        unpack(blob, out_dir)
        return int(code)

    def _result(self, future: Any, limit_s: float, stopping: bool) -> tuple[int, bytes]:
        deadline = time.monotonic() + limit_s
        while not future.done():
            if time.monotonic() > deadline:
                future.cancel()
                return LOST_EXIT, pack_text(CELL_LOG, "no answer from the cluster in time\n")
            time.sleep(POLL_S)
            if not stopping:
                self.signals.tick()
            elif self.signals.kill_now():
                self.kill_event.set()
        try:
            code, blob = future.result()
        except Exception as exc:  # the task raised, or its worker died too often
            text = "".join(traceback.format_exception(exc))
            log.error("cluster task failed: %s", str(exc).splitlines()[0] if str(exc) else exc)
            return LOST_EXIT, pack_text(CELL_LOG, text)
        return int(code), bytes(blob)


def remote_cell(
    argv: list[str], timeout_s: float, scenario_text: str | None, stop_name: str,
    kill_name: str,
) -> tuple[int, bytes]:
    """On a worker: the cell in a temporary folder; (exit code, that folder packed)."""
    from distributed import Event

    stop, kill = Event(stop_name), Event(kill_name)

    def tick() -> None:
        if stop.is_set():
            raise KeyboardInterrupt

    with tempfile.TemporaryDirectory(prefix="enclose-cell-") as tmp:
        out = Path(tmp) / "cell"
        local = localise(argv, out, Path(tmp), scenario_text)
        runner = SubprocessRunner(tick=tick, kill_now=kill.is_set)
        try:
            code = INTERRUPTED_EXIT if stop.is_set() else runner.run_cell(local, out, timeout_s)
        except KeyboardInterrupt:
            code = INTERRUPTED_EXIT
        return code, pack(out)


def localise(argv: list[str], out: Path, tmp: Path, scenario_text: str | None) -> list[str]:
    """The cell's argv for this machine: its --out here, its scenario file sent along."""
    local = list(argv)
    local[local.index("--out") + 1] = str(out)
    if scenario_text is not None:
        scenario = tmp / Path(argv[1]).name
        scenario.write_text(scenario_text)
        local[1] = str(scenario)
    return local


def pack(folder: Path) -> bytes:
    """The cell's folder as a gzipped tar, without its run's private keys: the run is over,
    and they would cross the network in clear."""
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tar:
        if folder.is_dir():
            for path in sorted(folder.iterdir()):
                if path.name not in NOT_SENT:
                    tar.add(path, arcname=path.name)
    return buf.getvalue()


def pack_text(name: str, text: str) -> bytes:
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / name).write_text(text)
        return pack(Path(tmp))


def unpack(blob: bytes, folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    with tarfile.open(fileobj=io.BytesIO(blob), mode="r:gz") as tar:
        tar.extractall(folder, filter="data")
