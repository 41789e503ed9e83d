"""The network half of a scenario: what the transport layer needs to know of it.

Zenoh link protocol and runtime, scheduling class of the agents, and the seeded
impairment of each follower link.  The scenario (`agents.scenario.model.Scenario.network`)
holds one `NetworkConfig`, read by `agents.scenario.network`; it lives here so that
transport (impairment, Zenoh config) never imports agents.
"""

from __future__ import annotations

from dataclasses import dataclass, field

LINK_PROTOCOLS = ("tcp", "udp")
# How each process runs Zenoh (transport.zenoh_config.RUNTIME_SETTINGS): "split", its own
# threads for receiving, sending and the rest; "one_thread", all of it on one.
ZENOH_RUNTIMES = ("split", "one_thread")
AGENT_SCHEDS = ("normal", "batch")
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
    # "batch": followers, targets and the recorder run SCHED_BATCH (agents.process
    # apply_agent_sched): their wake-ups no longer preempt the simulator, which stands for
    # the physical world, on a machine they oversubscribe (ring64 on 2 cores).
    agent_sched: str = "normal"

    def impairment(self, sender: int, receiver: int) -> LinkImpairment:
        for src, dst, spec in self.links:
            if (src, dst) == (sender, receiver):
                return spec
        return self.default
