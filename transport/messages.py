"""The messages of the swarm: frozen dataclasses with units and frames in names.

Conventions:
- Positions/velocities are in the local ENU frame, metres and m/s.  2-D
  vectors (the enclosing plane) are `Vec2 = tuple[float, float]`; the truth
  snapshot gives followers in 3-D (`Vec3`, z up) because vehicles fly at altitude.
- Vectors are plain tuples of Python floats, never numpy arrays: messages stay
  immutable, comparable and hashable.  Build them from numpy with `vec2(arr)` /
  `vec3(arr)`; go back with `numpy.asarray(msg.r_m)`.
- Indices are 0-based (follower i, target j), as everywhere in code.
- Every message starts with a `Header` (sender id, per-sender sequence number,
  sender clock `stamp_s`), made by a `Stamper`.  The codec version travels on
  the wire (see `transport.codec`).  A later version may append fields, with
  defaults, to a message; older payloads then decode with those defaults.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from transport.bus import Clock
from transport.fastbuild import build
from transport.law_fields import LawFields

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
ClockEcho = tuple[str, float, float]  # (peer sender id, its probe's stamp, our receive time)

PROCESS_STATES = ("starting", "linked", "running", "flying", "stopping", "done", "failed")


def vec2(values: Iterable[float]) -> Vec2:
    """A Vec2 from any 2-sequence (numpy array, list, tuple)."""
    x, y = (float(v) for v in values)
    return (x, y)


def vec3(values: Iterable[float]) -> Vec3:
    x, y, z = (float(v) for v in values)
    return (x, y, z)


@dataclass(frozen=True)
class Header:
    sender_id: str  # e.g. "follower-2", "sim-0"
    seq: int  # per (sender, key) stream, +1 per message sent, from 0
    stamp_s: float  # sender's clock when the message was built


class Stamper:
    """Makes the headers of one stream: same sender id, seq +1 per message, its clock.

    Use one Stamper per key a process publishes on, so that a receiver of that key
    sees consecutive numbers and can count gaps (see `transport.decoder`).
    """

    def __init__(self, sender_id: str, clock: Clock = time.time) -> None:
        self.sender_id = sender_id
        self._clock = clock
        self._seq = 0

    @property
    def next_seq(self) -> int:
        return self._seq

    def header(self, stamp_s: float | None = None) -> Header:
        """Header for the next message; `stamp_s` overrides the clock (e.g. sim time)."""
        # Built without the frozen __init__ (transport.fastbuild): one per message sent.
        head = build(Header, {"sender_id": self.sender_id, "seq": self._seq,
                              "stamp_s": self._clock() if stamp_s is None else stamp_s})
        self._seq += 1
        return head


@dataclass(frozen=True)
class FollowerState:
    """What follower `index` tells its neighbours (and the recorder) every step: what the
    platform always publishes, and its law's own fields (transport.law_fields)."""

    header: Header
    index: int
    r_m: Vec2  # its law's estimate r_i of the targets' centre (LAP)
    dr_m_s: Vec2  # its derivative dr_i/dt
    pos_m: Vec2  # own position used this step
    vel_m_s: Vec2  # own velocity used this step
    u_m_s: Vec2  # velocity command sent this step
    vehicle_stamp_s: float  # stamp of the vehicle state used
    # The fields its law declared, by name (codec v4): a float, a Vec2, or per neighbour j
    # (j, x, y).  The paper's law: nothing with its own estimator; with the robust one its
    # link sums and their rates, and at order 2 rv_m_s and the velocity stage's
    # (agents.law.paper).
    law: LawFields = field(default_factory=dict)


@dataclass(frozen=True)
class TargetObservation:
    """Target `target_index` seen by follower `observer_index` (published by the sensor)."""

    header: Header
    observer_index: int
    target_index: int
    pos_m: Vec2
    observed_stamp_s: float  # when the position was true
    noise_std_m: float | None = None  # std of the added measurement noise, if known


@dataclass(frozen=True)
class TruthSnapshot:
    """Ground truth from the simulator, for the recorder."""

    header: Header
    sim_time_s: float
    follower_pos_m: tuple[Vec3, ...]
    follower_vel_m_s: tuple[Vec3, ...]
    target_pos_m: tuple[Vec2, ...]
    target_vel_m_s: tuple[Vec2, ...]


@dataclass(frozen=True)
class ProcessStatus:
    """A process's life cycle and counters (drops, gaps, overruns, ...)."""

    header: Header
    role: str  # follower | sim | recorder | launcher | ...
    index: int
    state: str  # one of PROCESS_STATES
    counters: Mapping[str, int] = field(default_factory=dict)
    detail: str = ""


RUN_COMMANDS = ("start", "stop")


@dataclass(frozen=True)
class RunControl:
    """The launcher's word to every process: start the experiment clock, or stop."""

    header: Header
    command: str  # one of RUN_COMMANDS
    start_stamp_s: float  # sender clock at which experiment time 0 is (targets start moving)
    duration_s: float  # experiment length after start


@dataclass(frozen=True)
class ClockProbe:
    """One process's side of the NTP-style exchange that estimates peer clock offsets
    (transport.clock_sync): sent a few times a second; the header stamp is the send time."""

    header: Header
    epoch_s: float  # sender's clock when its process started: a new value means a restart
    echoes: tuple[ClockEcho, ...] = ()  # the newest probe heard from each peer


Message = (FollowerState | TargetObservation | TruthSnapshot | ProcessStatus | RunControl
           | ClockProbe)
