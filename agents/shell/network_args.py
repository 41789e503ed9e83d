"""Command-line overrides of the `[network]` table, for `enclose run` and its children:
the flags, their typed `NetworkOptions`, and how they change a scenario."""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass, field

from agents.scenario.checks import check_estimator_order
from agents.scenario.model import ESTIMATORS, Scenario
from agents.scenario.net_faults import parse_net_fault_flag
from agents.scenario.network import IMPAIRMENT_KEYS, impairment
from agents.shell.weather_args import (
    WeatherOptions,
    add_weather_arguments,
    apply_weather_arguments,
    weather_overrides,
)
from errors import ScenarioError
from transport.network_schema import AGENT_SCHEDS, LINK_PROTOCOLS, LOSS_MODELS, ZENOH_RUNTIMES

FLAGS = {key: "--" + key.replace("_", "-") for key in IMPAIRMENT_KEYS}


def add_network_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("network (overrides the scenario's [network] table)")
    g.add_argument("--estimator", choices=ESTIMATORS, default=None,
                   help="robust (default) | paper (the paper's law: estimator order 1)")
    g.add_argument("--estimator-order", type=int, choices=(1, 2), default=None,
                   help="1: the paper's estimator; 2: with the velocity stage (robust only; "
                        "the scenario's [gains] estimator_order by default)")
    g.add_argument("--link", choices=LINK_PROTOCOLS, default=None, help="Zenoh link protocol")
    g.add_argument("--zenoh-runtime", choices=ZENOH_RUNTIMES, default=None,
                   help="split (default): Zenoh's own threads per process; one_thread: all on "
                        "one (less CPU per message, a little more latency: large swarms)")
    g.add_argument("--agent-sched", choices=AGENT_SCHEDS, default=None,
                   help="normal (default) | batch: followers, targets and the recorder do not "
                        "preempt the simulator when they wake (a machine they oversubscribe)")
    g.add_argument("--delay-ms", type=float, default=None, help="added one-way delay per message")
    g.add_argument("--jitter-ms", type=float, default=None, help="std of the added delay")
    g.add_argument("--loss", type=float, default=None, help="fraction of messages lost")
    g.add_argument("--loss-model", choices=LOSS_MODELS, default=None)
    g.add_argument(
        "--burst-len", type=float, default=None, help="mean loss burst (gilbert_elliott)"
    )
    g.add_argument("--duplicate", type=float, default=None, help="probability of a duplicate")
    g.add_argument("--reorder", type=float, default=None, help="probability of a reordering")
    g.add_argument("--impair-seed", type=int, default=None, help="seed of the impairment")
    g.add_argument("--net-fault", action="append", default=None, metavar="SPEC",
                   help="a network fault on the run's timeline, e.g. 40:partition:1,2|3,4:15 "
                        "(agents.scenario.net_faults; `enclose run --fault` takes it too)")
    g.add_argument("--os-cut", default=None, metavar="K,K",
                   help="the network faults (0-based, in time order) cut by the OS between "
                        "hosts (deploy.hosts.host_cut): not cut again at the receivers")
    g.add_argument("--latency-stamps", action="store_true", default=None,
                   help="stamp every sample's arrival: one-way latency per link in the "
                        "followers' status (lat_p50_us_f<j>; bench/bench_latency.py)")
    # The weather's flags travel with the network's: to every process and sweep cell.
    add_weather_arguments(parser)


