"""``visualization_msgs/MarkerArray`` of an estimate, in Autoware's lanelet marker style.

Namespaces (DESIGN.md §6): ``center`` (sphere), ``arm_axes`` (arrow from the center outward
per arm), ``left_lane_bound`` / ``right_lane_bound`` (line strip per lanelet; connector
borders are virtual and drawn thin and pale), ``center_lane_line`` (entering / leaving
lanes), ``connectors`` (connector center lines), ``center_line_arrows`` (triangles along
every center line, pointing in driving direction), ``lanelet_id`` (text).

Marker ids are stable: per lanelet a hash of its id (the same lanelet keeps its id across
calls, whatever the order), per arm its index. Keys that were published before and are
gone now get a DELETE, so RViz / Foxglove never show stale lanes. All markers are in the
header's frame (the fixed frame); publish with TRANSIENT_LOCAL durability. Colours come
from :mod:`intersection_estimator.palette` (entering green, leaving blue, connector orange),
the same as in the PNG.
"""

from __future__ import annotations

import math
import zlib

import numpy as np

from intersection_estimator.palette import RGBA

__all__ = ['NAMESPACES', 'COLORS', 'DRAW_STEP', 'markers_msg', 'clear_markers_msg', 'lanelet_marker_id',
           'thin']

NAMESPACES = ('center', 'arm_axes', 'left_lane_bound', 'right_lane_bound', 'center_lane_line',
              'center_line_arrows', 'connectors', 'lanelet_id')
#: RGBA per kind of drawing: the package's one palette (the PNG uses the same colours).
COLORS = RGBA
ARROW, SPHERE, LINE_STRIP, TEXT_VIEW_FACING, TRIANGLE_LIST = 0, 2, 4, 9, 11
ADD, DELETE, DELETEALL = 0, 2, 3
_ARROW_SPACING = 8.0   # [m] between center line arrows
_ARROW_SIZE = 1.2      # [m]
#: [m] line strips are drawn with one vertex about every this many metres of arc (and both
#: ends): a lane course has a station every ~0.5 m, and building thousands of Point
#: messages per update cost the node tens of ms on real junctions. On a curve of radius R
#: the drawn chord is within DRAW_STEP**2 / (8 R) of the lane (2.5 cm at R = 5 m). The
#: ``~/lanelets`` topic keeps every station.
DRAW_STEP = 1.0


def thin(xy: np.ndarray, step: float) -> np.ndarray:
    """The vertices of polyline ``xy`` (n, 2) at which its arc length first reaches each
    multiple of ``step`` [m], and its last vertex."""
    if len(xy) <= 2:
        return xy
    seg = np.hypot(*np.diff(xy, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    idx = np.unique(np.r_[np.searchsorted(s, np.arange(0.0, s[-1], step)), len(xy) - 1])
    return xy[idx]


def lanelet_marker_id(lanelet_id: str) -> int:
    """Stable non-negative int32 marker id of a lanelet id."""
    return zlib.crc32(str(lanelet_id).encode('utf-8')) & 0x7FFFFFFF


class _Builder:
    def __init__(self, types, header):
        self.types, self.header = types, header
        g = types.get
        self.Marker, self.Point, self.Color = (g('visualization_msgs/msg/Marker'),
                                               g('geometry_msgs/msg/Point'), g('std_msgs/msg/ColorRGBA'))
        self.Pose, self.Quat, self.Vec = (g('geometry_msgs/msg/Pose'), g('geometry_msgs/msg/Quaternion'),
                                          g('geometry_msgs/msg/Vector3'))

    def color(self, key):
        r, g, b, a = COLORS[key]
        return self.Color(r=r, g=g, b=b, a=a)

    def points(self, xy):
        return self.types.points(xy)

    def line(self, xy):
        """Points of a line strip, one about every :data:`DRAW_STEP` (display only)."""
        return self.types.points(thin(np.asarray(xy, float).reshape(-1, 2), DRAW_STEP))

    def marker(self, ns, mid, mtype, color, scale=(0.2, 0.2, 0.2), points=(), position=(0.0, 0.0),
               text='', action=ADD):
        pose = self.Pose(position=self.Point(x=float(position[0]), y=float(position[1]), z=0.0),
                         orientation=self.Quat(x=0.0, y=0.0, z=0.0, w=1.0))
        return self.Marker(header=self.header, ns=ns, id=int(mid), type=mtype, action=action,
                           pose=pose, scale=self.Vec(x=scale[0], y=scale[1], z=scale[2]),
                           color=self.color(color), points=list(points), text=text)


def _arrow_triangles(center: np.ndarray) -> np.ndarray:
    """(3k, 2) triangle corners pointing along a polyline every ``_ARROW_SPACING`` m."""
    c = np.asarray(center, float).reshape(-1, 2)
    if len(c) < 2:
        return np.zeros((0, 2))
    seg = np.diff(c, axis=0)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))])
    if s[-1] <= 0:
        return np.zeros((0, 2))
    at = np.arange(0.5 * min(_ARROW_SPACING, s[-1]), s[-1], _ARROW_SPACING)
    pos = np.stack([np.interp(at, s, c[:, 0]), np.interp(at, s, c[:, 1])], axis=1)
    i = np.clip(np.searchsorted(s, at) - 1, 0, len(seg) - 1)
    d = seg[i] / np.maximum(np.hypot(seg[i, 0], seg[i, 1]), 1e-9)[:, None]
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)
    h = 0.5 * _ARROW_SIZE
    tri = np.stack([pos + d * h, pos - d * h + n * h * 0.6, pos - d * h - n * h * 0.6], axis=1)
    return tri.reshape(-1, 2)


