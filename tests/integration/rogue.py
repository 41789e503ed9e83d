"""A hostile process for the security tests (issue #12's attack), run as its own OS process.

    python -m tests.integration.rogue --vehicle-port P --agent-port A --vehicles N \
        --endpoint E --swarm S --followers N --fuzz-identity FILE --fuzz-count K \
        --seconds T --out report.json

- MAVLink: unsigned COMMAND_LONG force-disarm and NAV_LAND to every vehicle port every 0.2 s;
  counts what it sent and every COMMAND_ACK it got back.  Forged telemetry to every agent's
  port in the vehicle's name (HEARTBEAT disarmed, LOCAL_POSITION_NED 700 m away), as often.
- Zenoh without credentials: a plain peer connecting to the swarm's endpoint, publishing
  forged follower states on every follower key at 50 Hz; records whether it ever linked.
- Zenoh with follower j's certificate (`--fuzz-identity`; in an --insecure run none, and j
  is `--follower`): K random and mutated payloads on
  follower j's state key, all of them invalid (garbage, wrong types, wrong sender or index,
  non-finite, impossible or future-stamped values), paced over the run; and forged states on
  follower j+1's key, which its rights do not cover.
- Tokens (part `tokens`): the identity part's tokens alone (for an --insecure run, where
  nothing stops them before the receivers).
- Identity (part `identity`, with follower j's certificate): statuses forged as the
  simulator, on the simulator's key and on follower j's own; 2000 made-up roles, on keys
  of their own and on follower j's; a "stop" word on follower j's state key; liveliness
  tokens out of range or malformed, and follower j's own token declared and withdrawn
  again and again.  Every forged status carries a `forged` counter.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import socket
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import msgpack

from agents.mavlink.wire import new_codec
from agents.mavlink.wire_decode import decode_datagram
from transport.bus import Congestion
from transport.codec import encode
from transport.credentials import Identity
from transport.key_exprs import SwarmKeys
from transport.messages import FollowerState, Header, ProcessStatus, RunControl
from transport.zenoh_bus import ZenohBus
from transport.zenoh_config import ZenohConfig

ARM_DISARM, NAV_LAND, FORCE = 400, 21, 21196.0
PARTS = os.environ.get("ROGUE_PARTS", "mav,plain,insider")
ROLES = 2000
BAD_TOKENS = ("9", "4", "123456789", "99999999999", "-1", "01", "\u00b2", "\u0663")


def forged_state(i: int, seq: int, **kw: object) -> FollowerState:
    f: dict[str, object] = dict(r_m=(500.0, -500.0), dr_m_s=(0.0, 0.0),
                                pos_m=(500.0, -500.0), vel_m_s=(0.0, 0.0), u_m_s=(0.0, 0.0),
                                vehicle_stamp_s=time.time())
    f.update(kw)
    stamp = float(f.pop("stamp_s", time.time()))  # type: ignore[arg-type]
    sender = str(f.pop("sender", f"follower-{i}"))
    return FollowerState(Header(sender, seq, stamp), i, **f)  # type: ignore[arg-type]


def fuzz_payload(rng: random.Random, j: int, seq: int) -> bytes:
    """One invalid payload for follower j's key (each kind is refused by every receiver)."""
    kind = rng.randrange(8)
    if kind == 0:
        return rng.randbytes(rng.randrange(0, 200))
    if kind == 1:
        good = msgpack.unpackb(encode(forged_state(j, seq)))
        good[rng.randrange(len(good))] = rng.choice([None, "x", [1], {"a": 1}, b"\x00", True])
        return bytes(msgpack.packb(good))
    if kind == 2:
        return encode(forged_state(j, seq, sender=f"follower-{j + 1}"))
    if kind == 3:
        return encode(forged_state(j + 1, seq))  # index does not match the key
    if kind == 4:  # the codec refuses to encode a NaN: write it in by hand
        good = msgpack.unpackb(encode(forged_state(j, seq)))
        good[6] = [float("nan"), 0.0]
        return bytes(msgpack.packb(good))
    if kind == 5:
        return encode(forged_state(j, seq, pos_m=(1e9, 0.0)))
    if kind == 6:
        return encode(forged_state(j, seq, stamp_s=time.time() + 1e6))
    data = bytearray(encode(forged_state(j, seq)))
    return bytes(data[: rng.randrange(1, len(data))])  # truncated


