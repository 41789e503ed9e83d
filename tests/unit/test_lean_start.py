"""Issue 15 (fast start, lean processes): what stays out of a follower, forked children,
start-up phase stamps, and one-way latency from stamped arrivals."""

from __future__ import annotations

import contextlib
import os
import platform
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from agents.shell import phases
from deploy.procs.forked import call_forked, fork_main
from errors import DeployError
from transport.bus import Received
from transport.codec import encode
from transport.key_exprs import SwarmKeys
from transport.link_stats import LinkDecoder
from transport.messages import FollowerState, Header, RunControl

K = SwarmKeys("lean")
# Heavy packages a follower (or `enclose run` before its swarm starts) never needs.
NOT_IN_A_FOLLOWER = ("cryptography", "matplotlib", "mcap", "numba", "scipy", "pandas")
# Modules a follower does without (issue 50: <= 40 MB per follower): OpenSSL's hashes
# (hashlib, hmac: 3.6 MB of RSS), fastcrc (0.5 MB), random (0.2 MB), fractions with decimal
# (0.5 MB), tempfile (importlib.resources), importlib.metadata (2.6 MB: the journal's header
# names the release, enclose_release.py).
LEAN_NOT_IN_A_FOLLOWER = ("_hashlib", "hashlib", "hmac", "fastcrc", "random", "fractions",
                          "decimal", "tempfile", "importlib.metadata", "zipfile", "email")


def modules_after(code: str) -> set[str]:
    """Every module a fresh interpreter holds after running `code`."""
    out = subprocess.run(
        [sys.executable, "-c", f"{code}\nimport sys; print(' '.join(sys.modules))"],
        capture_output=True, text=True, check=True, timeout=60,
    ).stdout
    return set(out.split())


def imported_by(code: str) -> set[str]:
    return {m.split(".")[0] for m in modules_after(code)}


# What a follower does before its loop, in a fresh interpreter: what it imports then.
FOLLOWER_SET_UP = """
import agents.follower.main
from agents.membership.follower_place import setup_for
from agents.loading.scenario_file import load_scenario
from transport.impairment import ImpairedBus
from transport.memory_bus import MemoryBus, MemoryHub
from transport.key_exprs import SwarmKeys
from transport.link_stats import AgeHistogram
for name in ("paper", "ring16"):
    s = load_scenario(name, whole_run=False)
    for i in range(s.n):
        setup_for(s, i, set(range(s.n)) - {(i + 1) % s.n})
    bus = ImpairedBus(MemoryBus(MemoryHub(), "lean"), s.network, receiver=0)
    bus.impairer(bus.link(SwarmKeys("lean").follower_state(1)))
    ages = AgeHistogram()
    ages.add(0.01)
    assert ages.percentile_s(99) is not None
from agents.mavlink.signing import signature
assert len(signature(b"k" * 32, b"a frame up to its timestamp")) == 6
import os
from pathlib import Path
from agents.follower.journal_file import FrameWriter
journal = Path(f"/tmp/enclose-lean-{os.getpid()}.journal")
try:
    FrameWriter(journal, {"who": "follower-0"}).flush()
finally:
    journal.unlink()
"""


@pytest.mark.realtime
@pytest.mark.timeout(90)
def test_a_follower_and_the_launcher_import_none_of_the_heavy_packages() -> None:
    swarm = imported_by("import agents.follower.main, agents.target, sim_backend.swarm_sim")
    assert "numpy" in swarm and "zenoh" in swarm  # the check can fail
    assert not swarm & set(NOT_IN_A_FOLLOWER)
    # Not even numpy (16.7 MB) in a follower (issue 15: <= 50 MB per follower).
    follower = imported_by(FOLLOWER_SET_UP)
    assert "zenoh" in follower and "agents" in follower
    assert not follower & {"numpy", *NOT_IN_A_FOLLOWER}
    assert not modules_after(FOLLOWER_SET_UP) & set(LEAN_NOT_IN_A_FOLLOWER)
    assert set(LEAN_NOT_IN_A_FOLLOWER) <= modules_after(
        "import hmac, fastcrc, fractions, tempfile, importlib.metadata")
    launcher = imported_by("from deploy.cli import build_parser; build_parser(['run'])")
    assert "deploy" in launcher
    assert not launcher & set(NOT_IN_A_FOLLOWER)


