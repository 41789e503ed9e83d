"""`enclose keys`: one folder per host holding only what its processes need, the CA key with
the operator; `enclose host --credentials` refuses a folder with the CA key or missing a
file (deploy.hosts.host_keys)."""

from __future__ import annotations

import json
import shutil
import stat
from pathlib import Path

import pytest

from deploy.cli import main
from deploy.hosts.deployment import Deployment, HostSpec, dump_deployment
from deploy.hosts.host_keys import (
    ACL_FILE,
    CA_KEY,
    OPERATOR,
    HostSecrets,
    check_folder,
    host_acl,
    host_names,
    needed_files,
    write_swarm_keys,
)
from errors import ConfigError
from transport.credentials import Identity

pytestmark = pytest.mark.timeout(60)
DEP = Deployment("field", "paper", (
    HostSpec("ground", "10.0.0.1", ("launcher", "sim", "recorder", "target-0", "target-1")),
    HostSpec("drone-a", "10.0.0.2", ("follower-0", "follower-1")),
    HostSpec("drone-b", "10.0.0.3", ("follower-2", "follower-3"))))


@pytest.fixture(scope="module")
def keys(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("keys") / "creds"
    write_swarm_keys(out, DEP, 4, 2)
    return out


def test_each_host_holds_exactly_what_its_processes_are_given(keys: Path) -> None:
    operator = keys / OPERATOR
    assert (operator / CA_KEY).is_file()
    assert sorted(p.name for p in keys.iterdir()) == sorted([OPERATOR, "ground", "drone-a",
                                                             "drone-b"])
    for k, host in enumerate(DEP.hosts):
        folder = keys / host.name
        held = {p.name for p in folder.iterdir()}
        ours = {f for name in host_names(DEP, k) for f in needed_files(operator, name)}
        theirs = {f for j in range(len(DEP.hosts)) if j != k
                  for name in host_names(DEP, j) for f in needed_files(operator, name)}
        assert held == ours, host.name
        assert CA_KEY not in held
        # Nothing given only to another host's processes: their keys, certificates, and
        # MAVLink material that is not also ours (the simulator's secret, other vehicles').
        assert not held & (theirs - ours), host.name
        assert stat.S_IMODE(folder.stat().st_mode) == 0o700
        assert all(stat.S_IMODE((folder / f).stat().st_mode) == 0o600 for f in held)
        for f in held - {ACL_FILE}:  # copies of the operator's files, not new ones
            assert (folder / f).read_bytes() == (operator / f).read_bytes()
        # but the ACL, the host's own (transport.access.relayed_keys)
        assert json.loads((folder / ACL_FILE).read_text()) == host_acl(DEP, k, 4, 2)
    drone_a = {p.name for p in (keys / "drone-a").iterdir()}
    assert {"follower-0.key", "follower-1.json", "router-1.key", "ca.pem", "acl.json"} <= drone_a
    assert not {"follower-2.key", "sim.json", "target-0.key", "router-0.key"} & drone_a


def test_a_host_folder_is_a_working_identity_for_its_processes(keys: Path) -> None:
    secrets = HostSecrets.of(DEP, (1, 2), {1: keys / "drone-a", 2: keys / "drone-b"})
    args = secrets.args_for("follower-2")
    assert args[1] == str((keys / "drone-b" / "follower-2.json").resolve())
    ident = secrets.identity("router-1")
    assert isinstance(ident, Identity) and ident.name == "router-1"
    assert Path(ident.key_path).parent == (keys / "drone-a").resolve()
    assert "enclose/field/follower/2/state" in str(ident.acl())


def test_a_folder_with_the_ca_key_or_missing_a_file_is_refused(keys: Path,
                                                               tmp_path: Path) -> None:
    leaky = tmp_path / "leaky"
    shutil.copytree(keys / "drone-a", leaky)
    shutil.copy(keys / OPERATOR / CA_KEY, leaky / CA_KEY)
    with pytest.raises(ConfigError, match=r"ca\.key"):
        check_folder(leaky, host_names(DEP, 1), "drone-a")
    wrong = tmp_path / "wrong"
    shutil.copytree(keys / "drone-a", wrong)
    (wrong / "follower-1.key").unlink()
    with pytest.raises(ConfigError, match=r"follower-1\.key \(follower-1\)"):
        check_folder(wrong, host_names(DEP, 1), "drone-a")
    with pytest.raises(ConfigError, match="follower-2"):  # another host's folder
        check_folder(keys / "drone-a", host_names(DEP, 2), "drone-b")
    with pytest.raises(ConfigError, match=r"ca\.key"):  # the whole output: operator's too
        check_folder(keys / OPERATOR, host_names(DEP, 1), "drone-a")
    with pytest.raises(ConfigError, match="looks like this host's folder"):
        outer = tmp_path / "outer"
        shutil.copytree(keys / "drone-b", outer / "drone-b")
        check_folder(outer, host_names(DEP, 2), "drone-b")
    assert check_folder(keys / "drone-b", host_names(DEP, 2), "drone-b").is_dir()


def test_enclose_keys_command_from_a_deployment_file_or_a_host_count(tmp_path: Path) -> None:
    dep_file = tmp_path / "dep.toml"
    dep_file.write_text(dump_deployment(DEP))
    assert main(["keys", str(tmp_path / "a"), "--deployment", str(dep_file)]) == 0
    assert {p.name for p in (tmp_path / "a").iterdir()} == {OPERATOR, "ground", "drone-a",
                                                            "drone-b"}
    assert main(["keys", str(tmp_path / "b"), "--deployment", str(dep_file),
                 "--swarm", "other"]) == 2  # the file says "field"
    assert not (tmp_path / "b").exists()
    assert main(["keys", str(tmp_path / "c"), "paper", "--routers", "3"]) == 0
    hosts = sorted(p.name for p in (tmp_path / "c").iterdir() if p.name != OPERATOR)
    assert hosts == ["h0", "h1", "h2"]  # `enclose run --hosts 3`'s split and names
    assert (tmp_path / "c" / "h0" / "sim.json").is_file()
    assert not (tmp_path / "c" / "h1" / "sim.json").exists()


@pytest.mark.realtime
def test_enclose_host_refuses_a_folder_with_the_ca_key_before_starting_anything(
        keys: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    dep_file = tmp_path / "dep.toml"
    dep_file.write_text(dump_deployment(DEP))
    leaky = tmp_path / "drone-b"
    shutil.copytree(keys / "drone-b", leaky)
    shutil.copy(keys / OPERATOR / CA_KEY, leaky / CA_KEY)
    run = tmp_path / "run"
    argv = ["host", str(dep_file), "--host", "drone-b", "--out", str(run), "--credentials"]
    assert main([*argv, str(leaky)]) == 2
    assert "holds the swarm CA's private key" in caplog.text
    assert main([*argv, str(keys)]) == 2  # the whole output, not the host's folder
    assert "drone-b looks like this host's folder" in caplog.text
    assert not (run / "logs").exists()  # nothing was started
