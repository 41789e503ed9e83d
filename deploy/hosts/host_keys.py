"""A swarm's credentials for several hosts: one folder per host, the CA key with the operator.

`enclose keys OUT_DIR` writes

    OUT_DIR/operator/   everything, the CA's private key (`ca.key`, to add hosts later) and
                        the MAVLink secret included: keep it offline, copy it nowhere
    OUT_DIR/<host>/     what the processes the deployment places on <host> need, and its
                        router: the CA certificate, the host's ACL, their own
                        certificates and keys, and their own MAVLink key material; nothing
                        of another host's processes, never the CA key

A host folder holds exactly the files `RunSecrets.args_for` hands its processes (and the
files their identity files name): what a process is given is decided there, once, and a
host gets no more.  So a host that does not run the simulator gets no MAVLink secret
that the simulator alone is given.  Each host's ACL is its own: another host's router
may bring its processes only what that host's processes may put (transport.access), so
a folder's router key relays nothing of another host's.  `enclose host --credentials
DIR` checks its folder (`check_folder`): a CA key in it, or a missing file, is refused.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from deploy.hosts.deployment import Deployment
from deploy.launch.run_secrets import RunSecrets, write_mavlink_keys
from errors import ConfigError
from transport.access import access_control
from transport.credentials import Identity, identity_file, make_credentials
from transport.key_exprs import SwarmKeys

log = logging.getLogger("enclose.keys")
OPERATOR = "operator"
CA_KEY = "ca.key"
ACL_FILE = "acl.json"
IDENTITY_FILES = ("ca", "cert", "key", "acl")  # the files an identity file names
SHOW_MISSING = 6  # missing files named in the error


def host_names(dep: Deployment, k: int) -> list[str]:
    """The identities host k's part of the swarm uses: its processes and its router."""
    return [*dep.hosts[k].processes, f"router-{k}"]


def needed_files(folder: Path, name: str) -> list[str]:
    """The files (names in `folder`) process `name` is given: those its arguments name,
    and those its identity file names (as written there, or as `enclose keys` names them
    if it is missing)."""
    out: list[str] = []
    for value in RunSecrets(folder).args_for(name)[1::2]:
        path = Path(value)
        if path.parent == folder and path.name not in out:
            out.append(path.name)
    ident = identity_file(folder, name)
    try:
        raw = json.loads(ident.read_text())
        named = [raw[k] for k in IDENTITY_FILES]
    except (OSError, ValueError, KeyError, TypeError):
        named = ["ca.pem", f"{name}.pem", f"{name}.key", "acl.json"]
    out += [n for n in named if isinstance(n, str) and n not in out]
    return out


def _copy_private(src: Path, dst: Path) -> None:
    fd = os.open(dst, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as out:
        out.write(src.read_bytes())
    os.chmod(dst, 0o600)


def write_swarm_keys(out_dir: Path, dep: Deployment, n: int, m: int,
                     keep_ca_key: bool = True) -> dict[str, Path]:
    """The operator's full set and one folder per host of `dep` under `out_dir`; the host
    folders by host name."""
    out_dir.mkdir(parents=True, exist_ok=True)
    os.chmod(out_dir, 0o700)
    operator = make_credentials(out_dir / OPERATOR, SwarmKeys(dep.swarm), n, m,
                                keep_ca_key=keep_ca_key, n_routers=len(dep.hosts))
    write_mavlink_keys(operator, n, m)
    folders: dict[str, Path] = {}
    for k, host in enumerate(dep.hosts):
        if host.name == OPERATOR:
            raise ConfigError("deployment.hosts.name", f"{OPERATOR!r} is the operator's folder")
        folder = folders[host.name] = out_dir / host.name
        folder.mkdir(exist_ok=True)
        os.chmod(folder, 0o700)
        for name in host_names(dep, k):
            for f in needed_files(operator, name):
                _copy_private(operator / f, folder / f)
        _write_acl(folder / ACL_FILE, host_acl(dep, k, n, m))
    return folders


def host_acl(dep: Deployment, k: int, n: int, m: int) -> dict[str, object]:
    """The ACL of host k's processes: another host's router brings them only what that
    host's own processes may put (transport.access.relayed_keys)."""
    return access_control(SwarmKeys(dep.swarm), n, m, len(dep.hosts),
                          hosts=[h.processes for h in dep.hosts], here=k)


def _write_acl(path: Path, acl: dict[str, object]) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as out:
        json.dump(acl, out, indent=1)


def check_folder(folder: Path, names: Iterable[str], host: str) -> Path:
    """`folder` as host `host`'s credentials for processes `names`: refused (ConfigError)
    if it holds the CA key or misses a file one of them needs; the resolved folder."""
    folder = folder.resolve()
    if not folder.is_dir():
        raise ConfigError("--credentials", f"{folder} is not a folder")
    if (folder / CA_KEY).exists():
        raise ConfigError("--credentials", f"{folder} holds the swarm CA's private key "
                          f"({CA_KEY}): it stays with the operator (`enclose keys OUT_DIR` "
                          f"keeps it in OUT_DIR/{OPERATOR}/); give host {host} only "
                          f"OUT_DIR/{host}/")
    missing: dict[str, str] = {}  # file -> the first process that needs it
    for name in names:
        for f in needed_files(folder, name):
            if not (folder / f).is_file():
                missing.setdefault(f, name)
    if missing:
        shown = [f"{f} ({name})" for f, name in list(missing.items())[:SHOW_MISSING]]
        more = len(missing) - len(shown)
        hint = (f"; {folder / host} looks like this host's folder"
                if (folder / host).is_dir() else "")
        raise ConfigError("--credentials", f"{folder} is not host {host}'s credentials: "
                          f"missing {', '.join(shown)}{f' and {more} more' if more else ''}"
                          f"{hint}")
    return folder


@dataclass(frozen=True)
class HostSecrets(RunSecrets):
    """A run's secrets over hosts: each process's from its own host's folder."""

    folders: Mapping[str, Path] = field(default_factory=dict)  # process name -> folder

    @classmethod
    def of(cls, dep: Deployment, local: Iterable[int], folders: Mapping[int, Path]) -> HostSecrets:
        """The checked folders of the hosts `local`, by host index."""
        by_name: dict[str, Path] = {}
        for k in local:
            names = host_names(dep, k)
            folder = check_folder(folders[k], names, dep.hosts[k].name)
            by_name.update(dict.fromkeys(names, folder))
        return cls(next(iter(by_name.values()), None), by_name)

    def identity(self, name: str) -> Identity | None:
        return RunSecrets(self.folders[name]).identity(name)

    def args_for(self, name: str) -> list[str]:
        return RunSecrets(self.folders[name]).args_for(name)
