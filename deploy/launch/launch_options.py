"""What a launcher (`enclose run`, `enclose host`) was asked on its command line, typed.

Read once from the parsed flags by the command (deploy.commands.run, deploy.commands.host);
`deploy.launch.launcher.Launch` and the runs in namespaces (deploy.netns) take it from there.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field, replace
from pathlib import Path

from agents.scenario.faults import is_net_action
from agents.shell.law_args import LawOptions
from agents.shell.network_args import NetworkOptions
from deploy.launch.live_args import LiveOptions


@dataclass(frozen=True)
class LaunchOptions:
    scenario: str | None = None  # shipped name or TOML path; None: the paper's case
    zenoh_config: str | None = None  # the user's Zenoh config file
    noise_std_m: float = 0.0  # on target observations
    link_timeout_s: float = 120.0
    insecure: bool = False  # no mTLS/ACL, no MAVLink signing
    json: bool = False  # metrics and verdict as JSON on stdout
    restart: str = "on-failure"  # deploy.procs.restarts.RESTART_POLICIES
    max_restarts: int = 5
    faults: tuple[str, ...] = ()  # --fault AT_S:ACTION:TARGET[:DURATION_S]
    network: NetworkOptions = field(default_factory=NetworkOptions)
    law: LawOptions = field(default_factory=LawOptions)  # --law, --law-param
    live: LiveOptions | None = None  # None: no live view
    port_range: str | None = None  # LO-HI
    credentials_dir: str | None = None  # a host's copy of `enclose keys` (enclose host)
    verbose: int = 0
    # Every follower journals its law's inputs (enclose replay); None: as the scenario says.
    journal: bool | None = None
    figures: bool = True  # the recorder draws the run's figures at the end

    @classmethod
    def from_namespace(cls, args: argparse.Namespace, scenario: str | None,
                       live: LiveOptions | None, network: NetworkOptions,
                       port_range: str | None = None,
                       credentials_dir: str | None = None) -> LaunchOptions:
        """The flags both launchers share, from `args`; the others as the command says."""
        # A network fault reaches every process as the network flag --net-fault.
        net_faults = tuple(f for f in args.fault if is_net_action(f))
        network = replace(network, net_faults=network.net_faults + net_faults)
        return cls(
            scenario=scenario, zenoh_config=args.zenoh_config, noise_std_m=args.noise_std_m,
            link_timeout_s=args.link_timeout, insecure=args.insecure, json=args.json,
            restart=args.restart, max_restarts=args.max_restarts,
            faults=tuple(f for f in args.fault if not is_net_action(f)),
            network=network, law=LawOptions.from_namespace(args), live=live,
            port_range=port_range,
            credentials_dir=credentials_dir, verbose=int(getattr(args, "verbose", 0)),
            journal=getattr(args, "journal", None),
            figures=not getattr(args, "no_figures", False),
        )

    def scenario_ref(self) -> str:
        """The scenario as a child process is told it: a shipped name, or an absolute path."""
        scen = self.scenario
        if scen and scen.endswith(".toml"):
            return str(Path(scen).resolve())
        return scen or "paper"

    def supervision_argv(self) -> list[str]:
        """The flags a launcher started inside a namespace is given again."""
        argv = ["--noise-std-m", repr(self.noise_std_m), "--link-timeout",
                repr(self.link_timeout_s), "--restart", self.restart,
                "--max-restarts", str(self.max_restarts)]
        for fault in self.faults:
            argv += ["--fault", fault]
        if self.journal is not None:
            argv.append("--journal" if self.journal else "--no-journal")
        if not self.figures:
            argv.append("--no-figures")
        return argv + (["--insecure"] if self.insecure else [])


def add_figures_argument(p: argparse.ArgumentParser) -> None:
    """--no-figures, for every command that records a run."""
    p.add_argument("--no-figures", action="store_true",
                   help="write the metrics, series and recording but draw no figures (~1.3 s "
                   "of CPU less, the end ~2 s sooner; `enclose report RUN` draws them later)")


def add_journal_argument(p: argparse.ArgumentParser) -> None:
    """--journal / --no-journal, for every command that launches followers."""
    p.add_argument(
        "--journal", action=argparse.BooleanOptionalAction, default=None,
        help="every follower journals its law's inputs into RUN/journal (enclose replay; "
        "default: the scenario's [run] journal, on unless it says false)")