def _lanelet_markers(b: _Builder, ll, mid: int) -> list:
    connector = ll.kind == 'connector'
    bound = 'virtual_bound' if connector else 'bound'
    width = 0.08 if connector else 0.15
    out = [b.marker('left_lane_bound', mid, LINE_STRIP, bound, (width, 0, 0), b.line(ll.left)),
           b.marker('right_lane_bound', mid, LINE_STRIP, bound, (width, 0, 0), b.line(ll.right)),
           b.marker('connectors' if connector else 'center_lane_line', mid, LINE_STRIP, ll.kind,
                    (0.15, 0, 0), b.line(ll.center))]
    tri = _arrow_triangles(ll.center)
    if len(tri):
        out.append(b.marker('center_line_arrows', mid, TRIANGLE_LIST, 'arrow', (1.0, 1.0, 1.0),
                            b.points(tri)))
    c = np.asarray(ll.center, float).reshape(-1, 2)
    if len(c):
        out.append(b.marker('lanelet_id', mid, TEXT_VIEW_FACING, 'text', (0, 0, 1.0),
                            position=c[len(c) // 2], text=str(ll.id)))
    return out


def _arm_length(center, arm_index, lanelets, default=30.0) -> float:
    pts = [np.asarray(ll.center, float).reshape(-1, 2) for ll in lanelets
           if ll.arm == arm_index and ll.kind != 'connector']
    if not pts:
        return default
    d = np.hypot(*(np.concatenate(pts) - center).T)
    return float(d.max()) if len(d) else default


def _unique_ids(lanelets) -> dict[str, int]:
    """Lanelet id -> marker id, hash collisions resolved deterministically."""
    used, out = set(), {}
    for lid in sorted(str(ll.id) for ll in lanelets):
        mid = lanelet_marker_id(lid)
        while mid in used:
            mid = (mid + 1) & 0x7FFFFFFF
        used.add(mid)
        out[lid] = mid
    return out


def markers_msg(types, header, intersection, lanelets=(), previous_keys=frozenset()):
    """(MarkerArray, keys): markers of the estimate plus DELETEs for ``previous_keys`` that
    are gone; pass the returned ``keys`` (a frozenset of ``(ns, id)``) to the next call."""
    b = _Builder(types, header)
    markers = []
    if intersection is not None:
        c = np.asarray(intersection.center, float)
        markers.append(b.marker('center', 0, SPHERE, 'center', (2.0, 2.0, 2.0), position=c))
        for i, arm in enumerate(intersection.arms):
            end = c + _arm_length(c, i, lanelets) * np.array([math.cos(arm.angle), math.sin(arm.angle)])
            markers.append(b.marker('arm_axes', i, ARROW, 'arm', (0.3, 1.0, 1.5), b.points([c, end])))
    ids = _unique_ids(lanelets)
    for ll in lanelets:
        markers.extend(_lanelet_markers(b, ll, ids[str(ll.id)]))
    keys = frozenset((m.ns, int(m.id)) for m in markers)
    for ns, mid in sorted(set(previous_keys) - keys):
        markers.append(b.marker(ns, mid, ARROW, 'arrow', action=DELETE))
    return types.get('visualization_msgs/msg/MarkerArray')(markers=markers), keys


def clear_markers_msg(types, header):
    """MarkerArray with one DELETEALL (empty namespace: every marker of the display): what a
    reset publishes, so that RViz / Foxglove drop the previous intersection's lanes."""
    b = _Builder(types, header)
    return types.get('visualization_msgs/msg/MarkerArray')(
        markers=[b.marker('', 0, ARROW, 'arrow', action=DELETEALL)])
