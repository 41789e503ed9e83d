"""The follower's input journal: records round-trip, a cut tail is read up to its last
whole frame, a damaged frame and another version are named, and a replay reproduces a
runner's steps bit for bit (or names the first that differs)."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import msgpack
import pytest

from agents.follower.journal import JournalWriter, PeerCodec, journal_path
from agents.follower.journal_file import JOURNAL_VERSION, Frames, FrameWriter
from agents.follower.journal_replay import replay
from agents.follower.runner import LawRunner
from agents.law.interface import Inputs, Law, Output, Peer, Sample, Setup
from agents.loading.law_loader import make_law
from agents.loading.scenario_file import load_scenario
from agents.membership.follower_place import setup_for
from enclose_release import VERSION
from errors import JournalError

pytestmark = pytest.mark.timeout(60)
HEADER = {"index": 0, "scenario": "paper", "law": None, "law_params": [], "network": []}


def _fly(path: Path, steps: int, heard_again: bool = True) -> LawRunner:
    """Follower 0 of the paper case on made-up inputs, journaled at `path`; a change of
    members half way, and (`heard_again`) a neighbour heard again after a silence at 3/4."""
    scenario = load_scenario("paper", whole_run=False)
    runner = LawRunner(make_law(scenario), setup_for(scenario, 0))
    runner.journal = JournalWriter(path, HEADER, runner.declared)
    setup = runner.setup
    peers: dict[int, Peer] = {}
    for k in range(steps):
        now = 100.0 + 0.02 * k
        targets = {j: Sample(complex(j + 0.1 * now, 1.0), 0.1 + 0j, now - 0.01)
                   for j in setup.observed}
        if k % 3 != 1:  # not every peer is new at every step
            for j in setup.peers:
                peers[j] = Peer(Sample(complex(0.5 * j, 0.01 * k), 0.01j, now - 0.02),
                                Sample(complex(j, -j), 0j, now - 0.03), {})
        if k == steps // 2:
            runner.regroup(setup_for(scenario, 0, [0, 1, 2]))
            setup = runner.setup
            peers = {j: p for j, p in peers.items() if j in setup.peers}
        if heard_again and k == 3 * steps // 4:
            runner.continue_estimate()
        runner.step(now, k % 2 == 0, Sample(complex(0.1 * k, 2.0), 0.3j, now), targets,
                    dict(peers))
    runner.journal.close()
    return runner


def test_a_replay_reproduces_every_step(tmp_path: Path) -> None:
    path = tmp_path / "f.journal"
    _fly(path, 200)
    found = replay(path, load_scenario("paper", whole_run=False), make_law(
        load_scenario("paper", whole_run=False)))
    assert found.steps == 200
    assert found.difference is None and found.stopped is None and found.reproduced
    assert len(found.series.t_s) == 100 and found.series.regroups_s


def test_an_estimate_continued_after_a_silence_is_journaled_and_replayed(
        tmp_path: Path) -> None:
    flown = _fly(tmp_path / "a.journal", 200)
    plain = _fly(tmp_path / "b.journal", 200, heard_again=False)
    assert flown.last_r != plain.last_r  # the continuation changed the flight
    scenario = load_scenario("paper", whole_run=False)
    found = replay(tmp_path / "a.journal", scenario, make_law(scenario))
    assert found.reproduced and found.steps == 200


def test_another_gain_differs_and_is_named(tmp_path: Path) -> None:
    import dataclasses

    path = tmp_path / "f.journal"
    _fly(path, 50)
    scenario = load_scenario("paper", whole_run=False)
    other = dataclasses.replace(scenario, gains=dataclasses.replace(scenario.gains, k_e=1.0))
    found = replay(path, other, make_law(other))
    assert found.difference is not None
    assert "command" in found.difference.why or "estimate" in found.difference.why


def test_a_cut_journal_is_read_to_its_last_whole_frame(tmp_path: Path) -> None:
    path = tmp_path / "f.journal"
    w = FrameWriter(path, HEADER)
    for k in range(3):
        w.add(["x", k])
        w.flush()
    w.close()
    whole = path.read_bytes()
    path.write_bytes(whole[:-3])  # a SIGKILL during the last write
    frames = Frames.open(path)
    assert [r for _, r in frames.records()] == [["x", 0], ["x", 1]]
    assert frames.stopped is not None and "cut short" in frames.stopped


def test_a_damaged_frame_is_named_by_offset(tmp_path: Path) -> None:
    path = tmp_path / "f.journal"
    w = FrameWriter(path, HEADER)
    w.add(["x", 1])
    w.flush()
    at = w.bytes_written
    w.add(["x", 2])
    w.close()
    data = bytearray(path.read_bytes())
    data[at + 10] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(JournalError) as err:
        list(Frames.open(path).records())
    assert err.value.offset == at and str(path) in str(err.value)


def test_another_version_is_refused_naming_both(tmp_path: Path) -> None:
    path = tmp_path / "f.journal"
    import zlib

    mine = VERSION
    for version, enclose in ((JOURNAL_VERSION + 1, mine), (JOURNAL_VERSION, "0.0.1")):
        head = msgpack.packb({"magic": "enclose-journal", "version": version,
                              "enclose": enclose})
        path.write_bytes(struct.pack("<II", len(head), zlib.crc32(head)) + head)
        with pytest.raises(JournalError) as err:
            Frames.open(path)
        assert f"journal version {version}" in str(err.value)
        assert f"enclose {enclose!r}" in str(err.value)
        assert f"this is enclose {mine!r} (journal version {JOURNAL_VERSION})" in str(err.value)


def test_a_restarted_process_writes_the_next_part(tmp_path: Path) -> None:
    first = journal_path(tmp_path, 3)
    first.write_bytes(b"")
    assert first.name == "follower-3.journal"
    assert journal_path(tmp_path, 3).name == "follower-3-part2.journal"
    assert not os.path.exists(tmp_path / "follower-3-part2.journal")


def test_a_peer_with_rated_fields_round_trips_exactly() -> None:
    codec = PeerCodec([("sums", "rates"), ("rates", None), ("k", None), ("v", None)])
    r = Sample(complex(0.1, 0.7), complex(1e-3, 3.0), 12.5)
    rated = Sample(complex(2.0, -1.0 / 3.0), complex(0.25, 0.5), 12.5)
    off = Sample(complex(2.0, 1.0), complex(9.0, 0.5), 11.0)  # not at r's stamp: kept whole
    for fields in ({"sums": rated, "rates": complex(0.25, 0.5), "k": 3, "v": 0.1},
                   {"sums": off, "rates": complex(0.25, 0.5)}, {}):
        peer = Peer(r, Sample(complex(1.5, 2.5), 0.5j, 12.25), fields)
        back = codec.decode(msgpack.unpackb(msgpack.packb(codec.encode(peer))))
        assert back == peer and list(back.fields) == list(fields)
        assert all(type(back.fields[k]) is type(v) for k, v in fields.items())


def test_enclose_replay_names_a_damaged_or_cut_journal(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    from agents.follower import journal_file
    from deploy.cli import main

    monkeypatch.setattr(journal_file, "FLUSH_EVERY_S", 0.0)  # a frame per record
    path = tmp_path / "journal" / "follower-0.journal"
    path.parent.mkdir()
    _fly(path, 150)
    assert main(["replay", str(tmp_path), "follower-0"]) == 0
    assert "reproduced bit for bit" in capsys.readouterr().out
    whole = path.read_bytes()
    path.write_bytes(whole[:-5])  # killed while writing its last frame
    assert main(["replay", str(tmp_path), "--all"]) == 0
    out = capsys.readouterr().out
    assert "stops early" in out and "run reproduced" in out
    damaged = bytearray(whole)
    damaged[len(whole) // 2] ^= 0x55
    path.write_bytes(bytes(damaged))
    assert main(["replay", str(tmp_path), "follower-0"]) == 2
    out = capsys.readouterr().out
    assert "damaged" in out and str(path) in out and "byte" in out


class Clocked(Law[tuple[float, ...]]):
    """Flies east at t_s m/s (a command that is the run's time), keeping every t_s seen."""

    name = "clocked"

    def start(self, setup: Setup) -> tuple[float, ...]:
        return ()

    def step(self, state: tuple[float, ...], inputs: Inputs,
             ) -> tuple[tuple[float, ...], Output]:
        return (*state, inputs.t_s), Output(complex(inputs.t_s, 0.0), 0j, 0j, {})


def test_the_laws_run_time_counts_from_the_start_word_and_replays(tmp_path: Path) -> None:
    scenario = load_scenario("paper", whole_run=False)
    runner = LawRunner(Clocked(), setup_for(scenario, 0))
    runner.journal = JournalWriter(tmp_path / "f.journal", HEADER, runner.declared)
    runner.window(1000.0, 1060.0)  # the start word, on the follower's (bus) clock
    for k in range(5):
        now = 1000.0 + 0.25 * k
        runner.step(now, True, Sample(0j, 0j, now), {}, {})
    runner.window(1000.0, 1000.5)  # the stop word: the origin stays
    runner.step(1001.25, True, Sample(0j, 0j, 1001.25), {}, {})
    runner.journal.close()
    assert runner.state == (0.0, 0.25, 0.5, 0.75, 1.0, 1.25)
    # The replay's t_s is the run's (its commands are t_s: compared bit for bit)
    found = replay(tmp_path / "f.journal", scenario, Clocked())
    assert found.reproduced and found.steps == 6
    assert found.series.u_m_s == [0j, 0.25, 0.5, 0.75, 1.0, 1.25]
