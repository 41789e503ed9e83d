"""The swarm's ACL and the secure Zenoh config (no session opened)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from errors import ConfigError
from transport.access import access_control, own_keys
from transport.credentials import Identity, identity_file, make_credentials
from transport.key_exprs import SwarmKeys
from transport.zenoh_config import ZenohConfig, build_zenoh_config

KEYS = SwarmKeys("acl")


def test_each_process_owns_only_its_keys() -> None:
    assert set(own_keys(KEYS, "follower-2", 4)) == {
        KEYS.follower_state(2), KEYS.follower_estimate(2), KEYS.status("follower", 2),
        KEYS.alive("follower", 2)}
    sim = own_keys(KEYS, "sim", 4)
    assert KEYS.truth() in sim and KEYS.sensor_targets(3) in sim and KEYS.control() not in sim
    assert KEYS.control() in own_keys(KEYS, "launcher", 4)
    assert set(own_keys(KEYS, "recorder", 4)) == {KEYS.status("recorder", 0),
                                                  KEYS.alive("recorder", 0)}
    assert set(own_keys(KEYS, "target-1", 4)) == {KEYS.status("target", 1),
                                                  KEYS.alive("target", 1)}
    # Clock probes are the routers' alone (transport.clock_sync): no process may forge one.
    assert not any("/clock/" in k for k in own_keys(KEYS, "follower-2", 4))


def test_routers_relay_every_swarm_key_but_are_named_apart() -> None:
    acl = access_control(KEYS, 2, 1, n_routers=2)
    rules = {r["id"]: r for r in acl["rules"]}  # type: ignore[attr-defined]
    assert rules["own-router-1"]["key_exprs"] == [KEYS.everything()]
    assert rules["own-router-1"]["flows"] == ["ingress"]
    names = acl["subjects"][0]["cert_common_names"]  # type: ignore[index]
    assert "router-0" in names and "router-1" in names


def test_default_deny_and_ingress_puts_only_per_process() -> None:
    acl = access_control(KEYS, 2, 1)
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    rules = {r["id"]: r for r in acl["rules"]}  # type: ignore[attr-defined]
    assert rules["send"]["flows"] == ["egress"] and "put" in rules["send"]["messages"]
    assert "declare_subscriber" in rules["read"]["messages"]
    assert rules["own-follower-1"]["flows"] == ["ingress"]
    assert rules["own-follower-1"]["key_exprs"] == own_keys(KEYS, "follower-1", 2)


def test_secure_config_is_mtls_with_the_acl(tmp_path: Path) -> None:
    creds = make_credentials(tmp_path / "c", KEYS, 2, 0)
    ident = Identity.load(identity_file(creds, "follower-0"))
    cfg = build_zenoh_config(ZenohConfig(identity=ident))
    assert json.loads(cfg.get_json("listen/endpoints"))[0].startswith("tls/127.0.0.1:")
    assert json.loads(cfg.get_json("transport/link/tls/enable_mtls")) is True
    assert json.loads(cfg.get_json("access_control/default_permission")) == "deny"
    with pytest.raises(ConfigError, match=r"zenoh\.link"):
        ZenohConfig(identity=ident, link="udp")
    with pytest.raises(ConfigError, match="credentials"):
        Identity.load(tmp_path / "missing.json")


HOSTS = [["launcher", "sim", "recorder", "target-0"], ["follower-0"], ["follower-1"]]


def _own(acl: dict[str, object], name: str) -> list[str]:
    rules = {r["id"]: r for r in acl["rules"]}  # type: ignore[attr-defined]
    return list(rules[f"own-{name}"]["key_exprs"])


def test_another_hosts_router_relays_only_its_own_processes_keys() -> None:
    # The ACL of host 1's processes: the link from router-2 carries host 2's keys only
    # (a stolen host folder's router key puts nothing else past it), not the sensing the
    # simulator sends to host 2 straight; its own router and the hub relay everything.
    acl = access_control(KEYS, 2, 1, n_routers=3, hosts=HOSTS, here=1)
    assert _own(acl, "router-1") == _own(acl, "router-0") == [KEYS.everything()]
    assert set(_own(acl, "router-2")) == {
        KEYS.follower_state(1), KEYS.follower_estimate(1), KEYS.status("follower", 1),
        KEYS.alive("follower", 1), KEYS.clock("router", 2)}
    # At the hub, every other router brings its own host's keys only.
    hub = access_control(KEYS, 2, 1, n_routers=3, hosts=HOSTS, here=0)
    assert _own(hub, "router-0") == [KEYS.everything()]
    assert KEYS.follower_state(0) in _own(hub, "router-1")
    for forged in (KEYS.control(), KEYS.truth(), KEYS.sensor_targets(0),
                   KEYS.sensor_targets(1), KEYS.follower_state(1), KEYS.status("sim", 0),
                   KEYS.alive("target", 0), KEYS.clock("router", 2)):
        assert forged not in _own(hub, "router-1"), forged
    with pytest.raises(ValueError, match="3 hosts for 2 routers"):
        access_control(KEYS, 2, 1, n_routers=2, hosts=HOSTS, here=0)
