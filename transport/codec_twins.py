"""The fast twins of the rarer messages (clock probes, status, run control), and the
table of every twin with the schema it implements (see transport.codec_fast)."""

from __future__ import annotations

from typing import Any

from transport.codec_fast import (
    MAX_ITEMS,
    MAX_STR,
    VERSION,
    Decoder,
    Encoder,
    Wire,
    dec_follower_state,
    dec_target_observation,
    dec_truth_snapshot,
    enc_follower_state,
    enc_target_observation,
    enc_truth_snapshot,
    head_ok,
    header,
)
from transport.fastbuild import NEW, SET
from transport.messages import (
    PROCESS_STATES,
    RUN_COMMANDS,
    ClockProbe,
    FollowerState,
    ProcessStatus,
    RunControl,
    TargetObservation,
    TruthSnapshot,
)


def _echoes_ok(echoes: Any, seq_type: Any) -> bool:
    if type(echoes) is not seq_type or len(echoes) > MAX_ITEMS:
        return False
    s = 0.0
    for e in echoes:
        if type(e) is not seq_type:
            return False
        peer, t1, t2 = e
        if type(peer) is not str or len(peer) > MAX_STR or type(t1) is not float \
                or type(t2) is not float:
            return False
        s += t1 + t2
    return s - s == 0.0


def enc_clock_probe(m: ClockProbe) -> Wire | None:
    h = m.header
    sid, seq, st, epoch, echoes = h.sender_id, h.seq, h.stamp_s, m.epoch_s, m.echoes
    if not (head_ok(sid, seq, st) and type(epoch) is float and st - st + epoch - epoch == 0.0
            and _echoes_ok(echoes, tuple)):
        return None
    return [VERSION, 6, sid, seq, st, epoch, echoes]


def dec_clock_probe(o: Wire) -> ClockProbe | None:
    _, _, sid, seq, st, epoch, echoes = o
    if not (head_ok(sid, seq, st) and type(epoch) is float and st - st + epoch - epoch == 0.0
            and _echoes_ok(echoes, list)):
        return None
    m = NEW(ClockProbe)
    SET(m, "__dict__", {"header": header(sid, seq, st), "epoch_s": epoch,
                         "echoes": tuple(map(tuple, echoes))})
    return m


def _counters_ok(counters: Any) -> bool:
    if type(counters) is not dict or len(counters) > MAX_ITEMS:
        return False
    for k, n in counters.items():
        if type(k) is not str or len(k) > MAX_STR or type(n) is not int:
            return False
    return True


def _status_ok(o: Wire) -> bool:
    _, _, sid, seq, st, role, idx, state, counters, detail = o
    return (head_ok(sid, seq, st) and st - st == 0.0 and type(role) is str
            and len(role) <= MAX_STR and type(idx) is int and idx >= 0 and type(state) is str
            and state in PROCESS_STATES and _counters_ok(counters) and type(detail) is str
            and len(detail) <= MAX_STR)


def enc_process_status(m: ProcessStatus) -> Wire | None:
    h = m.header
    o = [VERSION, 4, h.sender_id, h.seq, h.stamp_s, m.role, m.index, m.state, m.counters,
         m.detail]
    return o if _status_ok(o) else None


def dec_process_status(o: Wire) -> ProcessStatus | None:
    if not _status_ok(o):
        return None
    _, _, sid, seq, st, role, idx, state, counters, detail = o
    m = NEW(ProcessStatus)
    SET(m, "__dict__", {"header": header(sid, seq, st), "role": role, "index": idx,
                         "state": state, "counters": counters, "detail": detail})
    return m


def _control_ok(o: Wire) -> bool:
    _, _, sid, seq, st, command, start, duration = o
    return (head_ok(sid, seq, st) and type(command) is str and command in RUN_COMMANDS
            and type(start) is float and type(duration) is float
            and st - st + start - start + duration - duration == 0.0)


def enc_run_control(m: RunControl) -> Wire | None:
    h = m.header
    o = [VERSION, 5, h.sender_id, h.seq, h.stamp_s, m.command, m.start_stamp_s, m.duration_s]
    return o if _control_ok(o) else None


def dec_run_control(o: Wire) -> RunControl | None:
    if not _control_ok(o):
        return None
    _, _, sid, seq, st, command, start, duration = o
    m = NEW(RunControl)
    SET(m, "__dict__", {"header": header(sid, seq, st), "command": command,
                         "start_stamp_s": start, "duration_s": duration})
    return m


# Each twin pair and the schema it implements: tag, then `name:kind` per field in order
# (`@n`: since codec version n), as in codec.SCHEMAS.
TWINS: dict[type, tuple[int, str, Encoder, Decoder]] = {
    FollowerState: (1, "index:int r_m:vec2 dr_m_s:vec2 pos_m:vec2 vel_m_s:vec2 u_m_s:vec2 "
                    "vehicle_stamp_s:float law:law@4",
                    enc_follower_state, dec_follower_state),
    TargetObservation: (2, "observer_index:int target_index:int pos_m:vec2 "
                        "observed_stamp_s:float noise_std_m:opt_float",
                        enc_target_observation, dec_target_observation),
    TruthSnapshot: (3, "sim_time_s:float follower_pos_m:vec3s follower_vel_m_s:vec3s "
                    "target_pos_m:vec2s target_vel_m_s:vec2s",
                    enc_truth_snapshot, dec_truth_snapshot),
    ProcessStatus: (4, "role:str index:int state:state counters:counters detail:str",
                    enc_process_status, dec_process_status),
    RunControl: (5, "command:command start_stamp_s:float duration_s:float",
                 enc_run_control, dec_run_control),
    ClockProbe: (6, "epoch_s:float echoes:echoes", enc_clock_probe, dec_clock_probe),
}
