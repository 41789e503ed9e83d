"""Key expressions: building, validation, parsing and wildcard matching."""

from __future__ import annotations

import pytest

from errors import ConfigError
from transport.key_exprs import KeyInfo, SwarmKeys, key_matches, parse_key, validate_concrete

K = SwarmKeys("s1")


def test_keys_are_namespaced_per_swarm() -> None:
    assert K.follower_state(3) == "enclose/s1/follower/3/state"
    assert K.sensor_targets(0) == "enclose/s1/sensor/0/targets"
    assert K.truth() == "enclose/s1/truth"
    assert K.control() == "enclose/s1/control"
    assert K.status("sim", 0) == "enclose/s1/status/sim/0"
    assert K.alive("follower", 2) == "enclose/s1/alive/follower/2"
    assert not key_matches(SwarmKeys("s2").everything(), K.truth())


@pytest.mark.parametrize("name", ["", "a/b", "a*", "a$", "a#", "a?", "a b", "x" * 65, "é"])
def test_bad_swarm_names_rejected(name: str) -> None:
    with pytest.raises(ConfigError) as err:
        SwarmKeys(name)
    assert err.value.field == "swarm"


@pytest.mark.parametrize("index", [-1, True, 1.0, "1"])
def test_bad_indices_rejected(index: object) -> None:
    with pytest.raises(ConfigError):
        K.follower_state(index)  # type: ignore[arg-type]


def test_bad_role_rejected() -> None:
    with pytest.raises(ConfigError):
        K.status("a/b", 0)


@pytest.mark.parametrize(("expr", "key", "hit"), [
    (K.all_follower_states(), K.follower_state(12), True),
    (K.all_follower_states(), K.sensor_targets(1), False),
    (K.all_sensor_targets(), K.sensor_targets(1), True),
    (K.all_status(), K.status("follower", 4), True),
    (K.all_alive(), K.alive("sim", 0), True),
    (K.everything(), K.truth(), True),
    ("enclose/s1/**", "enclose/s1", True),        # ** matches zero chunks
    ("enclose/*/truth", "enclose/s1/truth", True),
    ("enclose/*", "enclose/s1/truth", False),     # * is one chunk only
    ("enclose/**/state", "enclose/s1/follower/1/state", True),
    ("enclose/s1/follower/st*", "enclose/s1/follower/state", True),
    ("enclose/s1/truth", "enclose/s1/truth/x", False),
])
def test_wildcard_matching(expr: str, key: str, hit: bool) -> None:
    assert key_matches(expr, key) is hit


def test_parse_key_finds_the_sender() -> None:
    assert parse_key(K.follower_state(5)) == KeyInfo("s1", "follower", "follower", 5)
    assert parse_key(K.sensor_targets(2)) == KeyInfo("s1", "sensor", "follower", 2)
    assert parse_key(K.status("sim", 0)) == KeyInfo("s1", "status", "sim", 0)
    assert parse_key(K.truth()) == KeyInfo("s1", "truth")
    assert parse_key(K.control()) == KeyInfo("s1", "control")
    assert parse_key("other/s1/truth") is None
    assert parse_key("enclose/s1/follower/x/state") is None


@pytest.mark.parametrize("key", ["", "a//b", "a/*", "a/**", "a/$x", "/a"])
def test_publish_keys_must_be_concrete(key: str) -> None:
    with pytest.raises(ConfigError):
        validate_concrete(key)
