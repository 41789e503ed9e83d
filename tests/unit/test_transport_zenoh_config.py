"""Zenoh config: safe defaults, user JSON5 file passed through, validation (no session opened)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from agents.errors import ConfigError
from transport.zenoh_config import ZenohConfig, build_zenoh_config, loopback_endpoint


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
    path.write_text('{ transport: { unicast: { max_links: 2 } } }')
    cfg = ZenohConfig(user_config_path=str(path), listen=(loopback_endpoint(17004),))
    assert get(cfg, "scouting/multicast/enabled") is False
    assert get(cfg, "listen/endpoints") == ["tcp/127.0.0.1:17004"]
    assert get(cfg, "transport/unicast/max_links") == 2


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