# A follower's or target's MAVLink side at work: a signed vehicle's frames in, setpoints,
# commands, heartbeats and TIMESYNC out.
VEHICLE_SET_UP = """
import socket
from agents.mavlink import lean_common
from agents.mavlink.adapter import AdapterConfig, MavlinkAdapter
from agents.mavlink.offboard import OffboardKeeper
from agents.mavlink.wire import encode, new_codec, sign_outgoing
key = bytes(range(32))
vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
vehicle.bind(("127.0.0.1", 0))
vehicle.settimeout(10.0)
cfg = AdapterConfig(local_port=0, target_sysid=1, signing_key=key)
with MavlinkAdapter(cfg) as ad:
    px4 = new_codec(1, 1, lean_common)
    sign_outgoing(px4, key, 0, ad.verifier.now_ticks())
    frames = [encode(px4, px4.heartbeat_encode(2, 12, 129, 6 << 16, 4)),
              encode(px4, px4.local_position_ned_encode(5, 1.0, 2.0, -3.0, 0.0, 0.0, 0.0))]
    vehicle.sendto(b"".join(frames), ad.sock.getsockname())
    for _ in range(200):
        if ad.poll().link_ok:
            break
        ad.wait_readable(0.01)
    assert ad.flavour == "px4" and ad.state.link_ok and ad.counters["bad_packets"] == 0
    assert ad.send_velocity_enu((1.0, 0.0, 0.0))
    ad.send_command(400, (1.0,))
    OffboardKeeper(ad).check(0.0)
    assert vehicle.recv(1000)
vehicle.close()
"""
TARGET_SET_UP = """
import agents.target
from agents.scenario.target_motion import TargetMotion
from agents.loading.scenario_file import load_scenario
TargetMotion(load_scenario("paper", whole_run=False), horizon_s=10.0).state(1.0)
"""
FULL_DIALECT = "pymavlink.dialects.v20.common"


@pytest.mark.realtime
@pytest.mark.timeout(120)
def test_a_follower_and_a_target_hold_the_lean_mavlink_dialect_not_the_full_one() -> None:
    """pymavlink's common dialect costs ~4.8 MB a process; the agents' lean one ~0.6."""
    for set_up in (FOLLOWER_SET_UP, TARGET_SET_UP):
        modules = modules_after(set_up + VEHICLE_SET_UP)
        assert "agents.mavlink.lean_common" in modules and "agents" in modules
        assert FULL_DIALECT not in modules
    assert FULL_DIALECT in modules_after("import sim_backend.swarm_sim")  # the check can fail


# Compiles a large module from source, as an interpreter without cached bytecode does at
# import, then trims: the compiler's freed memory must leave the resident set.
TRIMMED = """
import os
import agents.mavlink.lean_gen as gen
from deploy.report.cpu_load import process_status_kb
from deploy.procs.forked import trim_heap
code = compile(gen.OUTPUT.read_text(), "lean_common.py", "exec")
before = process_status_kb(os.getpid(), "VmRSS")
trim_heap()
print(before - process_status_kb(os.getpid(), "VmRSS"))
"""


@pytest.mark.realtime
@pytest.mark.timeout(60)
@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="malloc_trim is glibc's")
def test_trimming_the_heap_before_forking_returns_the_compilers_memory() -> None:
    out = subprocess.run([sys.executable, "-c", TRIMMED], capture_output=True, text=True,
                         check=True, timeout=50).stdout
    assert int(out) > 1024  # kB: on this machine ~5 MB of the compiler's 7


def wait_exit(proc: object, timeout_s: float = 20.0) -> int | None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        code = proc.poll()  # type: ignore[attr-defined]
        if code is not None:
            return int(code)
        time.sleep(0.01)
    return None


