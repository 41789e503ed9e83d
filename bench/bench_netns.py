"""Real loss in a network namespace: Zenoh TCP vs UDP links (issue: network realism, item 2).

For each link protocol and OS loss P, runs `enclose run SCENARIO --netns --os-loss P
--link L` (root: a fresh namespace whose loopback input drops P of the packets, MAVLink
exempt) and prints one table row:
  exit code, seconds to link, the loss the kernel really applied (nft counters),
  metrics (estimator, radius, angle errors over the steady part, command jump),
  what the followers saw of their neighbours: share of the neighbours' states received
  once a link formed (sum of rx_f<j> / sum of seq_last_f<j> - seq_first_f<j> + 1),
  neighbour links that delivered nothing at all though the neighbour published,
  neighbour-state age at use (p50 and p99, worst follower), worst
  per-link p99 age, and decoder sequence gaps.
Add --rescan to print the table again from the run directories, without running.

Run (as root): python bench/bench_netns.py [--duration 60] [--losses 0 0.05 0.1]
                                           [--links tcp udp] [--out runs/bench-netns]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from agents.loading.scenario_file import load_scenario
from agents.scenario.model import Scenario
from deploy.json_files import read_json as read_json_or_none
from deploy.netns.namespace import probe

METRICS = ("estimator_error_m", "radius_error_m", "angle_error", "command_jump_m_s")
COLUMNS = ("link", "os_loss", "exit", "link_s", "kernel_loss", *METRICS, "nbr_rx_share",
           "dead_links", "age_p50_ms", "age_p99_ms", "link_age_p99_ms", "seq_gap")


def read_json(path: Path) -> dict[str, Any]:
    return read_json_or_none(path) or {}


def neighbour_view(status: dict[str, dict[str, int]], scenario: Scenario) -> dict[str, Any]:
    """What the followers saw of each other, from their final status counters: the share of
    a neighbour's states received once its link formed, links that delivered nothing, ages."""
    rx = span = sent = dead = 0
    link_p99: list[int] = []
    followers = {i: status.get(f"follower-{i}", {}) for i in range(scenario.n)}
    for i, f in followers.items():
        for j in scenario.neighbours(i):
            sent += followers[j].get("states_sent", 0)
            if f.get(f"rx_f{j}", 0) == 0:
                dead += 1
                continue
            rx += f[f"rx_f{j}"]  # states sent before the link formed are not loss: seq span
            span += f[f"seq_last_f{j}"] - f[f"seq_first_f{j}"] + 1
            link_p99.append(f.get(f"age_p99_us_f{j}", 0))

    def worst_ms(key: str) -> float | None:
        values = [f[key] for f in followers.values() if key in f]
        return max(values) / 1000.0 if values else None

    return {
        "nbr_rx_share": rx / span if span else None,
        "dead_links": dead if sent else None,
        "age_p50_ms": worst_ms("nbr_age_p50_us"),
        "age_p99_ms": worst_ms("nbr_age_p99_us"),
        "link_age_p99_ms": max(link_p99) / 1000.0 if link_p99 else None,
        "seq_gap": sum(f.get("seq_gap", 0) for f in followers.values()) if sent else None,
    }


def run_case(args: argparse.Namespace, out: Path, link: str, loss: float) -> None:
    argv = [sys.executable, "-m", "deploy.cli", "run", args.scenario, "--netns",
            "--os-loss", str(loss), "--link", link, "--duration", str(args.duration),
            "--link-timeout", str(args.link_timeout), "--out", str(out)]
    out.mkdir(parents=True, exist_ok=True)
    with open(out.parent / f"{out.name}.log", "w") as log:
        try:
            subprocess.run(argv, stdout=log, stderr=subprocess.STDOUT, check=False,
                           timeout=args.duration + args.link_timeout + 240)
        except subprocess.TimeoutExpired:  # run() killed it; the namespace goes at next start
            log.write("bench_netns: run timed out and was killed\n")


def collect(out: Path, link: str, loss: float, scenario: Scenario) -> dict[str, Any]:
    launch, metrics = read_json(out / "launch.json"), read_json(out / "metrics.json")
    netns = read_json(out / "netns.json")
    row: dict[str, Any] = {"link": link, "os_loss": loss, "exit": netns.get("exit_code"),
                           "link_s": launch.get("link_s"),
                           "kernel_loss": netns.get("measured_loss")}
    linked = "link_s" in launch
    row.update({k: metrics.get(k) if linked else None for k in METRICS})
    row.update(neighbour_view(launch.get("status", {}), scenario))
    return row


def cell(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.3g}"
    return str(value)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--scenario", default="paper")
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--losses", type=float, nargs="+", default=[0.0, 0.05, 0.1])
    parser.add_argument("--links", nargs="+", default=["tcp", "udp"], choices=["tcp", "udp"])
    parser.add_argument("--link-timeout", type=float, default=60.0)
    parser.add_argument("--out", type=Path, default=Path("runs/bench-netns"))
    parser.add_argument("--rescan", action="store_true", help="only print the earlier runs")
    args = parser.parse_args()
    scenario = load_scenario(args.scenario)
    reason = None if args.rescan else probe()
    if reason is not None:
        sys.exit(f"bench_netns: cannot make a network namespace here: {reason}")
    rows = []
    print("| " + " | ".join(COLUMNS) + " |\n|" + "---|" * len(COLUMNS), flush=True)
    for link in args.links:
        for loss in args.losses:
            out = (args.out / f"{link}-loss{loss:g}").resolve()
            if not args.rescan:
                run_case(args, out, link, loss)
            row = collect(out, link, loss, scenario)
            rows.append(row)
            print("| " + " | ".join(cell(row.get(c)) for c in COLUMNS) + " |", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "results.json").write_text(json.dumps(rows, indent=2) + "\n")
    print(f"\n{args.scenario}, {args.duration:g} s per run; rows in {args.out / 'results.json'}")


if __name__ == "__main__":
    main()
