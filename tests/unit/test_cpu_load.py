"""deploy.report.cpu_load: CPU per process from the real /proc, late ticks, the verdict's lines."""

from __future__ import annotations

import os
import time

import pytest

from deploy.report.cpu_load import (
    CpuSampler,
    load_line,
    machine_ticks,
    memory_line,
    overrun_line,
    overrun_summary,
    process_cpu_s,
    process_status_kb,
)

pytestmark = [pytest.mark.timeout(30), pytest.mark.serial,  # it measures CPU: alone
              pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="Linux /proc")]


def _burn(seconds: float) -> None:
    end = time.process_time() + seconds
    while time.process_time() < end:
        pass


def test_a_busy_process_reads_as_busy_and_a_gone_one_as_nothing() -> None:
    t0 = time.monotonic()
    sampler = CpuSampler(windows_from_s=(t0,))
    pid = os.getpid()
    sampler.sample(t0, {"me": pid, "gone": 2**22 + 12345, "unstarted": None})
    _burn(0.3)
    sampler.sample(time.monotonic(), {"me": pid})
    summary = sampler.summary(t0)
    per = summary["process_cpu_pct"]
    assert isinstance(per, dict) and set(per) == {"me"}
    assert per["me"] > 40.0  # busy-looping, on a loaded 2-core machine at worst shared
    assert summary["cores"] == os.cpu_count()
    assert 0.0 < float(str(summary["machine_busy_pct"])) <= 100.0


def test_a_restart_is_a_new_stretch_not_a_negative_cpu() -> None:
    sampler = CpuSampler(windows_from_s=(0.0, 1.0))
    for t_s, pid, cpu_s in [(0.0, 10, 5.0), (1.0, 10, 5.5), (2.0, 11, 0.0), (3.0, 11, 0.1)]:
        sampler.add_cpu("follower-1", t_s, pid, cpu_s)
    per = sampler.summary(0.0)["process_cpu_pct"]
    assert per == {"follower-1": 30.0}  # (0.5 + 0.1) s of CPU over 2 s sampled in one pid
    assert sampler.summary(1.0)["process_cpu_pct"] == {"follower-1": 10.0}  # from 1 s on
    with pytest.raises(ValueError, match="no CPU window"):
        sampler.summary(0.5)


def test_readers_of_proc() -> None:
    cpu = process_cpu_s(os.getpid())
    assert cpu is not None and cpu > 0.0
    ticks = machine_ticks()
    assert ticks is not None and 0 <= ticks[0] <= ticks[1]
    rss = process_status_kb(os.getpid(), "VmRSS")
    hwm = process_status_kb(os.getpid(), "VmHWM")
    assert rss is not None and hwm is not None and 0 < rss <= hwm
    assert process_status_kb(os.getpid(), "NoSuchField") is None
    assert process_status_kb(2**22 + 12345, "VmRSS") is None


def test_late_ticks_from_status_counters() -> None:
    status = {
        "follower-0": {"state": "done", "overruns": 2, "ticks": 1000},
        "follower-1": {"state": "done", "overruns": 30, "ticks": 1000},
        "follower-2": {"state": "done", "overruns": 1},  # an older follower: no tick count
        "sim-0": {"overruns": 500, "ticks": 1000},  # not a follower's control loop
        "recorder-0": "garbage",
    }
    summary = overrun_summary(status)
    assert summary == {"overruns": 32, "ticks": 2000, "overrun_pct": 1.6,
                       "worst": "follower-1", "worst_pct": 3.0,
                       "sim_overruns": 500, "sim_ticks": 1000, "sim_overrun_pct": 50.0}
    line = overrun_line(summary)
    assert line is not None and "1.60 %" in line and "follower-1" in line
    assert "simulator 50.00 % (500 of 1000)" in line
    # A simulator without a tick count (an older one, or none): the followers' line alone.
    del status["sim-0"]["ticks"]  # type: ignore[attr-defined]
    line = overrun_line(overrun_summary(status))
    assert line is not None and "simulator" not in line
    assert overrun_summary({}) == {} and overrun_line({}) is None


def test_load_line_names_followers_and_the_machine() -> None:
    line = load_line({"process_cpu_pct": {"follower-0": 4.0, "follower-1": 6.0, "sim": 12.0,
                                          "target-0": 3.0, "target-1": 5.0},
                      "machine_busy_pct": 71.0, "load_1min": 3.2, "cores": 2})
    assert line is not None
    assert "followers 5.0 % of a core each (max 6.0 follower-1)" in line
    assert "sim 12 %" in line and "targets 4 % each" in line
    assert "machine 71 % busy (2 cores, load 3.2)" in line and "saturated" not in line
    assert load_line({}) is None
    full = load_line({"process_cpu_pct": {"follower-0": 4.0}, "machine_busy_pct": 99.5,
                      "cores": 2})
    assert full is not None and "machine 100 % busy (2 cores): saturated" in full


def test_enclose_profile_dir_leaves_a_cpu_profile_per_process(
    tmp_path: object, monkeypatch: pytest.MonkeyPatch
) -> None:
    import argparse
    import pstats
    from pathlib import Path

    from agents.shell.process import profiled

    folder = Path(str(tmp_path)) / "prof"

    def work(args: argparse.Namespace) -> int:
        _burn(0.05)
        return int(args.code)

    assert profiled(work, argparse.Namespace(code=0), "follower-7") == 0
    assert not folder.exists()  # off unless asked for
    monkeypatch.setenv("ENCLOSE_PROFILE_DIR", str(folder))
    assert profiled(work, argparse.Namespace(code=3), "follower-7") == 3
    stats = pstats.Stats(str(folder / "follower-7.prof"))
    assert any(name == "work" for (_, _, name) in stats.stats)  # type: ignore[attr-defined]
    assert stats.total_tt >= 0.04  # type: ignore[attr-defined]  # CPU of the busy loop
    monkeypatch.setenv("ENCLOSE_PROFILE_ONLY", "sim, follower-2")
    assert profiled(work, argparse.Namespace(code=0), "follower-1") == 0
    assert profiled(work, argparse.Namespace(code=0), "follower-2") == 0
    assert sorted(p.name for p in folder.iterdir()) == ["follower-2.prof", "follower-7.prof"]


def test_peak_memory_is_the_kernels_high_water_mark_kept_over_restarts() -> None:
    sampler = CpuSampler()
    pid = os.getpid()
    ballast = bytearray(64 * 1024 * 1024)  # touched: resident
    ballast[::4096] = b"\x01" * len(ballast[::4096])
    sampler.sample(time.monotonic(), {"follower-0": pid, "gone": 2**22 + 12345})
    del ballast
    sampler.sample(time.monotonic(), {"follower-0": pid})
    peak = sampler.summary(0.0)["process_peak_rss_mb"]
    assert isinstance(peak, dict) and set(peak) == {"follower-0"}
    assert peak["follower-0"] >= 64.0  # the peak stays after the ballast is freed
    earlier = peak["follower-0"] + 1000.0  # an earlier pid of the same name held more
    sampler.peak_rss_mb["follower-0"] = earlier
    sampler.sample(time.monotonic(), {"follower-0": pid})
    assert sampler.peak_rss_mb["follower-0"] == earlier


def test_memory_line_names_the_largest_follower() -> None:
    line = memory_line({"process_peak_rss_mb": {"follower-0": 44.0, "follower-1": 48.5,
                                                "sim": 60.2, "target-0": 54.0,
                                                "target-1": 55.4}})
    assert line == ("followers 46.2 MB each at peak (max 48.5 follower-1); sim 60 MB; "
                    "targets 55 MB at most")
    assert memory_line({}) is None