def attack_mavlink(sock: socket.socket, ports: list[int], report: dict[str, int]) -> None:
    mav = new_codec(250, 190)
    for k, port in enumerate(ports):
        for cmd, p1, p2 in ((ARM_DISARM, 0.0, FORCE), (NAV_LAND, 0.0, 0.0)):
            msg = mav.command_long_encode(k + 1, 1, cmd, 0, p1, p2, 0, 0, 0, 0, 0)
            sock.sendto(msg.pack(mav), ("127.0.0.1", port))
            report["mavlink_unsigned_sent"] += 1
    while True:
        try:
            data = sock.recv(65535)
        except BlockingIOError:
            return
        acks = [m for m in decode_datagram(mav, data).messages if m.get_type() == "COMMAND_ACK"]
        report["mavlink_acks"] += len(acks)


def forge_telemetry(sock: socket.socket, ports: list[int], report: dict[str, int]) -> None:
    """Unsigned telemetry in each vehicle's name (sysid k + 1, component 1) to its agent."""
    for k, port in enumerate(ports):
        mav = new_codec(k + 1, 1)
        frames = (mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav),  # PX4 quadrotor, disarmed
                  mav.local_position_ned_encode(0, 500.0, -500.0, -10.0, 5.0, 5.0, 0.0).pack(mav))
        for frame in frames:
            sock.sendto(frame, ("127.0.0.1", port))
            report["telemetry_forged_sent"] += 1


def wait_running(progress: Path, timeout_s: float = 90.0) -> None:
    """Until the recorder says the experiment runs (the attack is to hit a flying swarm)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError, ValueError):
            if json.loads(progress.read_text()).get("state") == "running":
                return
        time.sleep(0.1)
    raise SystemExit(f"{progress}: the run never started")


def forged_status(sender: str, role: str, index: int, seq: int) -> bytes:
    return encode(ProcessStatus(Header(sender, seq, time.time()), role, index, "failed",
                                {"forged": 1, "ticks": 10**9}, "forged"))


class TokenAttack:
    """Liveliness tokens out of range and malformed, declared once, and follower j's own
    token declared and withdrawn at every `step`, beside the real follower j's."""

    def __init__(self, bus: ZenohBus, keys: SwarmKeys, j: int, report: dict[str, int]) -> None:
        self.bus, self.key, self.report = bus, keys.alive("follower", j), report
        self.bad = [bus.declare_token(f"{keys.prefix}/alive/follower/{t}") for t in BAD_TOKENS]
        report["tokens_declared"] = len(self.bad)
        self.flap: object | None = None

    def step(self) -> None:
        if self.flap is None:
            self.flap = self.bus.declare_token(self.key)
        else:
            self.flap.close()  # type: ignore[attr-defined]
            self.flap = None
        self.report["token_flaps"] += 1


