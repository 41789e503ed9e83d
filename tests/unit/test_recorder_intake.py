"""The recorder's intake: samples recorded as they arrived, states decoded later.

Refusals decided on the key alone are counted at once; a state is checked and counted when
its batch is decoded, with the clock offset of when it arrived; the live view gets the
newest of each key, checked but not counted; a state is recorded as the JSON its wire array
makes, the same JSON as its decoded message's, and reads back as its wire payload; a payload
that is no wire array is not recorded, whatever it holds.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from agents.loading.scenario_file import load_scenario
from deploy.recording.intake import Intake
from deploy.recording.mcap_log import MESSAGE_ENCODING, McapLog, message_json, wire_json
from deploy.recording.resume import Recorded, read_back, read_messages
from tests.recorder_synth import SynthRun
from transport.access import sender_ids
from transport.bus import Received
from transport.codec import MAX_PAYLOAD_BYTES, decode, encode
from transport.decoder import Decoder
from transport.key_exprs import SwarmKeys
from transport.message_checks import RECORDER_LIMITS
from transport.messages import FollowerState, Header, Message
from transport.peer_clock import ClockBook

START_S = 1_700_000_000.0
KEYS = SwarmKeys("intake")


class _Offsets(ClockBook):
    """A clock book whose offsets the test sets (one peer: follower 0's host)."""

    def __init__(self) -> None:
        super().__init__()
        self.peers = {"router-1": None}  # type: ignore[dict-item]  # only its presence counts
        self.now: float | None = None

    def offset_s(self, sender_id: str) -> float | None:
        return self.now


def state(index: int, seq: int, stamp_s: float, x: float = 0.0) -> FollowerState:
    return FollowerState(Header(f"follower-{index}", seq, stamp_s), index, (x, 0.0),
                         (0.0, 0.0), (x, 1.0), (0.0, 0.0), (0.0, 0.0), stamp_s)


def make(tmp_path: Path, clocks: ClockBook | None = None) -> tuple[Intake, McapLog, Decoder]:
    n = load_scenario("paper").n
    mcap = McapLog(tmp_path / "r.mcap")
    decoder = Decoder(limits=RECORDER_LIMITS, senders=sender_ids(n, 1),
                      **({} if clocks is None else {"clocks": clocks}))
    return Intake(mcap, decoder, sender_ids(n, 1), n), mcap, decoder


def rec(key: str, msg: Message | bytes, recv_s: float = START_S + 0.01) -> Received:
    return Received(key, msg if isinstance(msg, bytes) else encode(msg), recv_s)


def test_what_the_key_alone_refuses_is_counted_at_once_and_never_recorded(
        tmp_path: Path) -> None:
    intake, mcap, decoder = make(tmp_path)
    now = intake.take([
        rec(KEYS.follower_state(9), state(9, 0, START_S)),  # no follower 9 in the paper's
        rec("elsewhere/x", b"\x90"),
        rec(KEYS.follower_state(1), b"\x90" * (MAX_PAYLOAD_BYTES + 1)),
        rec(KEYS.follower_state(0), state(0, 0, START_S)),
    ])
    mcap.close()
    assert now == []  # a state waits for its batch
    assert decoder.dropped == {"unknown_key": 2, "too_large": 1}
    assert dict(mcap.messages) == {KEYS.follower_state(0): 1}


def test_a_state_is_checked_and_counted_when_its_batch_is_decoded(tmp_path: Path) -> None:
    intake, mcap, decoder = make(tmp_path)
    forged = FollowerState(Header("follower-2", 0, START_S), 1, (0.0, 0.0), (0.0, 0.0),
                           (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), START_S)  # 2's, on 1's key
    intake.take([rec(KEYS.follower_state(0), state(0, 0, START_S)),
                 rec(KEYS.follower_state(1), forged),
                 rec(KEYS.follower_state(0), state(0, 2, START_S + 0.02))])
    assert not decoder.dropped and decoder.accepted == 0 and intake.arrivals[:2] == [2, 1]
    decoded = list(intake.decoded())
    mcap.close()
    assert [m.header.seq for m in decoded] == [0, 2]
    assert decoder.dropped == {"rejected_sender": 1}
    assert decoder.accepted == 2 and decoder.counters()["seq_gap"] == 1
    assert sum(mcap.messages.values()) == 3  # the refused one as it came: readers check
    assert list(intake.decoded()) == []  # the queue emptied


def test_a_state_is_mapped_with_the_clock_offset_of_its_arrival(tmp_path: Path) -> None:
    clocks = _Offsets()
    intake, mcap, _ = make(tmp_path, clocks)
    clocks.now = 0.25
    intake.take([rec(KEYS.follower_state(0), state(0, 0, START_S + 0.25),
                     recv_s=START_S + 0.01)])
    clocks.now = 0.0  # the estimate moved before the batch was decoded
    (msg,) = intake.decoded()
    mcap.close()
    assert msg.header.stamp_s == pytest.approx(START_S)


def test_the_view_gets_the_newest_of_each_key_checked_not_counted(tmp_path: Path) -> None:
    intake, mcap, decoder = make(tmp_path)
    intake.take([rec(KEYS.follower_state(0), state(0, k, START_S + 0.02 * k, x=k))
                 for k in range(3)])
    intake.take([rec(KEYS.follower_state(1), state(1, 0, START_S)),
                 rec(KEYS.follower_state(1), b"\xc1 garbage")])
    shown = list(intake.peek())
    assert [(m.index, m.r_m) for m, _ in shown if isinstance(m, FollowerState)] == [
        (0, (2.0, 0.0))]  # follower 1's newest is garbage: not shown
    assert not decoder.dropped and list(intake.peek()) == []  # counted with the batch
    assert len(list(intake.decoded())) == 4 and decoder.dropped == {"msgpack": 1}
    mcap.close()


def test_a_batch_is_due_when_its_oldest_has_waited_or_it_is_large(tmp_path: Path) -> None:
    intake, mcap, _ = make(tmp_path)
    intake.decode_bytes = 1000
    assert not intake.due(START_S + 100)
    intake.take([rec(KEYS.follower_state(0), state(0, 0, START_S), recv_s=START_S)])
    assert not intake.due(START_S + intake.decode_age_s / 2)
    assert intake.due(START_S + intake.decode_age_s)
    intake.take([rec(KEYS.follower_state(0), state(0, k, START_S), recv_s=START_S)
                 for k in range(1, 20)])
    assert intake.due(START_S)
    mcap.close()


def test_the_mcap_holds_states_as_json_from_their_wire_arrays_and_reads_back(
        tmp_path: Path) -> None:
    paper = load_scenario("paper")
    run = SynthRun(paper, KEYS, START_S, duration_s=0.2)
    samples = list(run.samples())
    intake, mcap, _ = make(tmp_path)  # writes r.mcap
    for key, msg in samples:
        if isinstance(msg, FollowerState):
            intake.take([rec(key, msg)])
        else:
            mcap.write(key, msg, START_S)
    mcap.close()
    old = McapLog(tmp_path / "old.mcap")  # every message decoded first, as before
    for key, msg in samples:
        old.write(key, msg, START_S)
    old.close()
    with (tmp_path / "r.mcap").open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        assert {c.message_encoding for c in summary.channels.values()} == {MESSAGE_ENCODING}
        assert {s.name for s in summary.schemas.values()} >= {"enclose.FollowerState"}
        recorded = [(c.topic, m.data) for _, c, m in reader.iter_messages()]
    states = [(k, m) for k, m in samples if isinstance(m, FollowerState)]
    assert [json.loads(d) for k, d in recorded if "/follower/" in k] == \
        [json.loads(message_json(m)) for _, m in states]
    for path in (tmp_path / "r.mcap", tmp_path / "old.mcap"):
        skipped: Counter[str] = Counter()
        items = [i for i in read_back(path, skipped) if isinstance(i, Recorded)]
        assert [(i.key, decode(i.payload)) for i in items] == samples, path
        assert [(k, m) for k, m, _ in read_messages(path, skipped)] == samples
        assert not skipped


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.binary(max_size=64),
                 st.lists(st.one_of(st.integers(-(2**63), 2**64 - 1), st.floats(),
                                    st.text(max_size=4), st.binary(max_size=4), st.none()),
                          max_size=16).map(msgpack.packb)))
def test_a_payload_that_is_no_wire_array_is_not_recorded_and_never_raises(
        payload: bytes) -> None:
    made = wire_json(FollowerState, payload)
    if made is not None:  # by chance a wire array of a state: the JSON of some object
        assert isinstance(json.loads(made[0]), dict)


def test_a_state_recorded_from_its_wire_array_is_its_messages_json() -> None:
    msg = state(2, 7, START_S, x=1.5)
    made = wire_json(FollowerState, encode(msg))
    assert made is not None
    data, stamp_ns, seq = made
    assert json.loads(data) == json.loads(message_json(msg))
    assert (stamp_ns, seq) == (int(START_S * 1e9), 7)
    assert wire_json(FollowerState, encode(msg)[:-1]) is None  # cut short
    wire = msgpack.unpackb(encode(msg))
    for stamp in ([1], "x", b"\x00", float("nan")):  # [1] * 1e9 would be a gigabyte
        wire[4] = stamp
        assert wire_json(FollowerState, msgpack.packb(wire)) is None
    assert wire_json(FollowerState, b"\x91" * 60_000 + b"\x00") is None  # nested too deep
