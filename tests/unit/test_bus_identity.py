"""Statuses tied to the process they name; keys parsed totally; what is refused, counted."""

from __future__ import annotations

import logging

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from deploy.launch.status_board import StatusBoard
from deploy.report.refusals import launch_refusals, refusal_text, refusals
from transport.access import own_keys, process_names, sender_id, sender_ids
from transport.bus import Received
from transport.codec import encode
from transport.decoder import Decoder
from transport.key_exprs import KeyInfo, SwarmKeys, parse_key
from transport.memory_bus import MemoryBus, MemoryHub
from transport.message_checks import key_reason, key_rule
from transport.messages import FollowerState, Header, ProcessStatus, RunControl, TruthSnapshot
from transport.ratelog import RateLimitedLog

pytestmark = pytest.mark.timeout(120)
KEYS = SwarmKeys("idt")
N, M = 4, 2
SENDERS = sender_ids(N, M)
NOW = 1_800_000_000.0


def status(sender: str, role: str, index: int, seq: int = 0, **counters: int) -> ProcessStatus:
    return ProcessStatus(Header(sender, seq, NOW), role, index, "running", counters)


def rec(key: str, msg: object, stamp_s: float = NOW) -> Received:
    return Received(key, encode(msg), stamp_s)  # type: ignore[arg-type]


# ---- keys ------------------------------------------------------------------------------
def rebuilt(info: KeyInfo) -> str:
    keys = SwarmKeys(info.swarm)
    if info.kind in ("truth", "control"):
        return f"{keys.prefix}/{info.kind}"
    assert info.index is not None and info.role is not None
    if info.kind == "sensor":
        return keys.sensor_targets(info.index)
    if info.kind == "follower":
        return ""  # two suffixes: checked by the caller
    return f"{keys.prefix}/{info.kind}/{info.role}/{info.index}"


chunk = st.text(min_size=0, max_size=12) | st.sampled_from(
    ["follower", "sim", "0", "3", "9", "03", "-1", "²", "٣", "1\n", "4294967296", "9" * 400,
     "state", "est", "targets", "alive", "status", "*", "**", ""])
swarm_keys = st.lists(chunk, min_size=0, max_size=6).map(
    lambda cs: "/".join(["enclose", "idt", *cs]))
any_text = st.text() | st.binary().map(lambda b: b.decode("utf-8", "surrogateescape"))


@settings(max_examples=400, deadline=None)
@given(swarm_keys | any_text)
def test_parse_key_is_total_and_gives_one_spelling_per_index(key: str) -> None:
    info = parse_key(key)  # never raises
    if info is None:
        return
    assert info.index is None or 0 <= info.index < 10**9
    if info.kind == "follower":
        assert key in (KEYS.follower_state(info.index or 0).replace("idt", info.swarm, 1),
                       KEYS.follower_estimate(info.index or 0).replace("idt", info.swarm, 1))
    else:
        assert key == rebuilt(info)


@pytest.mark.parametrize("key", [
    "enclose/idt/alive/follower/²", "enclose/idt/alive/follower/٣", "enclose/idt/alive/follower/-1",
    "enclose/idt/alive/follower/01", "enclose/idt/alive/follower/" + "9" * 5000,
    "enclose/idt/alive/follower/1\n", "enclose/idt/follower/1/other", "enclose/idt/alive/a b/1",
    "enclose/id t/truth", "enclose/idt/status/sim/0/x"])
def test_malformed_keys_parse_to_nothing(key: str) -> None:
    assert parse_key(key) is None


# ---- statuses on their own key, from the process they name ------------------------------
def test_a_status_counts_only_on_its_own_key_from_the_process_it_names() -> None:
    dec = Decoder(limits=None, senders=SENDERS)
    sim_key = KEYS.status("sim", 0)
    assert dec.decode(rec(sim_key, status("sim-0", "sim", 0))) is not None
    own = KEYS.status("follower", 2)
    assert dec.decode(rec(own, status("sim-0", "sim", 0))) is None  # as the sim, on its own key
    assert dec.decode(rec(own, status("follower-2", "sim", 0))) is None
    assert dec.decode(rec(own, status("follower-2", "follower", 1))) is None
    assert dec.decode(rec(KEYS.status("role7", 0), status("role7-0", "role7", 0))) is None
    assert dec.decode(rec(KEYS.status("follower", 9), status("follower-9", "follower", 9))) \
        is None
    assert dec.decode(rec(own, TruthSnapshot(Header("follower-2", 1, NOW), 0.0, (), (), (),
                                                  ()))) is None  # no truth on a status key
    c = dec.counters()
    assert c["drop_key_mismatch"] == 3 and c["drop_unknown_sender"] == 2
    assert c["drop_wrong_key"] == 1 and c["statuses_rejected"] == 6
    assert c["rejected_from_follower-2"] == 4 and c["accepted"] == 1


def test_with_limits_the_sender_must_be_the_keys_owner() -> None:
    board = StatusBoard(SENDERS)
    forged = rec(KEYS.status("sim", 0), status("follower-2", "sim", 0))
    assert board.decoder.decode(forged) is None
    assert board.decoder.dropped == {"rejected_sender": 1}
    assert board.decoder.counters()["rejected_from_sim-0"] == 1  # the key's owner: ACL-bound


def test_a_control_word_on_a_follower_key_is_refused() -> None:
    """A process holding its own state key cannot stop its neighbours through it."""
    stop = RunControl(Header("follower-2", 0, NOW), "stop", NOW, 0.0)
    assert key_reason(stop, KEYS.follower_state(2)) == "wrong_key"
    assert key_reason(stop, KEYS.control()) is None
    dec = Decoder(senders=SENDERS)
    assert dec.decode(rec(KEYS.follower_state(2), stop)) is None
    assert dec.counters()["states_rejected"] == 1


