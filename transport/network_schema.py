"""The network half of a scenario: what the transport layer needs to know of it.

Zenoh link protocol and runtime, scheduling class of the agents, and the seeded
impairment of each follower link.  The scenario (`agents.scenario.model.Scenario.network`)
holds one `NetworkConfig`, read by `agents.scenario.network`; it lives here so that
transport (impairment, Zenoh config) never imports agents.
"""

from __future__ import annotations

from dataclasses import dataclass, field

LINK_PROTOCOLS = ("tcp", "udp")
# How each process runs Zenoh (transport.zenoh_config.RUNTIME_SETTINGS): "split" (the
# default), its own threads for receiving, sending and the rest; "one_thread", all of it on
# one (~45 us less CPU per follower tick, but a consumer that stops reading then stalls
# every link of a publisher that waits on it: docs/large-swarms.md).
ZENOH_RUNTIMES = ("split", "one_thread")
AGENT_SCHEDS = ("normal", "batch")
# `[network] zenoh_lease_s` bounds, seconds: a lease under a second expires links on any
# scheduling hiccup; over ten minutes, a frozen process would never leave.
ZENOH_LEASE_RANGE_S = (1.0, 600.0)
AGENT_NICE_MAX = 19  # the largest nice value Linux has
LOSS_MODELS = ("independent", "gilbert_elliott")


@dataclass(frozen=True)
class LinkImpairment:
    """What one directed link does to each message: seeded, applied at the receiver."""

    delay_ms: float = 0.0
    jitter_ms: float = 0.0  # std of a zero-mean normal added to the delay (clipped at 0)
    loss: float = 0.0  # long-run fraction of messages lost
    loss_model: str = "independent"  # or gilbert_elliott: bursts, mean length burst_len
    burst_len: float = 1.0  # mean number of messages lost in a row (gilbert_elliott)
    duplicate: float = 0.0  # probability a delivered message arrives twice
    reorder: float = 0.0  # probability a message is held back behind the next one

    @property
    def is_identity(self) -> bool:
        return self == LinkImpairment()


NET_FAULT_ACTIONS = ("partition", "isolate", "degrade")


@dataclass(frozen=True)
class NetFault:
    """A change of the follower links for a window of experiment time (transport.net_timeline).

    partition: a link between followers of different `groups` is cut (followers named
    in no group form one more group); isolate: `groups` is the one follower cut off from
    every other; degrade: the links in `links` (all follower links when empty) follow
    `impairment` instead of their own.  The simulator's sensor link is never cut: what a
    vehicle observes of the targets is its own sensing, not the network's."""

    action: str
    at_s: float
    duration_s: float
    groups: tuple[frozenset[int], ...] = ()  # 0-based followers
    links: tuple[tuple[int, int], ...] = ()  # degrade: (from, to) 0-based; () all
    impairment: LinkImpairment = field(default_factory=LinkImpairment)

    @property
    def end_s(self) -> float:
        return self.at_s + self.duration_s

    def label(self) -> str:
        """How figures and the verdict name it, with the file's 1-based numbers."""
        if self.action == "degrade":
            what = "all" if not self.links else ",".join(f"{a + 1}>{b + 1}" for a, b in self.links)
        else:
            what = "|".join(",".join(str(k + 1) for k in sorted(g)) for g in self.groups)
        return f"{self.action} {what} {self.at_s:g}-{self.end_s:g} s"


@dataclass(frozen=True)
class NetworkConfig:
    """Estimator variant, Zenoh link protocol and runtime, impairment of the follower links."""

    # The link-sum estimator survives pauses, loss and delay with no lasting offset;
    # "paper" (the paper's integrated Phi) stays selectable to reproduce the paper.
    estimator: str = "robust"
    link: str = "tcp"
    default: LinkImpairment = field(default_factory=LinkImpairment)
    links: tuple[tuple[int, int, LinkImpairment], ...] = ()  # (from, to) 0-based overrides
    seed: int = 0
    zenoh_runtime: str = "split"
    # Every process's Zenoh lease, seconds (transport.zenoh_config.LEASE_KEY); None: Zenoh's
    # 10 s.  Longer: fewer keep-alives over a large mesh, and a frozen process stays a
    # member that much longer (docs/faults.md).
    zenoh_lease_s: float | None = None
    # "batch": followers, targets and the recorder run SCHED_BATCH (agents.shell.process
    # apply_agent_sched): their wake-ups no longer preempt the simulator, which stands for
    # the physical world, on a machine they oversubscribe (ring64 on 2 cores).
    agent_sched: str = "normal"
    # The vehicles' agents' scheduling weight below the simulator's and the recorder's
    # (agents.shell.process.yield_cpu): the nice of followers' and targets' own autogroups.  0:
    # the kernel's fair share per process, which on a machine the agents oversubscribe
    # leaves the simulator (the physical world) late.
    agent_nice: int = 0
    faults: tuple[NetFault, ...] = ()  # partitions, isolations, degradations on a timeline
    # Numbers of the faults the OS cuts between hosts (`--os-cut`, deploy.hosts.host_cut): the
    # receivers leave them alone.
    os_cut: tuple[int, ...] = ()

    def impairment(self, sender: int, receiver: int) -> LinkImpairment:
        for src, dst, spec in self.links:
            if (src, dst) == (sender, receiver):
                return spec
        return self.default
