"""The MCAP log read back with the mcap library: channels, JSON schemas, messages, crashes."""

from __future__ import annotations

import dataclasses
import io
import json
from pathlib import Path
from types import MappingProxyType
from typing import Any

import pytest

from agents.loading.scenario_file import load_scenario
from deploy.recording.mcap_log import McapLog, dataclass_schema, message_json
from tests.recorder_synth import SynthRun
from transport.key_exprs import SwarmKeys
from transport.messages import (
    FollowerState,
    Header,
    Message,
    ProcessStatus,
    RunControl,
    TargetObservation,
    TruthSnapshot,
)

START_S = 1_700_000_000.0
_JSON_TYPES: dict[str, Any] = {"number": (int, float), "integer": int, "string": str,
                               "object": dict, "array": list, "null": type(None)}


def conforms(value: Any, schema: dict[str, Any]) -> bool:
    """The subset of JSON Schema the generated schemas use (no jsonschema package here)."""
    if "anyOf" in schema:  # a union, e.g. a law field's value
        return any(conforms(value, s) for s in schema["anyOf"])
    if "type" not in schema:  # an unknown property
        return False
    kinds = schema["type"] if isinstance(schema["type"], list) else [schema["type"]]
    if not any(isinstance(value, _JSON_TYPES[k]) and not isinstance(value, bool) for k in kinds):
        return False
    if isinstance(value, dict):
        if set(schema.get("required", ())) - set(value):
            return False
        props, extra = schema.get("properties", {}), schema.get("additionalProperties", {})
        return all(conforms(v, props.get(k, extra)) for k, v in value.items())
    if isinstance(value, list):
        if not schema.get("minItems", 0) <= len(value) <= schema.get("maxItems", len(value)):
            return False
        if "prefixItems" in schema:  # a tuple of mixed types, e.g. a per_link entry
            return all(conforms(v, s) for v, s in zip(value, schema["prefixItems"], strict=True))
        return all(conforms(v, schema["items"]) for v in value)
    return True


def write_run(path: Path, chunk_size: int = 64 * 1024) -> tuple[McapLog, list[Any]]:
    scenario = load_scenario("paper")
    keys = SwarmKeys("mc")
    run = SynthRun(scenario, keys, START_S, duration_s=1.0)
    head = Header("x-0", 3, START_S + 0.5)
    extra: list[tuple[str, Message]] = [
        (keys.control(), RunControl(head, "start", START_S, 1.0)),
        (keys.status("follower", 1), ProcessStatus(head, "follower", 1, "running", {"gap": 2})),
        (keys.sensor_targets(0), TargetObservation(head, 0, 1, (1.0, 2.0), START_S, None)),
    ]
    log = McapLog(path, chunk_size=chunk_size, metadata={"swarm": "mc"})
    written = []
    for key, msg in [*extra, *run.samples()]:
        log.write(key, msg, msg.header.stamp_s + 0.002)
        written.append((key, msg))
    return log, written


@pytest.mark.timeout(30)
def test_channels_schemas_and_messages_read_back(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    path = tmp_path / "rec.mcap"
    log, written = write_run(path)
    log.close()
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        topics = {c.topic: c for c in summary.channels.values()}
        assert set(topics) == {k for k, _ in written}
        assert all(c.message_encoding == "json" for c in topics.values())
        schemas = {s.name: s for s in summary.schemas.values()}
        assert set(schemas) == {f"enclose.{c.__name__}" for c in
                                (FollowerState, TruthSnapshot, ProcessStatus, RunControl,
                                 TargetObservation)}
        assert all(s.encoding == "jsonschema" for s in schemas.values())
        assert summary.statistics is not None
        assert summary.statistics.message_count == len(written)
        got = list(reader.iter_messages(log_time_order=False))
    assert len(got) == len(written)
    for (schema, channel, message), (key, msg) in zip(got, written, strict=True):
        assert schema is not None and channel.topic == key
        body = json.loads(message.data)
        assert body == json.loads(json.dumps(dataclasses.asdict(msg)))
        assert conforms(body, json.loads(schema.data))
        assert message.publish_time == int(msg.header.stamp_s * 1e9)
        assert message.log_time == int((msg.header.stamp_s + 0.002) * 1e9)
        assert message.sequence == msg.header.seq


def test_schema_rejects_what_the_type_forbids() -> None:
    schema = dataclass_schema(FollowerState)
    assert schema["properties"]["r_m"] == {"type": "array", "items": {"type": "number"},
                                           "minItems": 2, "maxItems": 2}
    assert schema["properties"]["header"]["required"] == ["sender_id", "seq", "stamp_s"]
    assert not conforms({"header": {}, "r_m": [1.0]}, schema)
    assert dataclass_schema(TargetObservation)["properties"]["noise_std_m"]["type"] == [
        "number", "null"]
    law = schema["properties"]["law"]  # a law's fields: each kind of transport.law_fields
    link = [2, 0.5, -0.5]  # a per_link entry: (j, x, y)
    assert conforms({"k": 1.5, "v": [0.5, 1.0], "sums": [link], "none": []}, law)
    assert not conforms({"sums": [link[:2]]}, law)
    assert not conforms({"sums": [[0.5, *link[1:]]]}, law)
    assert not conforms({"v": [1.0]}, law) and not conforms({"k": "x"}, law)


@pytest.mark.timeout(30)
def test_unfinished_file_keeps_every_complete_chunk(tmp_path: Path) -> None:
    """A recorder killed mid-run (no close) loses at most the chunk being built."""
    from mcap.exceptions import EndOfFile
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    path = tmp_path / "crash.mcap"
    log, written = write_run(path, chunk_size=8 * 1024)
    log.flush()  # what the loop does every second; the process then "dies"
    messages = 0
    with pytest.raises(EndOfFile):
        for record in StreamReader(io.BytesIO(path.read_bytes())).records:
            messages += isinstance(record, Message)
    per_chunk = 8 * 1024 // 300  # a JSON message is over 300 bytes
    assert len(written) - per_chunk <= messages < len(written)


def test_message_json_is_the_standard_encoders_bytes(tmp_path: Path) -> None:
    """msgspec writes the channels' JSON: byte for byte what json.dumps(asdict) gives, so
    a reader (Foxglove, `mcap cat`) sees the same messages as before; a value msgspec does
    not know falls back to the standard encoder."""
    _, written = write_run(tmp_path / "r.mcap")
    assert {type(m) for _, m in written} >= {FollowerState, ProcessStatus}
    for _, msg in written:
        standard = json.dumps(dataclasses.asdict(msg), separators=(",", ":")).encode()
        assert message_json(msg) == standard
    status = next(m for _, m in written if isinstance(m, ProcessStatus))
    frozen = dataclasses.replace(status, counters=MappingProxyType({"rx": 3, "drop": 1}))
    assert message_json(frozen) == b'{"header":' + json.dumps(
        dataclasses.asdict(status)["header"], separators=(",", ":")).encode() + (
        b',"role":"%s","index":%d,"state":"%s","counters":{"rx":3,"drop":1},"detail":"%s"}'
        % (status.role.encode(), status.index, status.state.encode(), status.detail.encode()))