names = st.sampled_from([*sorted(SENDERS), "follower-4", "follower-99", "evil-0", "sim-1"])
roles = st.sampled_from(["sim", "follower", "target", "recorder", "launcher", "evil", "r2"])
idx = st.integers(0, 6)
event = st.tuples(roles, idx, names, roles, idx, st.integers(0, 3))


@settings(max_examples=150, deadline=None)
@given(st.lists(event, max_size=40))
def test_status_table_is_bounded_and_no_status_changes_another_identity(
        events: list[tuple[str, int, str, str, int, int]]) -> None:
    """Any statuses from anyone, on any status key: the board holds at most one entry per
    process of the scenario, each only ever from that process on its own key."""
    hub = MemoryHub()
    with MemoryBus(hub) as out, MemoryBus(hub) as board_bus:
        board = StatusBoard(SENDERS)
        board.subscription = board_bus.subscribe(KEYS.all_status())
        seqs: dict[str, int] = {}
        for key_role, key_idx, sender, role, index, mark in events:
            key_owner = f"{key_role}-{key_idx}"
            before = dict(board.latest)
            seq = seqs[sender] = seqs.get(sender, -1) + 1
            msg = status(sender, role, index, seq, mark=mark)
            out.publish(KEYS.status(key_role, key_idx), encode(msg))
            board.collect()
            assert len(board.latest) <= len(SENDERS) and set(board.latest) <= SENDERS
            for name, entry in board.latest.items():
                assert entry.header.sender_id == name == f"{entry.role}-{entry.index}"
            for name in set(before) | set(board.latest):
                if name != key_owner:  # only the key's own process may change its entry
                    assert board.latest.get(name) == before.get(name)


def test_the_codec_bounds_a_status_counters_in_number_and_name_length() -> None:
    dec = Decoder(senders=SENDERS)
    key = KEYS.status("follower", 1)
    ok = status("follower-1", "follower", 1, **{f"c{k}": k for k in range(200)})
    assert dec.decode(rec(key, ok)) is not None
    many = {f"c{k}": k for k in range(300)}
    long = {"x" * 300: 1}
    import msgpack

    for counters in (many, long):
        raw = msgpack.unpackb(encode(ok))
        raw[8] = counters
        assert dec.decode(Received(key, bytes(msgpack.packb(raw)), NOW)) is None
    assert dec.counters()["statuses_rejected"] == 2


# ---- visible ----------------------------------------------------------------------------
def test_refusals_are_logged_at_most_once_a_period_per_reason(
        caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    dec = Decoder(senders=SENDERS)
    dec.log = RateLimitedLog(logging.getLogger("enclose.bus"), 10.0, lambda: now[0])
    forged = rec(KEYS.status("follower", 2), status("follower-2", "sim", 0))
    with caplog.at_level(logging.WARNING, "enclose.bus"):
        for _ in range(500):
            dec.decode(forged)
        now[0] = 10.5
        dec.decode(forged)
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2 and dec.dropped["key_mismatch"] == 501
    assert "follower-2" in lines[0] and "'sim-0'" in lines[0] and "key_mismatch" in lines[0]
    assert "499 more" in lines[1]


def test_refusals_sum_over_processes_and_name_the_senders() -> None:
    launch = {"status": {
        "follower-0": {"state": "done", "statuses_rejected": 3, "rejected_from_follower-2": 3,
                       "tokens_rejected": 2},
        "recorder-0": {"state": "done", "statuses_rejected": 5, "observations_rejected": 1,
                       "rejected_from_follower-2": 5, "rejected_from_sim-0": 1}},
        "launcher": {"statuses_rejected": 4, "rejected_from_follower-2": 4}}
    summed = launch_refusals(launch)
    assert summed == {"statuses": 12, "observations": 1, "tokens": 2,
                      "from": {"follower-2": 12, "sim-0": 1},
                      "seen_by": {"follower-2": 3, "sim-0": 1}}
    assert refusal_text(summed) == ("refused 12 statuses, 1 observations, 2 tokens "
                                    "(from follower-2 12 seen by 3, sim-0 1 seen by 1)")
    assert refusals({"a": {"state": "done"}, "b": {"x": True}}) == {}
    assert refusal_text({}) is None


def test_a_follower_state_index_must_be_its_keys() -> None:
    z = (0.0, 0.0)
    msg = FollowerState(Header("follower-1", 0, NOW), 1, z, z, z, z, z, NOW)
    assert key_reason(msg, KEYS.follower_state(1)) is None
    assert key_reason(msg, KEYS.follower_estimate(1)) is None
    assert key_reason(msg, KEYS.follower_state(2)) == "key_mismatch"
    assert key_reason(msg, KEYS.sensor_targets(1)) == "wrong_key"
    assert key_reason(msg, "elsewhere/x") is None  # not a swarm key: not ours to judge


def test_the_access_control_and_the_checks_name_the_same_owner_for_every_key() -> None:
    """With mTLS + ACL a key is put only by the identity the ACL gives it (transport.access);
    the checks' owner of that key must be the same process, or a forgery on its own key
    could pass for another."""
    for name in process_names(N, M):
        for key in own_keys(KEYS, name, N):
            info = parse_key(key)
            assert info is not None
            owner = key_rule(key).owner  # type: ignore[union-attr]
            assert owner == sender_id(name), (name, key)
            if info.kind in ("status", "alive"):
                assert f"{info.role}-{info.index}" == sender_id(name)
