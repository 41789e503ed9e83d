"""The swarm as a Foxglove 3D scene (`foxglove.SceneUpdate`), from decoded bus messages (pure).

Frame "world" is the run's local ENU frame, metres, z up.  Entities (ids stable across
updates, so each update replaces the last):
- `follower-<i>`: a sphere at the vehicle's true position (simulator truth) and its label,
  red while another vehicle is closer than the scenario's safety distance;
- `target-<j>`: a cube at the target's true position, on the ground (z = 0);
- `estimate-<i>`: follower i's estimate r_i of the targets' centre, on the ground;
- `centre`: the true centre (mean of the targets), on the ground;
- `circle`: the desired circle (radius rho_d) around the true centre, at the vehicles'
  mean altitude, where the formation should fly;
- `links`: one segment per ring link, receiver to sender, coloured by its health.
Indices are 0-based, as in process names.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from foxglove import messages as fm
from numpy.typing import NDArray

from transport.messages import FollowerState, TruthSnapshot

FRAME_ID = "world"
CIRCLE_SEGMENTS = 72
VEHICLE_SIZE_M = 1.0
TARGET_SIZE_M = 0.8
ESTIMATE_SIZE_M = 0.4
LINE_THICKNESS_PX = 3.0
LINK_SIDE_OFFSET_M = 0.25

_IDENTITY = fm.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
FOLLOWER_RGBA = (0.20, 0.55, 1.00, 1.0)
TOO_CLOSE_RGBA = (0.95, 0.05, 0.05, 1.0)
TARGET_RGBA = (1.00, 0.45, 0.10, 1.0)
ESTIMATE_RGBA = (0.60, 0.30, 0.90, 0.9)
CIRCLE_RGBA = (0.60, 0.60, 0.60, 0.8)
WIND_RGBA = (0.30, 0.80, 0.90, 0.9)
WIND_ARROW_M_PER_M_S = 2.0  # the wind arrow's length per m/s of mean wind
HEALTH_RGBA = {
    "good": (0.10, 0.80, 0.20, 1.0),
    "degraded": (1.00, 0.75, 0.00, 1.0),
    "bad": (0.90, 0.10, 0.10, 1.0),
}


@dataclass(frozen=True)
class LinkView:
    """One directed ring link as drawn: `sender` -> `receiver` (follower indices)."""

    sender: int
    receiver: int
    health: str  # a key of HEALTH_RGBA


def timestamp(stamp_s: float) -> fm.Timestamp:
    sec = math.floor(stamp_s)
    return fm.Timestamp(sec=max(0, sec), nsec=min(999_999_999, round((stamp_s - sec) * 1e9)))


def _color(rgba: tuple[float, float, float, float]) -> fm.Color:
    r, g, b, a = rgba
    return fm.Color(r=r, g=g, b=b, a=a)


def _point(x: float, y: float, z: float) -> fm.Point3:
    return fm.Point3(x=x, y=y, z=z)


def _pose(x: float, y: float, z: float) -> fm.Pose:
    return fm.Pose(position=fm.Vector3(x=x, y=y, z=z), orientation=_IDENTITY)


def _size(s: float) -> fm.Vector3:
    return fm.Vector3(x=s, y=s, z=s)


def _entity(entity_id: str, stamp: fm.Timestamp, **primitives: Any) -> fm.SceneEntity:
    return fm.SceneEntity(id=entity_id, frame_id=FRAME_ID, timestamp=stamp,
                          frame_locked=False, **primitives)


def _label(text: str, x: float, y: float, z: float) -> fm.TextPrimitive:
    return fm.TextPrimitive(pose=_pose(x, y, z + 1.0), billboard=True, font_size=14.0,
                            scale_invariant=True, color=_color((1.0, 1.0, 1.0, 1.0)), text=text)


def centre_m(truth: TruthSnapshot) -> tuple[float, float]:
    """The true centre of the targets (the paper's leaders' average position)."""
    m = len(truth.target_pos_m)
    return (sum(p[0] for p in truth.target_pos_m) / m, sum(p[1] for p in truth.target_pos_m) / m)


def circle_points(cx: float, cy: float, radius_m: float, z: float) -> list[fm.Point3]:
    """A closed polygon (first point repeated) approximating the circle."""
    step = 2.0 * math.pi / CIRCLE_SEGMENTS
    return [_point(cx + radius_m * math.cos(k * step), cy + radius_m * math.sin(k * step), z)
            for k in range(CIRCLE_SEGMENTS + 1)]


def pair_distances(pos_m: NDArray[np.float64]
                   ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """i, j and the distance of every pair i < j of the (n, 2) positions, i then j in order:
    the numbers of agents.analysis.metrics.separation_series, at a seventh of its cost for
    one instant (the view's 10 Hz at n = 64: ~1 ms a scene in Python loops)."""
    i, j = np.triu_indices(len(pos_m), 1)
    diff = pos_m[j] - pos_m[i]
    return i, j, np.sqrt(np.add.reduce(diff * diff, axis=1))


def horizontal_m(truth: TruthSnapshot) -> NDArray[np.float64]:
    """The vehicles' (n, 2) horizontal positions."""
    return np.asarray(truth.follower_pos_m, dtype=np.float64).reshape(-1, 3)[:, :2]


def too_close(truth: TruthSnapshot, distance_m: float) -> list[tuple[float, int, int]]:
    """(distance, i, j) of each pair of vehicles closer than `distance_m` (horizontal)."""
    i, j, d = pair_distances(horizontal_m(truth))
    close = d < distance_m
    return [(float(x), int(a), int(b))
            for x, a, b in zip(d[close], i[close], j[close], strict=True)]


def _vehicles(truth: TruthSnapshot, stamp: fm.Timestamp,
              close: frozenset[int]) -> list[fm.SceneEntity]:
    out = []
    for i, (x, y, z) in enumerate(truth.follower_pos_m):
        rgba = TOO_CLOSE_RGBA if i in close else FOLLOWER_RGBA
        out.append(_entity(f"follower-{i}", stamp, spheres=[fm.SpherePrimitive(
            pose=_pose(x, y, z), size=_size(VEHICLE_SIZE_M), color=_color(rgba))],
            texts=[_label(f"f{i}", x, y, z)]))
    for j, (x, y) in enumerate(truth.target_pos_m):
        out.append(_entity(f"target-{j}", stamp, cubes=[fm.CubePrimitive(
            pose=_pose(x, y, 0.0), size=_size(TARGET_SIZE_M), color=_color(TARGET_RGBA))],
            texts=[_label(f"t{j}", x, y, 0.0)]))
    return out


def _estimates(states: Mapping[int, FollowerState], stamp: fm.Timestamp) -> list[fm.SceneEntity]:
    return [_entity(f"estimate-{i}", stamp, spheres=[fm.SpherePrimitive(
        pose=_pose(s.r_m[0], s.r_m[1], 0.0), size=_size(ESTIMATE_SIZE_M),
        color=_color(ESTIMATE_RGBA))]) for i, s in sorted(states.items())]


def _side_offset(a: tuple[float, float, float],
                 b: tuple[float, float, float]) -> tuple[float, float]:
    """A shift to the left of a -> b: the two directions of a link are drawn side by side."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    norm = math.hypot(dx, dy)
    if norm == 0.0:
        return 0.0, 0.0
    return -dy / norm * LINK_SIDE_OFFSET_M, dx / norm * LINK_SIDE_OFFSET_M


def _links(truth: TruthSnapshot, links: Sequence[LinkView],
           stamp: fm.Timestamp) -> fm.SceneEntity:
    points, colors = [], []
    n = len(truth.follower_pos_m)
    for link in links:
        if not (0 <= link.sender < n and 0 <= link.receiver < n):
            continue
        rgba = _color(HEALTH_RGBA.get(link.health, HEALTH_RGBA["bad"]))
        a, b = truth.follower_pos_m[link.receiver], truth.follower_pos_m[link.sender]
        ox, oy = _side_offset(a, b)
        for x, y, z in (a, b):
            points.append(_point(x + ox, y + oy, z))
            colors.append(rgba)
    line = fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineList, pose=_pose(0.0, 0.0, 0.0),
                            thickness=LINE_THICKNESS_PX, scale_invariant=True, points=points,
                            color=_color(HEALTH_RGBA["good"]), colors=colors)
    return _entity("links", stamp, lines=[line] if points else [])


def wind_arrow(wind_m_s: tuple[float, float], cx: float, cy: float, rho_m: float,
               z: float, stamp: fm.Timestamp) -> fm.SceneEntity:
    """The mean wind as an arrow outside the circle, pointing where the air goes."""
    speed = math.hypot(*wind_m_s)
    yaw = math.atan2(wind_m_s[1], wind_m_s[0])
    x, y = cx - rho_m * 1.5, cy + rho_m * 1.5
    pose = fm.Pose(position=fm.Vector3(x=x, y=y, z=z),
                   orientation=fm.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0),
                                             w=math.cos(yaw / 2.0)))
    arrow = fm.ArrowPrimitive(pose=pose, shaft_length=WIND_ARROW_M_PER_M_S * speed,
                              shaft_diameter=0.3, head_length=1.0, head_diameter=0.8,
                              color=_color(WIND_RGBA))
    return _entity("wind", stamp, arrows=[arrow],
                   texts=[_label(f"wind {speed:.3g} m/s", x, y, z)])


def scene_update(truth: TruthSnapshot, states: Mapping[int, FollowerState],
                 links: Sequence[LinkView], rho_d_m: float,
                 close: frozenset[int] = frozenset(),
                 wind_m_s: tuple[float, float] | None = None) -> fm.SceneUpdate:
    """The whole scene at the truth's instant (its sender stamp); `close`: the vehicles
    drawn red (too_close); `wind_m_s`: the scenario's mean wind, drawn as an arrow."""
    stamp = timestamp(truth.header.stamp_s)
    cx, cy = centre_m(truth)
    zs = [p[2] for p in truth.follower_pos_m]
    altitude_m = sum(zs) / len(zs) if zs else 0.0
    circle = fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineStrip, pose=_pose(0.0, 0.0, 0.0),
                              thickness=1.5, scale_invariant=True,
                              points=circle_points(cx, cy, rho_d_m, altitude_m),
                              color=_color(CIRCLE_RGBA))
    entities = [
        *_vehicles(truth, stamp, close),
        *_estimates(states, stamp),
        _entity("centre", stamp, spheres=[fm.SpherePrimitive(
            pose=_pose(cx, cy, 0.0), size=_size(ESTIMATE_SIZE_M), color=_color(TARGET_RGBA))]),
        _entity("circle", stamp, lines=[circle]),
        _links(truth, links, stamp),
    ]
    if wind_m_s is not None:
        entities.append(wind_arrow(wind_m_s, cx, cy, rho_d_m, altitude_m, stamp))
    return fm.SceneUpdate(entities=entities)