@dataclass(frozen=True)
class NetworkOptions:
    """The network flags given on a command line (None: the scenario's own setting)."""

    estimator: str | None = None
    estimator_order: int | None = None
    link: str | None = None
    zenoh_runtime: str | None = None
    agent_sched: str | None = None
    impairment: tuple[tuple[str, float | str], ...] = ()  # (IMPAIRMENT_KEYS name, value)
    impair_seed: int | None = None
    latency_stamps: bool = False
    net_faults: tuple[str, ...] = ()  # --net-fault texts
    os_cut: tuple[int, ...] = ()  # --os-cut: faults the OS cuts (their numbers)
    weather: WeatherOptions = field(default_factory=WeatherOptions)  # --wind, --gust, ...


    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> NetworkOptions:
        given = tuple((k, getattr(args, k)) for k in IMPAIRMENT_KEYS
                      if getattr(args, k, None) is not None)
        return cls(**{k: getattr(args, k, None) for k in _CHOICES}, impairment=given,
                   impair_seed=getattr(args, "impair_seed", None),
                   latency_stamps=bool(getattr(args, "latency_stamps", None)),
                   net_faults=tuple(getattr(args, "net_fault", None) or ()),
                   os_cut=_numbers(getattr(args, "os_cut", None)),
                   weather=WeatherOptions.from_namespace(args))


def _numbers(text: str | None) -> tuple[int, ...]:
    if not text:
        return ()
    try:
        return tuple(sorted({int(k) for k in text.split(",")}))
    except ValueError:
        raise ScenarioError("--os-cut", f"{text!r} is not a list of fault numbers") from None


_CHOICES = ("estimator", "estimator_order", "link", "zenoh_runtime", "agent_sched")


def network_overrides(opts: NetworkOptions) -> list[str]:
    """The flags given, as argv for a child process."""
    values = [(k, getattr(opts, k)) for k in _CHOICES]
    values += [*opts.impairment, ("impair_seed", opts.impair_seed)]
    argv: list[str] = []
    for dest, value in values:
        if value is not None:
            argv += ["--" + dest.replace("_", "-"), str(value)]
    for text in opts.net_faults:
        argv += ["--net-fault", text]
    if opts.os_cut:
        argv += ["--os-cut", ",".join(str(k) for k in opts.os_cut)]
    argv += weather_overrides(opts.weather)
    return argv + (["--latency-stamps"] if opts.latency_stamps else [])


def apply_network_arguments(scenario: Scenario, opts: NetworkOptions) -> Scenario:
    """`scenario` with the flags applied to its network (and to every per-link override)."""
    scenario = apply_weather_arguments(scenario, opts.weather)
    given = dict(opts.impairment)
    net = scenario.network
    if given:
        default = impairment(given, "command line", net.default)
        links = tuple((s, d, impairment(given, "command line", spec)) for s, d, spec in net.links)
        net = dataclasses.replace(net, default=default, links=links)
    for dest in ("estimator", "link", "zenoh_runtime", "agent_sched"):
        if getattr(opts, dest) is not None:
            net = dataclasses.replace(net, **{dest: getattr(opts, dest)})
    if opts.impair_seed is not None:
        net = dataclasses.replace(net, seed=opts.impair_seed)
    if opts.net_faults:
        # Their windows are checked against the run's length by the command that knows it
        # (deploy.commands.run: --duration may differ from the scenario's).
        added = [parse_net_fault_flag(t, scenario.n, "--net-fault") for t in opts.net_faults]
        net = dataclasses.replace(
            net, faults=tuple(sorted((*net.faults, *added), key=lambda f: f.at_s)))
    if opts.os_cut:
        if max(opts.os_cut) >= len(net.faults) or min(opts.os_cut) < 0:
            raise ScenarioError("--os-cut", f"fault numbers must be in 0..{len(net.faults) - 1}"
                                f", got {list(opts.os_cut)}")
        net = dataclasses.replace(net, os_cut=opts.os_cut)
    # The velocity stage is the robust estimator's: `--estimator paper` is order 1.
    order = opts.estimator_order
    if order is None:
        order = 1 if net.estimator == "paper" else scenario.gains.estimator_order
    gains = dataclasses.replace(scenario.gains, estimator_order=order)
    scenario = dataclasses.replace(scenario, network=net, gains=gains)
    check_estimator_order(scenario, "--estimator-order")
    return scenario
