"""Where a large ring's angle error lives: its spacing modes over time, and what drives them.

    python bench/bench_spacing_modes.py RUN_DIR [RUN_DIR ...] [--window 10] [--modes 3]

For each run directory (networked or lock-step: both write series.csv) it prints, per
time window, the largest |e_delta| and its RMS over the followers, and the amplitude of
the first Fourier modes of e_delta around the ring at the window's start (mode k: the
error pattern that repeats k times around the ring).  On a directed ring of n followers
mode k decays at g (1 - cos(2 pi k / n)) per second (g: the spacing law's gain in its rate
cap), so mode 1 of a 64-ring is the slow one.

For a networked run (with recording.mcap) it also prints, per follower and window, the
mean error of the velocity feed-forward dr_i against the targets' true mean velocity:
the forcing that keeps mode 1 from decaying when it differs between the followers that
observe different targets.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from deploy.recording.resume import read_messages
from deploy.report.rundir import SERIES_FILE, read_info, series_columns
from transport.messages import FollowerState, TruthSnapshot

FloatArray = NDArray[np.float64]


def read_deltas(run_dir: Path) -> tuple[FloatArray, FloatArray]:
    """(t_s, e_delta per follower) from series.csv: the true included-angle errors the
    angle metric judges (`e<i>_e_delta`, deploy.report.rundir.series_columns), not the ones each
    follower saw against its estimate (`delta<i>_delta`)."""
    info = read_info(run_dir)
    data = np.loadtxt(run_dir / SERIES_FILE, delimiter=",", skiprows=1, ndmin=2)
    names = series_columns(info.n, info.m)
    cols = [k for k, name in enumerate(names) if name.endswith("_e_delta")]
    return data[:, 0], data[:, cols]


def mode_table(t_s: FloatArray, delta: FloatArray, window_s: float, modes: int) -> None:
    print(f"{'window':>11}  {'max':>7}  {'rms':>7}  " +
          "  ".join(f"{'k=' + str(k):>7}" for k in range(1, modes + 1)))
    for lo in np.arange(0.0, float(t_s[-1]), window_s):
        inside = (t_s >= lo) & (t_s < lo + window_s)
        if not inside.any():
            continue
        block = delta[inside]
        amps = np.abs(np.fft.rfft(block[0])) * 2.0 / block.shape[1]
        print(f"{lo:5.0f}-{lo + window_s:<5.0f}  {np.abs(block).max():7.4f}  "
              f"{np.sqrt((block ** 2).mean()):7.4f}  " +
              "  ".join(f"{a:7.4f}" for a in amps[1:modes + 1]))


def feed_forward_bias(run_dir: Path, followers: list[int], window_s: float) -> None:
    """Mean dr_i - (targets' true mean velocity) per window, mm/s."""
    start = json.loads((run_dir / "metrics.json").read_text())["start_stamp_s"]
    truth: list[tuple[float, float, float]] = []
    dr: dict[int, list[tuple[float, float, float]]] = {i: [] for i in followers}
    for _key, msg, _recv_s in read_messages(run_dir / "recording.mcap", Counter()):
        if isinstance(msg, TruthSnapshot) and msg.header.stamp_s > start:
            v = np.mean(np.asarray(msg.target_vel_m_s), axis=0)
            truth.append((msg.header.stamp_s - start, float(v[0]), float(v[1])))
        elif isinstance(msg, FollowerState) and msg.index in dr and msg.header.stamp_s > start:
            dr[msg.index].append((msg.header.stamp_s - start, *msg.dr_m_s))
    tv = np.array(truth)
    for i, samples in dr.items():
        s = np.array(samples)
        err = s[:, 1:] - np.stack([np.interp(s[:, 0], tv[:, 0], tv[:, c]) for c in (1, 2)], 1)
        cells = []
        for lo in np.arange(0.0, float(s[-1, 0]), window_s):
            inside = (s[:, 0] >= lo) & (s[:, 0] < lo + window_s)
            if inside.any():
                mean = 1000.0 * err[inside].mean(axis=0)
                cells.append(f"{lo:.0f}s ({mean[0]:+.1f},{mean[1]:+.1f})")
        print(f"  follower {i}: dr - V_LAP mean mm/s  " + "  ".join(cells))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path, metavar="RUN_DIR")
    parser.add_argument("--window", type=float, default=10.0, help="seconds per row")
    parser.add_argument("--modes", type=int, default=3, help="ring modes to print")
    parser.add_argument("--followers", default="0,40",
                        help="0-based followers whose feed-forward bias to print")
    args = parser.parse_args()
    for run in args.runs:
        print(f"# {run}")
        t_s, delta = read_deltas(run)
        mode_table(t_s, delta, args.window, args.modes)
        if (run / "recording.mcap").exists():
            picked = [int(x) for x in args.followers.split(",") if x]
            feed_forward_bias(run, picked, 2.0 * args.window)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
