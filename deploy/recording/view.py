"""What the live view shows, as encoded frames: the same bytes go live and into the MCAP.

`LiveView` is fed the recorder's decoded messages and gives `ViewFrame`s (topic, schema,
encoded message, log time).  Channels -- Foxglove's well-known schemas where one fits, so
panels work without set-up:
- `/scene` (`foxglove.SceneUpdate`, protobuf): the 3D scene of `deploy.recording.scene`,
  at most `scene_hz` per second of truth;
- `/errors` (JSON `enclose.LiveErrors`): the paper's errors at that instant, per follower and
  their maxima, with the bounds they are judged against (the definitions of
  `agents.analysis.metrics.error_series`);
- `/links` (JSON `enclose.LiveLinks`): per link age and delivered ratio
  (`deploy.recording.live_links`), once a recorder tick;
- `/status` (JSON `enclose.LiveStatus`): each process's state, the member set and what the
  processes refused from the bus (deploy.report.refusals), each tick;
- `/log` (`foxglove.Log`, protobuf): a line per process state or membership change.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np
from foxglove import messages as fm

from agents.analysis.metrics import error_series
from agents.analysis.timeseries import RunSeries
from deploy.recording.live_links import LinkTracker
from deploy.recording.mcap_log import RawFrame, RawSchema
from deploy.recording.scene import LinkView, pair_distances, scene_update, timestamp, too_close
from deploy.report.refusals import refusals
from deploy.report.rundir import RunInfo
from transport.messages import FollowerState, Message, ProcessStatus, RunControl, TruthSnapshot

SCENE_TOPIC, ERRORS_TOPIC, LINKS_TOPIC = "/scene", "/errors", "/links"
STATUS_TOPIC, LOG_TOPIC = "/status", "/log"
DEFAULT_SCENE_HZ = 10.0
_NS = 1_000_000_000


ViewSchema = RawSchema
ViewFrame = RawFrame


def _proto(cls: Any) -> ViewSchema:
    s = cls.get_schema()
    return ViewSchema(s.name, s.encoding, bytes(s.data), "protobuf")


def _json_schema(name: str, properties: dict[str, Any]) -> ViewSchema:
    body = {"title": name, "type": "object", "properties": properties}
    return ViewSchema(name, "jsonschema", json.dumps(body).encode(), "json")


_NUM = {"type": ["number", "null"]}
_NUMS = {"type": "array", "items": _NUM}
SCHEMAS = {
    SCENE_TOPIC: _proto(fm.SceneUpdate),
    LOG_TOPIC: _proto(fm.Log),
    ERRORS_TOPIC: _json_schema("enclose.LiveErrors", {
        k: _NUMS if k.startswith(("e_", "est")) else _NUM
        for k in ("t_s", "e_rho_m", "e_delta", "estimator_error_m", "max_abs_e_rho_m",
                  "max_abs_e_delta", "max_estimator_error_m", "bound_rho_m", "bound_delta",
                  "bound_estimator_m", "min_separation_m", "safety_distance_m")}),
    LINKS_TOPIC: _json_schema("enclose.LiveLinks", {
        "links": {"type": "array", "items": {"type": "object"}}}),
    STATUS_TOPIC: _json_schema("enclose.LiveStatus", {
        "processes": {"type": "array", "items": {"type": "object"}},
        "members": {"type": "array", "items": {"type": "integer"}},
        "refused": {"type": "object"}}),
}


def _finite(values: Any) -> list[float | None]:
    return [float(v) if np.isfinite(v) else None for v in np.atleast_1d(values)]


def errors_now(truth: TruthSnapshot, states: Mapping[int, FollowerState],
               info: RunInfo) -> dict[str, Any] | None:
    """The paper's errors at the truth's instant, each estimate carried to it by its rate."""
    if len(states) < info.n or len(truth.follower_pos_m) != info.n:
        return None
    stamp = truth.header.stamp_s
    est = np.array([np.add(s.r_m, np.multiply(stamp - s.header.stamp_s, s.dr_m_s))
                    for _, s in sorted(states.items())])
    pos = np.asarray(truth.follower_pos_m, dtype=np.float64)[:, :2]
    series = RunSeries(np.array([stamp]), pos[None], est[None], np.zeros((1, info.n, 2)),
                       np.asarray(truth.target_pos_m, dtype=np.float64)[None])
    e = error_series(series, info.successor, np.asarray(info.angles_rad), info.rho_d_m)
    rho, delta, est_err = e.e_rho_m[0], e.e_delta[0], e.estimator_error_m[0]
    _, _, apart = pair_distances(pos)
    apart = apart[~np.isnan(apart)]  # as separation_series: NaN positions ignored
    return {"e_rho_m": _finite(rho), "e_delta": _finite(delta),
            "estimator_error_m": _finite(est_err),
            "max_abs_e_rho_m": _finite(np.abs(rho).max())[0],
            "max_abs_e_delta": _finite(np.abs(delta).max())[0],
            "max_estimator_error_m": _finite(est_err.max())[0],
            "bound_rho_m": info.eps_rho_m, "bound_delta": info.eps_delta,
            "bound_estimator_m": info.eps_rho_m,
            "min_separation_m": _finite(apart.min() if apart.size else np.nan)[0],
            "safety_distance_m": info.safety_distance_m}


def _json(topic: str, body: dict[str, Any], log_time_ns: int) -> ViewFrame:
    data = json.dumps(body, separators=(",", ":"), allow_nan=False).encode()
    return ViewFrame(topic, SCHEMAS[topic], data, log_time_ns)


class LiveView:
    """Latest truth, states and statuses; frames when there is something new to show."""

    def __init__(self, info: RunInfo, scene_hz: float = DEFAULT_SCENE_HZ,
                 recorded_states: list[int] | None = None) -> None:
        self.info = info
        self.period_s = 1.0 / scene_hz
        self.states: dict[int, FollowerState] = {}
        self.follower_status: dict[int, ProcessStatus] = {}
        self.processes: dict[str, ProcessStatus] = {}
        self.links = LinkTracker()
        self.start_stamp_s: float | None = None
        self._truth: tuple[TruthSnapshot, float] | None = None
        self._last_scene_s = -float("inf")
        self._members: frozenset[int] | None = None
        self._pending_log: list[ViewFrame] = []
        # States received per follower: counted here from what is added, or the recorder's
        # own count when it adds only the newest (deploy.recording.intake).
        self._counts_added = recorded_states is None
        self._recorded_states = [0] * info.n if recorded_states is None else recorded_states
        self._too_close = False  # two vehicles under the safety distance at the last scene
        self._network_said: set[tuple[int, str]] = set()  # network fault windows logged

    def add(self, msg: Message, recv_stamp_s: float) -> None:
        if isinstance(msg, TruthSnapshot):
            if msg.header.stamp_s >= self._last_scene_s + self.period_s:
                self._truth = (msg, recv_stamp_s)
        elif isinstance(msg, FollowerState) and 0 <= msg.index < self.info.n:
            self.states[msg.index] = msg
            if self._counts_added:
                self._recorded_states[msg.index] += 1
        elif isinstance(msg, ProcessStatus):
            self._add_status(msg, recv_stamp_s)
        elif isinstance(msg, RunControl) and msg.command == "start":
            self.start_stamp_s = msg.start_stamp_s

    def _add_status(self, msg: ProcessStatus, recv_stamp_s: float) -> None:
        name = f"{msg.role}-{msg.index}"
        before = self.processes.get(name)
        self.processes[name] = msg
        if before is None or before.state != msg.state:
            level = fm.LogLevel.Error if msg.state == "failed" else fm.LogLevel.Info
            detail = f" ({msg.detail})" if msg.detail else ""
            self._log(f"{name} {msg.state}{detail}", level, recv_stamp_s, name)
        if msg.role == "follower" and 0 <= msg.index < self.info.n:
            self.follower_status[msg.index] = msg
            self.links.update(msg, self.follower_status, self._recorded_states)

    def _network_marks(self, now_s: float) -> None:
        """A log line as each network fault's window opens and closes."""
        if self.start_stamp_s is None:
            return
        t = now_s - self.start_stamp_s
        for k, (label, at_s, end_s) in enumerate(self.info.net_faults):
            for edge, what in ((at_s, "begins"), (end_s, "ends")):
                if t >= edge and (k, what) not in self._network_said:
                    self._network_said.add((k, what))
                    self._log(f"network fault {label} {what}", fm.LogLevel.Warning, now_s,
                              "network")

    def _log(self, text: str, level: fm.LogLevel, stamp_s: float, name: str) -> None:
        msg = fm.Log(timestamp=timestamp(stamp_s), level=level, message=text, name=name)
        self._pending_log.append(ViewFrame(LOG_TOPIC, SCHEMAS[LOG_TOPIC], msg.encode(),
                                           int(stamp_s * _NS)))

    def frames(self) -> list[ViewFrame]:
        """The scene and errors of the newest unshown truth (throttled), and pending logs."""
        out, self._pending_log = self._pending_log, []
        if self._truth is None:
            return out
        truth, recv_s = self._truth
        self._truth = None
        self._last_scene_s = truth.header.stamp_s
        log_ns = int(recv_s * _NS)
        drawn = [LinkView(k.sender, k.receiver, k.health) for k in self.links.links()
                 if k.sender is not None]
        pairs = too_close(truth, self.info.safety_distance_m)
        close = frozenset(k for _, i, j in pairs for k in (i, j))
        if pairs and not self._too_close:
            d, i, j = min(pairs)
            self._log(f"followers {i} and {j} {d:.2f} m apart: under the safety distance "
                      f"({self.info.safety_distance_m:g} m)", fm.LogLevel.Error, recv_s,
                      "safety")
        self._too_close = bool(pairs)
        scene = scene_update(truth, self.states, drawn, self.info.rho_d_m, close,
                             self.info.wind_m_s)
        out.append(ViewFrame(SCENE_TOPIC, SCHEMAS[SCENE_TOPIC], scene.encode(), log_ns))
        errors = errors_now(truth, self.states, self.info)
        if errors is not None:
            t_s = None if self.start_stamp_s is None else truth.header.stamp_s - self.start_stamp_s
            out.append(_json(ERRORS_TOPIC, {"t_s": t_s, **errors}, log_ns))
        return out

    def tick_frames(self, now_s: float, members: frozenset[int] | None) -> list[ViewFrame]:
        """Once a recorder tick: links, process states and the member set."""
        if members is not None and members != self._members:
            self._members = members
            self._log(f"members {sorted(members)}", fm.LogLevel.Info, now_s, "membership")
        self._network_marks(now_s)
        ns = int(now_s * _NS)
        procs = [{"name": k, "state": s.state, "detail": s.detail}
                 for k, s in sorted(self.processes.items())]
        return [*self.frames(),
                _json(LINKS_TOPIC, {"links": [k.as_json() for k in self.links.links()]}, ns),
                _json(STATUS_TOPIC, {"processes": procs,
                                     "members": sorted(self._members or ()),
                                     "refused": refusals({k: s.counters for k, s
                                                          in self.processes.items()})},
                      ns)]

