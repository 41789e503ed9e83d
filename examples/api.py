"""enclose from Python, as in a notebook: a scenario variation, run lock-step and networked,
compared in one figure from their DataFrames.

    python examples/api.py [--duration 30] [--out runs/api-example]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # a file, not a window: this also runs unattended
import matplotlib.pyplot as plt

import enclose


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=30.0, help="seconds of each run")
    parser.add_argument("--out", type=Path, default=Path("runs/api-example"))
    args = parser.parse_args()

    # The paper's case on a wider circle: a variation checked as a scenario file is.
    wide = enclose.Scenario.load("paper").replace({"pattern.rho_d_m": 10.0}, name="paper_wide")

    lockstep = enclose.simulate(wide, duration_s=args.duration, dt_s=0.002,
                                out=args.out / "lockstep")
    networked = enclose.run(wide, duration_s=args.duration, out=args.out / "networked")
    print(lockstep)
    print(networked)

    # The radius error of follower 1 in both runs, from the series DataFrames.
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for run in (lockstep, networked):
        run.series["e1_e_rho_m"].abs().plot(ax=ax, logy=True, label=run.kind)
    ax.axhline(wide.model.run.eps_rho_m, color="k", ls="--", label="paper's bound")
    ax.set(xlabel="t (s)", ylabel="|e_rho| follower 1 (m)")
    ax.legend()
    figure = args.out / "radius_error.png"
    fig.savefig(figure, dpi=120, bbox_inches="tight")
    print(f"figure: {figure}")


if __name__ == "__main__":
    main()