@pytest.mark.realtime
@pytest.mark.timeout(30)
def test_a_forked_child_runs_main_with_its_own_log_pid_and_exit_code(tmp_path: Path) -> None:
    log = tmp_path / "child.log"
    proc = fork_main("tests.child_proc", ["print", "hello"], log)
    assert proc.pid != os.getpid()
    assert wait_exit(proc) == 0
    assert log.read_text().strip() == "hello"
    failing = fork_main("tests.child_proc", ["exit", "3"], tmp_path / "f.log")
    assert wait_exit(failing) == 3


@pytest.mark.timeout(30)
def test_call_forked_reports_a_failure(tmp_path: Path) -> None:
    call_forked(lambda: (tmp_path / "made").write_text("x") and None, "making")
    assert (tmp_path / "made").read_text() == "x"  # ran, in another process

    def fail() -> None:
        raise ValueError("no")

    with pytest.raises(DeployError, match="making"):
        call_forked(fail, "making")


def test_phase_stamps_round_trip_through_a_log_line(caplog: pytest.LogCaptureFixture) -> None:
    phases.reset()
    phases.mark("main")
    phases.mark("bus_open")
    phases.mark("main")  # the first stamp of a phase wins
    with caplog.at_level("INFO"):
        phases.log_phases("test")
    parsed = [p for p in map(phases.parse_phases, caplog.messages) if p is not None]
    assert len(parsed) == 1
    stamps, cpu_s = parsed[0]
    assert list(stamps)[-2:] == ["main", "bus_open"] and stamps["main"] <= stamps["bus_open"]
    assert stamps.get("exec", 0.0) <= stamps["main"] <= time.monotonic() and cpu_s > 0
    assert phases.parse_phases("start-up phases {not json") is None
    phases.reset()


def rec(seq: int, stamp_s: float, arrival_s: float | None, hlc_s: float | None) -> Received:
    z = (0.0, 0.0)
    payload = encode(FollowerState(Header("follower-0", seq, stamp_s), 0, z, z, z, z, z, 0.0))
    return Received(K.follower_state(0), payload, stamp_s + 0.01, hlc_s, None, arrival_s)


def start(stamp_s: float, seq: int) -> Received:
    word = encode(RunControl(Header("launcher-0", seq, stamp_s), "start", 100.0, 10.0))
    return Received(K.control(), word, stamp_s)


def test_latency_is_arrival_minus_the_senders_put_and_survives_repeated_start_words() -> None:
    d = LinkDecoder()
    d.decode(start(99.0, 0))
    for k in range(100):  # put 0.2 ms after the header stamp, arrived 0.15 ms later
        t = 100.0 + 0.02 * k
        d.decode(rec(k, t, t + 0.00035, t + 0.0002))
        if k % 50 == 49:
            d.decode(start(t, k + 1))  # the launcher's repeats: same start stamp
    c = d.counters()
    assert 140 <= c["lat_p50_us_f0"] <= 160 and 140 <= c["lat_p99_us_f0"] <= 160
    assert c["nbr_lat_n"] == 100 and 140 <= c["nbr_lat_p50_us"] <= 160
    assert 9_900 <= c["age_p50_us_f0"] <= 10_100  # still counted from the first start word


def test_no_latency_without_arrival_stamps() -> None:
    d = LinkDecoder()
    d.decode(rec(0, 100.0, None, 100.0))
    assert not any("lat" in k for k in d.counters())


def test_no_fork_beside_a_thread_python_does_not_know(tmp_path: Path) -> None:
    """Threads Python does not see (Zenoh's runtime, alive after its last Zenoh session): the
    kernel's task list decides."""
    from deploy.procs.forked import only_thread

    (tmp_path / "100").mkdir()
    assert only_thread(tmp_path)
    (tmp_path / "101").mkdir()  # a runtime thread left by a closed Zenoh session
    assert not only_thread(tmp_path)
    assert only_thread(tmp_path / "no-proc-here")  # no /proc: Python's count decides


