"""MAVLink signing keys: the key file, and a key per vehicle derived from a run secret.

Vehicle `sysid`'s key:

    passphrase = hex(HMAC-SHA256(run secret, "enclose-mavlink-vehicle-<sysid>"))
    key        = SHA-256(passphrase)

so that whoever holds the secret (the simulator, an operator's ground station) holds every
vehicle's key, each agent only its own, and the key is also what MAVProxy's `signing key
<passphrase>` makes of the passphrase (it hashes passphrases with SHA-256).
"""

from __future__ import annotations

import os
from pathlib import Path

from agents.mavlink.digest import sha256
from errors import ConfigError

KEY_LEN = 32
VEHICLE_KEY_LABEL = "enclose-mavlink-vehicle-{sysid}"


def write_key(path: Path) -> bytes:
    """A fresh random 32-byte key, written raw to `path` with 0600 rights from the start."""
    key = os.urandom(KEY_LEN)
    write_raw_key(path, key)
    return key


def key_from_passphrase(passphrase: str) -> bytes:
    """MAVProxy's `signing setup <passphrase>` key: sha256 of the passphrase."""
    return sha256(passphrase.encode()).digest()


def vehicle_passphrase(run_secret: bytes, sysid: int) -> str:
    """Vehicle `sysid`'s signing passphrase (64 hex digits): what a ground station is given."""
    if not 1 <= sysid <= 255:
        raise ConfigError("sysid", f"a MAVLink system id is 1..255, got {sysid}")
    import hmac  # OpenSSL, loaded only where keys are derived (digest.py)

    label = VEHICLE_KEY_LABEL.format(sysid=sysid).encode()
    return hmac.new(run_secret, label, "sha256").hexdigest()


def vehicle_key(run_secret: bytes, sysid: int) -> bytes:
    """Vehicle `sysid`'s 32-byte signing key, derived from the run secret (module docstring)."""
    return key_from_passphrase(vehicle_passphrase(run_secret, sysid))


def agent_of_vehicle(sysid: int, n: int) -> str:
    """The agent that flies vehicle `sysid` of a swarm of n followers, and alone holds its
    key: follower i flies vehicle i (sysid i+1), target j vehicle n+j (sysid n+j+1)."""
    return f"follower-{sysid - 1}" if sysid <= n else f"target-{sysid - 1 - n}"


def write_raw_key(path: Path, key: bytes) -> None:
    """`key` written raw to `path`, 0600 from the start."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as out:
        out.write(key)
    os.chmod(path, 0o600)


def load_key(path: str | Path) -> bytes:
    """The 32 raw bytes of a key file; an all-zero key would disable signing: refused."""
    try:
        key = Path(path).read_bytes()
    except OSError as exc:
        raise ConfigError("signing_key", f"{path}: {exc.strerror}") from exc
    if len(key) != KEY_LEN:
        raise ConfigError("signing_key", f"{path} holds {len(key)} bytes, a key is {KEY_LEN}")
    if not any(key):
        raise ConfigError("signing_key", f"{path} is all zeros (that disables signing)")
    return key