class IdentityAttack:
    """Follower j's certificate used to pass for others (see the module docstring); one
    `step` every 0.2 s spreads the made-up roles over the attack."""

    def __init__(self, bus: ZenohBus, keys: SwarmKeys, j: int, report: dict[str, int]) -> None:
        self.bus, self.keys, self.j, self.report = bus, keys, j, report
        self.own = bus.declare_publisher(keys.status("follower", j), Congestion.BLOCK)
        self.tokens = TokenAttack(bus, keys, j, report)
        self.seq = 0

    def step(self) -> None:
        keys, r = self.keys, self.report
        self.seq += 1
        self.bus.publish(keys.status("sim", 0), forged_status("sim-0", "sim", 0, self.seq))
        r["statuses_forged_other_keys"] += 1
        for sender in ("sim-0", f"follower-{self.j}"):
            self.own.put(forged_status(sender, "sim", 0, self.seq))
            r["statuses_forged_own_key"] += 1
        for _ in range(ROLES // 80):  # all 2000 in the first 16 s
            if r["roles_sent"] >= ROLES:
                break
            role = f"role{r['roles_sent']}"
            self.bus.publish(keys.status(role, 0), forged_status(f"{role}-0", role, 0, 0))
            self.own.put(forged_status(f"follower-{self.j}", role, 0, self.seq))
            r["roles_sent"] += 1
            r["statuses_forged_own_key"] += 1
            r["statuses_forged_other_keys"] += 1
        stop = RunControl(Header(f"follower-{self.j}", self.seq, time.time()), "stop",
                          time.time(), 0.0)
        self.bus.publish(keys.follower_state(self.j), encode(stop))
        r["control_forged_sent"] += 1
        self.tokens.step()


def run(args: argparse.Namespace) -> dict[str, int]:
    keys, rng = SwarmKeys(args.swarm), random.Random(12)
    report = dict.fromkeys(("mavlink_unsigned_sent", "mavlink_acks", "plain_published",
                            "plain_linked", "fuzz_sent", "fuzz_out_of_rights_sent",
                            "telemetry_forged_sent", "statuses_forged_own_key",
                            "statuses_forged_other_keys", "roles_sent", "control_forged_sent",
                            "token_flaps"), 0)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    ports = [args.vehicle_port + k for k in range(args.vehicles)]
    agent_ports = [args.agent_port + k for k in range(args.vehicles)]
    # Without a certificate (an --insecure run) it passes for follower `--follower`.
    ident = None if args.fuzz_identity is None else Identity.load(args.fuzz_identity)
    j = args.follower if ident is None else int(ident.name.rsplit("-", 1)[1])
    with ZenohBus(ZenohConfig(connect=(args.endpoint,))) as plain, \
            ZenohBus(ZenohConfig(connect=(args.endpoint,), identity=ident)) as insider:
        # BLOCK: every payload leaves (an attacker picks what suits it, not the default).
        fuzz_pub = insider.declare_publisher(keys.follower_state(j), Congestion.BLOCK)
        wait_running(Path(args.progress))
        identity: IdentityAttack | TokenAttack | None = None
        if "identity" in PARTS:
            identity = IdentityAttack(insider, keys, j, report)
        elif "tokens" in PARTS:
            identity = TokenAttack(insider, keys, j, report)
        t0 = time.monotonic()
        next_attack = t0
        while (elapsed := time.monotonic() - t0) < args.seconds:
            if time.monotonic() >= next_attack:
                next_attack += 0.2
                if "mav" in PARTS:
                    attack_mavlink(sock, ports, report)
                    forge_telemetry(sock, agent_ports, report)
                if identity is not None:
                    identity.step()
                if "plain" in PARTS:
                    for i in range(args.followers):
                        plain.publish(keys.follower_state(i), encode(forged_state(i, 0)))
                        report["plain_published"] += 1
                    report["plain_linked"] |= int(bool(plain.peers()))
                if "insider" in PARTS:
                    other = (j + 1) % args.followers
                    insider.publish(keys.follower_state(other), encode(forged_state(other, 0)))
                    report["fuzz_out_of_rights_sent"] += 1
            if "insider" not in PARTS:
                time.sleep(0.02)
                continue
            due = min(args.fuzz_count, int(args.fuzz_count * elapsed / (0.9 * args.seconds)))
            while report["fuzz_sent"] < due:
                fuzz_pub.put(fuzz_payload(rng, j, report["fuzz_sent"]))
                report["fuzz_sent"] += 1
            time.sleep(0.02)  # bursts of fuzz 50 times a second: the rogue stays light
    sock.close()
    return report


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--vehicle-port", type=int, required=True)
    p.add_argument("--agent-port", type=int, required=True)
    p.add_argument("--vehicles", type=int, required=True)
    p.add_argument("--endpoint", required=True)
    p.add_argument("--swarm", required=True)
    p.add_argument("--followers", type=int, required=True)
    p.add_argument("--fuzz-identity", default=None, help="a follower's identity file")
    p.add_argument("--follower", type=int, default=0, help="the follower it passes for "
                   "without --fuzz-identity")
    p.add_argument("--fuzz-count", type=int, default=100_000)
    p.add_argument("--seconds", type=float, required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--progress", required=True, help="the run's progress.json")
    args = p.parse_args(argv)
    report = run(args)
    with open(args.out, "w") as out:
        json.dump(report, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
