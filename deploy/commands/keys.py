"""`enclose keys OUT_DIR`: a swarm's credentials for processes on several hosts.

One folder per host, holding only what that host's processes need, and the CA key in
OUT_DIR/operator/ (deploy.hosts.host_keys).  The hosts are a deployment file's
(`--deployment`), or the split `enclose run --hosts K` makes (h0: launcher, simulator,
recorder, targets; the followers over h1..h<K-1>).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from agents.loading.scenario_file import load_scenario
from deploy.hosts.deployment import Deployment, HostSpec, load_deployment, split_over_hosts
from deploy.hosts.host_keys import OPERATOR, write_swarm_keys
from errors import ConfigError


def register(sub: Any) -> None:
    p = sub.add_parser("keys", help="make a swarm's credentials: one folder per host, the CA "
                       "key apart (for processes on several hosts)")
    p.add_argument("out_dir", type=Path, help="directory to create (0700)")
    p.add_argument("scenario", nargs="?", default=None, help="scenario (default: paper)")
    p.add_argument("--swarm", default=None, help="swarm name on the bus (default: enclose)")
    p.add_argument("--routers", type=int, default=None, metavar="K",
                   help="K hosts h0..h<K-1>, split as `enclose run --hosts K` does, one "
                   "router each (default 1)")
    p.add_argument("--deployment", type=Path, default=None, metavar="TOML",
                   help="the hosts, their processes, the swarm and the scenario of this "
                   "deployment file (deploy/hosts/deployment.py)")
    p.set_defaults(func=_main)


def _deployment(args: argparse.Namespace) -> Deployment:
    if args.deployment is None:
        scenario = load_scenario(args.scenario)
        k = 1 if args.routers is None else max(1, args.routers)
        hosts = tuple(HostSpec(f"h{i}", f"10.77.0.{i + 1}", tuple(procs))
                      for i, procs in enumerate(split_over_hosts(k, scenario.n, scenario.m)))
        return Deployment(args.swarm or "enclose", args.scenario or "paper", hosts)
    dep = load_deployment(args.deployment)
    for flag, given, there in (("--swarm", args.swarm, dep.swarm),
                               ("scenario", args.scenario, dep.scenario),
                               ("--routers", args.routers, len(dep.hosts))):
        if given is not None and given != there:
            raise ConfigError(flag, f"{given!r}, but the deployment file says {there!r}")
    return dep


def _main(args: argparse.Namespace) -> int:
    dep = _deployment(args)
    scenario = load_scenario(dep.scenario)
    dep.check(scenario.n, scenario.m)
    folders = write_swarm_keys(args.out_dir, dep, scenario.n, scenario.m)
    print(f"credentials for swarm {dep.swarm} ({scenario.n} followers, {scenario.m} targets) "
          f"in {args.out_dir}:")
    for host, folder in folders.items():
        procs = next(h.processes for h in dep.hosts if h.name == host)
        print(f"  {folder}/  for host {host} ({', '.join(procs)}): copy it there, pass "
              f"--credentials to `enclose host`")
    print(f"  {args.out_dir / OPERATOR}/  the CA key and every secret: keep it offline, "
          "copy it to no host")
    return 0