@pytest.mark.realtime
@pytest.mark.timeout(30)
def test_no_fork_while_a_thread_runs(tmp_path: Path) -> None:
    import threading

    from deploy.procs.forked import ForkedProcess, fork_is_safe
    from deploy.procs.supervisor import Supervisor

    # A fresh process is safe to fork from (this one may hold other tests' threads).
    fresh = subprocess.run(
        [sys.executable, "-c", "from deploy.procs.forked import fork_is_safe; "
         "raise SystemExit(0 if fork_is_safe() else 1)"], timeout=20, check=False)
    assert fresh.returncode == 0
    stop = threading.Event()
    helper = threading.Thread(target=stop.wait)
    helper.start()
    try:
        assert not fork_is_safe()
        sup = Supervisor(tmp_path)
        child = sup.start("c", "tests.child_proc", ["exit", "0"], fork=True)
        assert child.proc is not None and not isinstance(child.proc, ForkedProcess)
        assert sup.wait([child], 20.0) and child.poll() == 0
    finally:
        stop.set()
        helper.join()


@pytest.mark.realtime
@pytest.mark.timeout(60)
def test_the_fork_server_forks_lean_children_that_this_process_waits_for(
        tmp_path: Path) -> None:
    import numpy  # noqa: F401  # this process has it; the server's children must not

    from deploy.procs.supervisor import Supervisor
    from deploy.procs.zygote import Zygote

    sup = Supervisor(tmp_path)
    zygote = sup.zygote = Zygote(["tests.child_proc"], tmp_path / "zygote.log")
    try:
        child = sup.start("c", "tests.child_proc", ["has", "numpy"], fork=True)
        failing = sup.start("f", "tests.child_proc", ["exit", "3"], fork=True)
        waiting = sup.start("w", "tests.child_proc", ["sleep", "30"], fork=True)
        # A child forked here meanwhile must not hold the server's pipes open.
        sleeper = fork_main("tests.child_proc", ["sleep", "30"], tmp_path / "s.log",
                            close_fds=zygote.fds())
    finally:
        sup.end_forks()
    try:
        assert zygote.proc.returncode == 0  # it ended when asked, not killed at the timeout
        stat = Path(f"/proc/{waiting.pid}/stat").read_text()
        assert int(stat.rsplit(")", 1)[1].split()[1]) == os.getpid()  # reparented to us
        assert sup.wait([child, failing], 20.0)  # and so waited for by PID
        assert child.poll() == 0 and failing.poll() == 3
        assert child.log_path.read_text().split() == ["False"]
    finally:
        sup.stop_all(grace_s=5.0)
        sleeper.send_signal(signal.SIGKILL)
        assert wait_exit(sleeper) is not None


# A launcher that starts a fork server, forks a helper that keeps the server's pipes open
# (as the launcher's own children could), and is killed.
KILLED_LAUNCHER = """
import os, sys, time
from pathlib import Path
from deploy.procs.zygote import Zygote
z = Zygote(["tests.child_proc"], Path(sys.argv[1]))
z.fork("tests.child_proc", ["exit", "0"], Path(sys.argv[1] + ".child"))  # it is serving
helper = os.fork()
if helper == 0:  # not the test's output pipe: only the server's
    os.close(1)
    os.close(2)
    time.sleep(30)
    os._exit(0)
print(z.proc.pid, helper, flush=True)
os.kill(os.getpid(), 9)
"""


def zygote_alive(pid: int) -> bool:
    try:
        return "zygote" in Path(f"/proc/{pid}/cmdline").read_text(errors="replace")
    except OSError:
        return False


@pytest.mark.realtime
@pytest.mark.timeout(60)
def test_the_fork_server_dies_with_a_killed_launcher(tmp_path: Path) -> None:
    launcher = subprocess.run([sys.executable, "-c", KILLED_LAUNCHER, str(tmp_path / "z.log")],
                              capture_output=True, text=True, timeout=30, check=False)
    assert launcher.returncode == -signal.SIGKILL
    pid, helper = map(int, launcher.stdout.split())
    try:
        deadline = time.monotonic() + 20.0
        while zygote_alive(pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not zygote_alive(pid)  # not left waiting for the end of its input
    finally:
        for stray in (pid, helper):
            with contextlib.suppress(ProcessLookupError):
                os.kill(stray, signal.SIGKILL)
