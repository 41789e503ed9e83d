"""Zenoh config: safe defaults, user JSON5 file passed through, validation (no session opened)."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from errors import ConfigError
from transport.codec import MAX_PAYLOAD_BYTES
from transport.network_schema import ZENOH_RUNTIMES
from transport.zenoh_config import (
    ACCEPT_PENDING,
    ACCEPT_PENDING_KEY,
    ACCEPT_TIMEOUT_KEY,
    ACCEPT_TIMEOUT_MS,
    LEASE_KEY,
    LINK_BUFFER_BYTES,
    MAX_MESSAGE_BYTES,
    MAX_MESSAGE_KEY,
    ROUTER_BLOCK_CLOSE_KEY,
    ROUTER_BLOCK_CLOSE_US,
    ROUTER_LEASE_KEY,
    ROUTER_LEASE_MS,
    ROUTER_OPEN_TIMEOUT_KEY,
    ROUTER_OPEN_TIMEOUT_MS,
    RUNTIME_SETTINGS,
    ZenohConfig,
    build_zenoh_config,
    loopback_endpoint,
)


def get(cfg: ZenohConfig, key: str) -> object:
    return json.loads(build_zenoh_config(cfg).get_json(key))


def test_defaults_are_safe_peer_on_loopback() -> None:
    cfg = ZenohConfig()
    assert get(cfg, "mode") == "peer"
    assert get(cfg, "scouting/multicast/enabled") is False
    assert get(cfg, "listen/endpoints") == ["tcp/127.0.0.1:0"]
    assert get(cfg, "connect/endpoints") == []
    assert get(cfg, "timestamping/enabled") is True
    assert get(cfg, "transport/unicast/lowlatency") is False
    assert get(cfg, "transport/link/tx/batch_size") == LINK_BUFFER_BYTES
    assert get(cfg, "transport/link/rx/buffer_size") == LINK_BUFFER_BYTES
    assert get(cfg, "transport/shared_memory/enabled") is False  # no watchdog threads
    # One link a pair of peers: only the greater ZID dials; any router is dialled.
    assert get(cfg, "scouting/gossip/autoconnect_strategy") == {
        "peer": {"to_router": "always", "to_peer": "greater-zid"}}


def test_every_session_refuses_messages_over_the_codecs_cap() -> None:
    """A larger message would be reassembled in full before the codec refuses it."""
    assert MAX_MESSAGE_BYTES - MAX_PAYLOAD_BYTES == 1024
    for cfg in (ZenohConfig(), ZenohConfig(mode="client", connect=("tcp/127.0.0.1:1",)),
                ZenohConfig(mode="router", listen=(loopback_endpoint(17002),))):
        assert get(cfg, MAX_MESSAGE_KEY) == MAX_MESSAGE_BYTES


def test_routers_close_a_stuck_link_and_reopen_a_healed_one_sooner_than_zenohs_defaults(
) -> None:
    router = ZenohConfig(mode="router", listen=(loopback_endpoint(17003),))
    assert get(router, ROUTER_BLOCK_CLOSE_KEY) == ROUTER_BLOCK_CLOSE_US < 5_000_000
    assert get(router, ROUTER_OPEN_TIMEOUT_KEY) == ROUTER_OPEN_TIMEOUT_MS < 10_000
    assert get(ZenohConfig(), ROUTER_BLOCK_CLOSE_KEY) == 5_000_000  # peers: Zenoh's own
    assert get(ZenohConfig(), ROUTER_OPEN_TIMEOUT_KEY) == 10_000


@pytest.mark.parametrize("mode", ["peer", "client", "router"])
def test_every_listener_outlasts_a_flood_of_idle_connections(mode: str) -> None:
    """More handshake slots than Zenoh's 100, each held for less than its 10 s
    (tests/integration/test_rendezvous_flood.py: 200 idle connections)."""
    cfg = ZenohConfig(mode=mode, connect=(loopback_endpoint(17005),))
    assert get(cfg, ACCEPT_PENDING_KEY) == ACCEPT_PENDING >= 200
    assert get(cfg, ACCEPT_TIMEOUT_KEY) == ACCEPT_TIMEOUT_MS < 10_000


def test_a_user_file_sets_its_own_accept_limits(tmp_path: Path) -> None:
    path = tmp_path / "zenoh.json5"
    path.write_text("{ transport: { unicast: { accept_pending: 50, accept_timeout: 9000 } } }")
    cfg = ZenohConfig(user_config_path=str(path))
    assert (get(cfg, ACCEPT_PENDING_KEY), get(cfg, ACCEPT_TIMEOUT_KEY)) == (50, 9000)


def test_routers_show_a_lost_link_within_their_lease_clients_keep_zenohs() -> None:
    router = ZenohConfig(mode="router", listen=(loopback_endpoint(17004),))
    assert get(router, ROUTER_LEASE_KEY) == ROUTER_LEASE_MS <= 3_000
    client = ZenohConfig(mode="client", connect=(loopback_endpoint(17004),))
    assert get(client, ROUTER_LEASE_KEY) == 10_000  # a paused client rides 10 s through
    assert get(ZenohConfig(), ROUTER_LEASE_KEY) == 10_000


def test_a_scenario_lease_reaches_peers_and_clients_not_routers() -> None:
    assert get(ZenohConfig(lease_s=30.0), LEASE_KEY) == 30_000
    client = ZenohConfig(mode="client", connect=(loopback_endpoint(17004),), lease_s=2.5)
    assert get(client, LEASE_KEY) == 2_500
    router = ZenohConfig(mode="router", listen=(loopback_endpoint(17004),), lease_s=30.0)
    assert get(router, ROUTER_LEASE_KEY) == ROUTER_LEASE_MS
    for bad in (0.5, 601.0, float("nan")):
        with pytest.raises(ConfigError, match=r"zenoh\.lease_s"):
            ZenohConfig(lease_s=bad)


def test_explicit_endpoints_and_lowlatency() -> None:
    cfg = ZenohConfig(listen=(loopback_endpoint(17001),), connect=(loopback_endpoint(17002),),
                      lowlatency=True)
    assert get(cfg, "listen/endpoints") == ["tcp/127.0.0.1:17001"]
    assert get(cfg, "connect/endpoints") == ["tcp/127.0.0.1:17002"]
    assert get(cfg, "transport/unicast/lowlatency") is True
    assert get(cfg, "transport/unicast/qos/enabled") is False


def test_user_file_settings_win_and_unset_keys_stay_safe(tmp_path: Path) -> None:
    path = tmp_path / "zenoh.json5"
    path.write_text("""{
      // the user's own choice: multicast on loopback only
      mode: "router",
      scouting: { multicast: { enabled: true, interface: "lo" } },
      connect: { endpoints: ["tcp/127.0.0.1:17003"] },
    }""")
    cfg = ZenohConfig(user_config_path=str(path))
    assert get(cfg, "mode") == "router"
    assert get(cfg, "scouting/multicast/enabled") is True
    assert get(cfg, "scouting/multicast/interface") == "lo"
    assert get(cfg, "connect/endpoints") == ["tcp/127.0.0.1:17003"]
    assert get(cfg, "listen/endpoints") == ["tcp/127.0.0.1:0"]  # file left it unset
    assert get(cfg, "timestamping/enabled") is True


def test_user_file_silent_on_scouting_gets_multicast_off(tmp_path: Path) -> None:
    path = tmp_path / "zenoh.json5"
    path.write_text('{ transport: { unicast: { max_links: 2 },'
                    ' link: { tx: { batch_size: 32768 } }, shared_memory: { enabled: true } } }')
    cfg = ZenohConfig(user_config_path=str(path), listen=(loopback_endpoint(17004),))
    assert get(cfg, "scouting/multicast/enabled") is False
    assert get(cfg, "transport/link/tx/batch_size") == 32768  # the user's
    assert get(cfg, "transport/link/rx/buffer_size") == LINK_BUFFER_BYTES  # ours
    assert get(cfg, "listen/endpoints") == ["tcp/127.0.0.1:17004"]
    assert get(cfg, "transport/unicast/max_links") == 2
    assert get(cfg, "transport/shared_memory/enabled") is True  # the user's


def test_a_user_file_keeps_zenohs_own_autoconnect_strategy(tmp_path: Path) -> None:
    path = tmp_path / "zenoh.json5"
    path.write_text('{ scouting: { gossip: { autoconnect_strategy:'
                    ' { peer: { to_peer: "always", to_router: "always" } } } } }')
    cfg = ZenohConfig(user_config_path=str(path))
    assert get(cfg, "scouting/gossip/autoconnect_strategy")["peer"]["to_peer"] == "always"
    silent = tmp_path / "silent.json5"
    silent.write_text("{ transport: { link: { tx: { batch_size: 32768 } } } }")
    strategy = get(ZenohConfig(user_config_path=str(silent)),
                   "scouting/gossip/autoconnect_strategy")
    assert strategy["peer"]["to_peer"] == "greater-zid"


@pytest.mark.parametrize("kwargs", [
    {"mode": "bridge"},
    {"listen": "tcp/127.0.0.1:1"},
    {"connect": ("127.0.0.1:1",)},
    {"user_config_path": "/nonexistent/zenoh.json5"},
])
def test_invalid_config_rejected(kwargs: dict[str, object]) -> None:
    with pytest.raises(ConfigError):
        ZenohConfig(**kwargs)  # type: ignore[arg-type]


def test_unparsable_user_file_rejected(tmp_path: Path) -> None:
    path = tmp_path / "bad.json5"
    path.write_text("{ mode: ")
    with pytest.raises(ConfigError):
        build_zenoh_config(ZenohConfig(user_config_path=str(path)))



@pytest.mark.realtime
@pytest.mark.timeout(60)
@pytest.mark.parametrize(("preset", "runtime", "rx_threads"),
                         [(None, "split", 1), ("(rx: (worker_threads: 2))", "split", 2),
                          (None, "one_thread", 0),
                          ("(rx: (worker_threads: 2))", "one_thread", 2)])
def test_zenoh_threads_follow_the_runtime_unless_the_user_says_otherwise(
        preset: str | None, runtime: str, rx_threads: int) -> None:
    """ZenohBus asks Zenoh for one rx worker (a second one only costs wake-ups), or for
    one thread in all (`one_thread`), unless ZENOH_RUNTIME is already set: then the user's
    choice stands."""
    env = {k: v for k, v in os.environ.items() if k != "ZENOH_RUNTIME"}
    if preset is not None:
        env["ZENOH_RUNTIME"] = preset
    with socket.socket() as s:  # a free port for the listening session
        s.bind(("127.0.0.1", 0))
        endpoint = loopback_endpoint(s.getsockname()[1])
    code = (
        "import os, time\n"
        "from transport.zenoh_bus import ZenohBus\n"
        "from transport.zenoh_config import ZenohConfig\n"
        f"a = ZenohBus(ZenohConfig(listen=({endpoint!r},), runtime={runtime!r}))\n"
        "sub = a.subscribe('t/x')\n"
        f"b = ZenohBus(ZenohConfig(connect=({endpoint!r},), runtime={runtime!r}))\n"
        "pub = b.declare_publisher('t/x')\n"
        "end = time.monotonic() + 20\n"
        "while not sub.drain() and time.monotonic() < end:\n"
        "    pub.put(b'x'); time.sleep(0.05)\n"
        "names = [open(f'/proc/self/task/{t}/comm').read().strip()\n"
        "         for t in os.listdir('/proc/self/task')]\n"
        "print(os.environ['ZENOH_RUNTIME'], sum(n.startswith('rx-') for n in names),\n"
        "      sum(n[:3] in ('rx-', 'tx-', 'net', 'acc') for n in names))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=50, check=True).stdout.split()
    assert " ".join(out[:-2]) == (preset or RUNTIME_SETTINGS[runtime])
    assert int(out[-2]) == rx_threads
    if preset is None and runtime == "one_thread":
        assert int(out[-1]) == 0  # only the app runtime's threads: no rx, tx, net or acc


def test_every_runtime_of_the_schema_has_a_setting() -> None:
    assert set(RUNTIME_SETTINGS) == set(ZENOH_RUNTIMES)


def test_an_unknown_runtime_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"zenoh\.runtime"):
        ZenohConfig(runtime="two_threads")
