"""Zenoh session configuration, built in one function from a frozen dataclass.

Safe by construction: peer mode, explicit endpoints, multicast scouting off,
listening on 127.0.0.1 only, HLC timestamping on.  A user's own Zenoh config
file (JSON5) may be given; it is loaded untouched as the base, and any key it
sets wins over our safe value -- except `timestamping/enabled`, which the
message stamps need, and non-empty `listen`/`connect` lists given here, which
are explicit choices of the caller.  Keys the file leaves unset get the safe
values, so a file that only tunes, say, buffers never opens multicast scouting
or a listener on every interface.  (A key the file sets to Zenoh's own default
reads as unset: ask for a 65535-byte batch as 65534.)  Shared memory is off (nothing
here uses it, and its watchdog threads cost every process) unless the file mentions
`shared_memory` at all.  Of two peers, only the one of greater ZID opens their link (one
link a pair, not two) unless the file mentions `autoconnect_strategy`.

With an `identity` (transport.credentials) the session is authenticated: every link
is mutual TLS with the swarm's CA (a peer without a swarm certificate cannot link),
and the swarm's `access_control` rules are loaded; default endpoints become `tls/`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import zenoh

from errors import ConfigError
from transport.codec import MAX_PAYLOAD_BYTES
from transport.credentials import Identity
from transport.network_schema import LINK_PROTOCOLS, ZENOH_LEASE_RANGE_S, ZENOH_RUNTIMES

LOOPBACK_LISTEN = ("tcp/127.0.0.1:0",)
# Zenoh's runtime, as ZENOH_RUNTIME (read once per process, when its first session opens).
# An enclose process receives a few hundred small messages a second, and every thread
# woken for one of them is CPU spent on the wake-up (BENCHMARKS.md, issue 15).  One
# setting per name of the scenario schema's ZENOH_RUNTIMES (`[network] zenoh_runtime`):
RUNTIME_SETTINGS = {
    # One receiving worker instead of Zenoh's two (ring16, paired runs: followers 7.8-8.0 %
    # of a core instead of 8.2-8.3 %, 0.4-0.7 % of ticks late instead of 0.9-1.0 %).
    "split": "(rx: (worker_threads: 1))",
    # All of Zenoh's work on one thread: ring16 followers 5.2-5.4 % instead of 5.7 %, and
    # ring32 on 2 cores 0.00-0.02 % late ticks instead of 0.73 %; one-way latency at n = 8
    # p50 250 instead of 222 us (its tasks wait for each other).
    "one_thread": "(rx: (handover: app), net: (handover: app), tx: (handover: app), "
                  "acc: (handover: app), app: (worker_threads: 1))",
}
ENDPOINT_PROTOCOLS = (*LINK_PROTOCOLS, "tls")
# Zenoh's batch and per-link receive buffer, bytes (Zenoh's default 65535).  Every link of
# the peer mesh holds them, and a follower of n peers has about n + 4 links: in ring32
# 8 KB instead of 64 KB took 3.4 MB off each follower's RSS (BENCHMARKS.md, issue 15).  Our
# samples are under 1 KB, so a batch still holds a tick's worth; a larger message is
# fragmented, not lost.  Both sides of a link agree on the smaller batch size.
LINK_BUFFER_BYTES = 8192
SHM_KEY = "transport/shared_memory/enabled"
# The largest message a session takes in (Zenoh: 1 GiB).  A larger one arrives in
# fragments that Zenoh holds until the whole is there, only for the codec to refuse it
# (MAX_PAYLOAD_BYTES): a 20-MB put held 20 MB in every subscriber first.  Past this
# size Zenoh drops the reassembly and keeps the link (measured: the next put arrives).
# Headroom over the payload cap for what Zenoh adds: key, timestamp, encoding.
MAX_MESSAGE_KEY = "transport/link/rx/max_message_size"
MAX_MESSAGE_BYTES = MAX_PAYLOAD_BYTES + 1024
# A router closes a link whose send queue stayed full this long (Zenoh: 5 s).  Samples
# went with BLOCK congestion control, so a link that carries nothing (a partition between
# hosts) held the router's forwarding, and behind it every publisher on its host, until
# then: the simulator's sensing and the near side's own states stalled for seconds
# (deploy.hosts.host_cut, BENCHMARKS.md).  Real-time data now goes with DROP (transport.bus.
# Congestion); the words sent once still block.  1 s: far past any queue on a link that
# still moves.
ROUTER_BLOCK_CLOSE_KEY = "transport/link/tx/queue/congestion_control/block/wait_before_close"
ROUTER_BLOCK_CLOSE_US = 1_000_000
# How long a router's attempt to open a link may take once its TCP connection is up
# (Zenoh: 10 s): the handshake, far past an mTLS exchange between hosts.  It does not bound
# the TCP connect itself (Zenoh 1.10 awaits it without a timeout): an attempt begun during
# a partition waits on the kernel's SYN retries, which the hosts bound instead
# (deploy.hosts.namespaced_hosts: `net.ipv4.tcp_syn_retries`; docs/multihost.md for real hosts).
ROUTER_OPEN_TIMEOUT_KEY = "transport/unicast/open_timeout"
ROUTER_OPEN_TIMEOUT_MS = 2000
# A router's lease (Zenoh: 10 s): a peer that heard nothing from it this long gives the
# link up.  Zenoh's 10 s outlasted the first 10 s of every 15-s partition between hosts,
# and a router began to look for the lost link only then; 2 s (keep-alives every 0.5 s)
# gives it up 2-3 s into a cut (membership sees the cut by the routers' probes, not by
# Zenoh's tokens: transport.clock_sync).  Each end expires a link by the lease the other
# announced, so a router's clients keep their own 10 s: a paused client is still ridden
# through (one paused over 2 s re-links to its router when it runs again).
ROUTER_LEASE_KEY = "transport/link/tx/lease"
ROUTER_LEASE_MS = 2000
# Peers and clients keep Zenoh's 10-s lease unless the scenario sets another
# (`[network] zenoh_lease_s`): every link sends a keep-alive each quarter lease while it
# carries nothing else, and in a full mesh most links carry nothing.  64 idle secure peers
# cost 0.48 % of a core each with 10 s, 0.16 % with 30 s (`bench/bench_mesh_cost.py
# --status-hz 0`); the lease is also how long a frozen (SIGSTOPped) process stays a member.
LEASE_KEY = ROUTER_LEASE_KEY
# Every listener (a router, the rendezvous peer) holds a link whose handshake has not
# finished in one of `accept_pending` slots (Zenoh: 100) for up to `accept_timeout` (Zenoh:
# 10 s).  Anyone who reaches the port fills them with bare TCP connections, no credentials
# needed: with 200 held open on a plain-TCP listener, a new peer's first sample got through
# after 11.1 s, once Zenoh had timed them out, and never while they were re-opened as they
# dropped (0.06 s with 500 slots); a follower killed in a run took 16.4 s to rejoin, 3.7 s
# with ours (bench/bench_rendezvous_flood.py, tests/integration/test_rendezvous_flood.py).
# 500 slots outnumber such a flood while staying under the usual 1024 descriptors a process
# may open; 3 s is still far past an mTLS handshake on a loaded machine, and frees a slot
# held by a silent connection three times sooner.
ACCEPT_PENDING_KEY = "transport/unicast/accept_pending"
ACCEPT_PENDING = 500
ACCEPT_TIMEOUT_KEY = "transport/unicast/accept_timeout"
ACCEPT_TIMEOUT_MS = 3000
# Which side of a pair of peers opens their link.  Zenoh's default (`always`) has both
# dial each other once gossip names them, and both links stay: ring16 held 393 TCP
# connections for the 210 pairs of its 21 processes (786 sockets on 127.0.0.1).  With
# `greater-zid` the peer of greater ZID dials and the other waits: 210, one a pair, so
# half the mTLS handshakes at start and half the keep-alives and link buffers after.
# ring64 linked and armed (take-off excluded) in 9.1-10.0 s instead of 12.0-12.9 s, its
# largest follower's peak RSS 56.3-57.7 MB instead of 60.5-61.2 (bench/bench_start.py, 2
# runs a side, alternated).  A router is still always dialled: it dials no peer itself.
AUTOCONNECT_STRATEGY_KEY = "scouting/gossip/autoconnect_strategy"
AUTOCONNECT_STRATEGY = {"peer": {"to_router": "always", "to_peer": "greater-zid"}}
_MODES = ("peer", "client", "router")


@dataclass(frozen=True)
class ZenohConfig:
    """What a process needs to open its Zenoh session."""

    mode: str = "peer"
    listen: tuple[str, ...] = ()  # empty: an OS-chosen port on 127.0.0.1
    connect: tuple[str, ...] = ()
    user_config_path: str | None = None
    lowlatency: bool = False  # `transport/unicast/lowlatency`; also turns QoS off
    link: str = "tcp"  # protocol of the default listen endpoint (scenario `[network] link`)
    identity: Identity | None = None  # None: unauthenticated (`--insecure`)
    # Stamp each sample as it arrives (transport.zenoh_bus): a Python callback, with the
    # GIL, on Zenoh's receiving thread for every sample, so off unless latency is measured.
    arrival_stamps: bool = False
    runtime: str = "split"  # one of ZENOH_RUNTIMES (scenario `[network] zenoh_runtime`)
    # A peer's or client's lease (scenario `[network] zenoh_lease_s`); None: Zenoh's 10 s.
    # A router keeps ROUTER_LEASE_MS whatever this says.
    lease_s: float | None = None
    # A client's wait at open for its router (Zenoh's `connect/timeout_ms`): -1 forever.
    connect_timeout_ms: int = -1

    def __post_init__(self) -> None:
        lo, hi = ZENOH_LEASE_RANGE_S
        if self.lease_s is not None and not lo <= self.lease_s <= hi:
            raise ConfigError("zenoh.lease_s", f"must be {lo:g}..{hi:g} s, got {self.lease_s!r}")
        if self.mode not in _MODES:
            raise ConfigError("zenoh.mode", f"{self.mode!r} not in {_MODES}")
        if self.runtime not in ZENOH_RUNTIMES:
            raise ConfigError("zenoh.runtime", f"{self.runtime!r} not in {ZENOH_RUNTIMES}")
        if self.link not in LINK_PROTOCOLS:
            raise ConfigError("zenoh.link", f"{self.link!r} not in {LINK_PROTOCOLS}")
        for field, endpoints in (("zenoh.listen", self.listen), ("zenoh.connect", self.connect)):
            if isinstance(endpoints, str) or not all(isinstance(e, str) for e in endpoints):
                raise ConfigError(field, "must be a tuple of endpoint strings")
            for e in endpoints:
                if "/" not in e:
                    raise ConfigError(field, f"{e!r} is not a locator like tcp/127.0.0.1:7447")
        if self.identity is not None and self.link != "tcp":
            raise ConfigError("zenoh.link", f"{self.link!r} cannot be authenticated (mTLS is "
                              "over TCP): use link tcp, or --insecure")
        if self.user_config_path is not None and not Path(self.user_config_path).is_file():
            raise ConfigError("zenoh.user_config_path", f"{self.user_config_path} is not a file")


def _is_set(config: zenoh.Config, default: zenoh.Config, key: str) -> bool:
    """True if the user's file gave `key` a value other than Zenoh's built-in one."""
    return bool(config.get_json(key) != default.get_json(key))


def _mentions(path: str | None, word: str) -> bool:
    """The user's file names `word`: a boolean set to Zenoh's default cannot be told from
    an unset one, so any mention leaves the setting to the file."""
    return path is not None and word in Path(path).read_text(errors="replace")


def _put(config: zenoh.Config, key: str, value: object) -> None:
    # insert_json5 takes a JSON5 *string*, not a Python value.
    config.insert_json5(key, json.dumps(value))


def build_zenoh_config(cfg: ZenohConfig) -> zenoh.Config:
    """The zenoh.Config for `cfg` (see the module docstring for precedence)."""
    default = zenoh.Config()
    if cfg.user_config_path is None:
        config = zenoh.Config()
    else:
        try:
            config = zenoh.Config.from_file(cfg.user_config_path)
        except zenoh.ZError as exc:
            raise ConfigError("zenoh.user_config_path", str(exc)) from exc
    user = cfg.user_config_path is not None
    if not (user and _is_set(config, default, "mode")):
        _put(config, "mode", cfg.mode)
    proto = "tls" if cfg.identity is not None else cfg.link
    # A client listens nowhere: it reaches the swarm through its router only.
    if cfg.mode == "client" and not cfg.listen:
        _put(config, "listen/endpoints", [])
    elif cfg.listen or not (user and _is_set(config, default, "listen/endpoints")):
        _put(config, "listen/endpoints", list(cfg.listen or (loopback_endpoint(0, proto),)))
    if cfg.connect:
        _put(config, "connect/endpoints", list(cfg.connect))
    if cfg.mode != "peer":
        # A client waits at open for its host's router, and both clients and routers
        # survive a router's restart: they keep retrying every 0.25-1 s (Zenoh: 1-4 s).
        _put(config, "connect/retry", {"period_init_ms": 250, "period_max_ms": 1000,
                                       "period_increase_factor": 2})
    if cfg.mode == "client":
        _put(config, "connect/timeout_ms", cfg.connect_timeout_ms)
    if cfg.mode != "router" and cfg.lease_s is not None \
            and not (user and _is_set(config, default, LEASE_KEY)):
        _put(config, LEASE_KEY, round(cfg.lease_s * 1000.0))
    if cfg.mode == "router":
        for key, value in ((ROUTER_BLOCK_CLOSE_KEY, ROUTER_BLOCK_CLOSE_US),
                           (ROUTER_OPEN_TIMEOUT_KEY, ROUTER_OPEN_TIMEOUT_MS),
                           (ROUTER_LEASE_KEY, ROUTER_LEASE_MS)):
            if not (user and _is_set(config, default, key)):
                _put(config, key, value)
    for key, value in ((ACCEPT_PENDING_KEY, ACCEPT_PENDING),
                       (ACCEPT_TIMEOUT_KEY, ACCEPT_TIMEOUT_MS)):
        if not (user and _is_set(config, default, key)):
            _put(config, key, value)
    if not (user and _is_set(config, default, "scouting/multicast/enabled")):
        _put(config, "scouting/multicast/enabled", False)
    # Zenoh's own `always`, written in the file, must win too: any mention leaves it there.
    if not (user and _mentions(cfg.user_config_path, "autoconnect_strategy")):
        _put(config, AUTOCONNECT_STRATEGY_KEY, AUTOCONNECT_STRATEGY)
    for key, value in (("transport/link/tx/batch_size", LINK_BUFFER_BYTES),
                       ("transport/link/rx/buffer_size", LINK_BUFFER_BYTES),
                       (MAX_MESSAGE_KEY, MAX_MESSAGE_BYTES)):
        if not (user and _is_set(config, default, key)):
            _put(config, key, value)
    # Nothing here sends through shared memory (no SHM provider; samples < 1 KB), but with
    # it on every session runs two watchdog threads, one at SCHED_FIFO, ~35 wake-ups a
    # second: a 64-process mesh idles at 0.40 % of a core each instead of 0.46 %.
    if not (user and _mentions(cfg.user_config_path, "shared_memory")):
        _put(config, SHM_KEY, False)
    _put(config, "timestamping/enabled", True)
    if cfg.lowlatency:
        _put(config, "transport/unicast/lowlatency", True)
        _put(config, "transport/unicast/qos/enabled", False)
    if cfg.identity is not None:
        _secure(config, cfg.identity)
    return config


def _secure(config: zenoh.Config, ident: Identity) -> None:
    """mTLS on every link with the swarm's CA, and the swarm's ACL (transport.access)."""
    _put(config, "transport/link/tls", {
        "root_ca_certificate": ident.ca_path,
        "listen_private_key": ident.key_path,
        "listen_certificate": ident.cert_path,
        "connect_private_key": ident.key_path,
        "connect_certificate": ident.cert_path,
        "enable_mtls": True,
        # The certificate names a process, not a host; trust comes from the private CA.
        "verify_name_on_connect": False,
    })
    _put(config, "access_control", ident.acl())


def loopback_endpoint(port: int, proto: str = "tcp") -> str:
    """`<proto>/127.0.0.1:<port>`, proto tcp, udp or tls: the only kind of endpoint used by default.

    Port 0 lets the OS choose, for udp as for tcp (Zenoh 1.10 binds `udp/127.0.0.1:0` and
    gossips the port it got, so peers listening that way still mesh).
    """
    if not 0 <= port <= 65535:
        raise ConfigError("zenoh.port", f"{port} out of range")
    if proto not in ENDPOINT_PROTOCOLS:
        raise ConfigError("zenoh.link", f"{proto!r} not in {ENDPOINT_PROTOCOLS}")
    return f"{proto}/127.0.0.1:{port}"
