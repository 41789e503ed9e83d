"""Authenticated Zenoh (mTLS + per-process ACL) between real sessions on loopback."""

from __future__ import annotations

import json
import stat
from pathlib import Path

import pytest

from deploy.launch.ports import free_tcp_port
from tests.integration.runs import wait_for
from transport.bus import Congestion
from transport.credentials import Identity, identity_file, make_credentials
from transport.key_exprs import SwarmKeys
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

pytestmark = pytest.mark.integration
KEYS = SwarmKeys("sec")


def bus(creds: Path | None, name: str, **kw: object) -> ZenohBus:
    ident = None if creds is None else Identity.load(identity_file(creds, name))
    return ZenohBus(ZenohConfig(identity=ident, **kw))  # type: ignore[arg-type]


def payloads(sub: object, seen: list[tuple[str, bytes]]) -> list[tuple[str, bytes]]:
    seen += [(r.key, r.payload) for r in sub.drain()]  # type: ignore[attr-defined]
    return seen


def test_credential_files_are_private(tmp_path: Path) -> None:
    creds = make_credentials(tmp_path / "c", KEYS, 2, 1)
    assert stat.S_IMODE(creds.stat().st_mode) == 0o700
    files = list(creds.iterdir())
    assert {f.name for f in files} >= {"ca.pem", "acl.json", "follower-1.key", "target-0.json"}
    assert not (creds / "ca.key").exists()  # a run's CA key is never kept
    assert all(stat.S_IMODE(f.stat().st_mode) == 0o600 for f in files)


@pytest.mark.timeout(60)
def test_rights_per_process_and_no_join_without_a_swarm_certificate(tmp_path: Path) -> None:
    creds = make_credentials(tmp_path / "c", KEYS, 2, 0)
    other_ca = make_credentials(tmp_path / "other", KEYS, 2, 0)
    endpoint = f"tls/127.0.0.1:{free_tcp_port()}"
    seen: list[tuple[str, bytes]] = []
    with bus(creds, "recorder", listen=(endpoint,)) as rec, \
            bus(creds, "follower-1", connect=(endpoint,)) as rogue, \
            bus(None, "-", connect=(endpoint.replace("tls/", "tcp/"),)) as plain, \
            bus(other_ca, "follower-0", connect=(endpoint,)) as foreign:
        sub = rec.subscribe(KEYS.everything())
        own = rogue.declare_publisher(KEYS.follower_state(1), Congestion.BLOCK)
        wait_for(lambda: bool(own.put(b"hello") or payloads(sub, seen)), 20, "follower-1 linked")
        # follower-1's certificate on follower 0's key, on the control key, on sim's truth:
        for key in (KEYS.follower_state(0), KEYS.control(), KEYS.truth()):
            for _ in range(20):
                rogue.publish(key, b"forged")
                plain.publish(key, b"forged")
                foreign.publish(key, b"forged")
        own.put(b"marker")  # same session, after the forgeries: they would be in by now
        wait_for(lambda: (KEYS.follower_state(1), b"marker") in payloads(sub, seen), 10,
                 "marker")
        assert all(p != b"forged" for _, p in seen), seen
        assert plain.peers() == [] and foreign.peers() == []  # never linked
        assert {k for k, _ in seen} == {KEYS.follower_state(1)}


def test_enclose_keys_makes_a_swarms_credentials(tmp_path: Path) -> None:
    from deploy.cli import main

    assert main(["keys", str(tmp_path / "k"), "paper", "--swarm", "field"]) == 0
    files = {f.name: f for f in (tmp_path / "k" / "h0").iterdir()}  # one host: all processes
    assert {"ca.pem", "acl.json", "mavlink-secret.bin", "launcher.json",
            "follower-3.json", "target-1.key", "router-0.json", "follower-3.mavlink-key.bin",
            "target-1.mavlink-key.bin"} <= set(files)
    assert "ca.key" not in files and (tmp_path / "k" / "operator" / "ca.key").is_file()
    assert all(stat.S_IMODE(f.stat().st_mode) == 0o600 for f in files.values())
    ident = Identity.load(files["follower-3.json"])
    acl = ident.acl()
    assert "enclose/field/follower/3/state" in json.dumps(acl)
