"""Initialisation of the lane-course step from the topology (paper §III-A, Fig. 5).

1. Trajectories (rows with ``track_id >= 0``, sorted by ``t``) are split at the point
   closest to the center (paper §II-A).
2. Each part goes to the lane of its driving direction whose center line (a ray of the
   topology model) is closest to the part's mean point.
3. Every entering/leaving lane of the topology becomes a straight lanelet between the
   arm's *stop distance* and the extent of the observed traffic; a pair of entering and
   leaving lanes that a trajectory connects gets a straight connector lanelet.

Stop distance (where lanes end at the intersection): the road edges of two adjacent
arms ``a``, ``b`` (half widths ``h_a``, ``h_b`` on the facing sides, angle ``D`` between
them) meet at the distance ``s_a = (h_b + h_a cos D) / sin D`` along ``a``; the stop
line of ``a`` is the larger of its two corners plus ``stop_margin``, clipped to
``[stop_min, stop_max]``. Neighbours more than 135 deg away do not constrain it.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from ..model import ENTERING, LEAVING, Intersection
from ..observations import Detections
from .config import LaneConfig
from .model import LaneletSpec

__all__ = ['Trajectory', 'trajectories', 'split_at_center', 'stop_distances', 'assign_parts',
           'lane_specs', 'lane_id', 'connector_id']


@dataclass
class Trajectory:
    """One tracked object: positions sorted by time, split index at the center."""

    track_id: int
    xy: np.ndarray
    split: int = 0
    lane_in: tuple | None = None     # (arm, k) of the entering part
    lane_out: tuple | None = None    # (arm, k) of the leaving part


def trajectories(dets: Detections | None) -> list[Trajectory]:
    """Rows with ``track_id >= 0`` grouped per id and sorted by ``t``; id -1 ignored."""
    if dets is None or len(dets) == 0:
        return []
    ok = (dets.track_id >= 0) & np.isfinite(dets.xy).all(axis=1) & np.isfinite(dets.t)
    if not ok.any():
        return []
    ids, xy, t = dets.track_id[ok], dets.xy[ok], dets.t[ok]
    order = np.lexsort((t, ids))
    ids, xy = ids[order], xy[order]
    cuts = np.flatnonzero(np.diff(ids)) + 1
    return [Trajectory(int(i[0]), p) for i, p in zip(np.split(ids, cuts), np.split(xy, cuts))]


def split_at_center(xy: np.ndarray, center: np.ndarray) -> int:
    """Index of the point closest to the center; parts are ``xy[:k+1]`` and ``xy[k:]``."""
    return int(np.argmin(np.sum((xy - center) ** 2, axis=1)))


def _facing_half_width(arm, side: int, traffic_side: int) -> float:
    """Half width of ``arm`` on its ``side`` (+1 = +n) side."""
    n_in_side = arm.lanes_in if side * traffic_side > 0 else arm.lanes_out
    return 0.5 * arm.gap + n_in_side * arm.lane_width


def stop_distances(topo: Intersection, cfg: LaneConfig) -> np.ndarray:
    """Stop-line distance from the center per arm (module docstring)."""
    arms, ts = topo.arms, topo.traffic_side
    out = np.full(len(arms), cfg.stop_min)
    for i, a in enumerate(arms):
        s = 0.0
        for j, b in enumerate(arms):
            if j == i:
                continue
            d = (b.angle - a.angle) % (2 * math.pi)       # ccw angle from a to b
            side = 1 if d < math.pi else -1                # b on a's +n or -n side
            D = d if side > 0 else 2 * math.pi - d
            if D > math.radians(135) or D < 1e-3:
                continue
            h_a = _facing_half_width(a, side, ts)
            h_b = _facing_half_width(b, -side, ts)
            s = max(s, (h_b + h_a * math.cos(D)) / math.sin(D))
        out[i] = min(max(s + cfg.stop_margin, cfg.stop_min), cfg.stop_max)
    return out


def _lane_rays(topo: Intersection):
    """(arm, k, direction, origin, u, n, offset) of every topology lane."""
    for ai, a in enumerate(topo.arms):
        for d in (ENTERING, LEAVING):
            for k, off in enumerate(a.lane_offsets(d, topo.traffic_side)):
                yield ai, k, d, a.direction, a.normal, float(off)


def _ray_distance(p: np.ndarray, c: np.ndarray, u, n, off: float) -> float:
    s = float((p - c) @ u)
    lat = float((p - c) @ n) - off
    return abs(lat) if s >= 0 else math.hypot(s, lat)


def assign_parts(trajs: list[Trajectory], topo: Intersection, cfg: LaneConfig) -> None:
    """Split every trajectory and assign its parts to lanes (paper §III-A)."""
    c = topo.center
    rays = list(_lane_rays(topo))
    for tr in trajs:
        if len(tr.xy) < 2 or not rays:
            continue
        tr.split = split_at_center(tr.xy, c)
        for d, part in ((ENTERING, tr.xy[:tr.split + 1]), (LEAVING, tr.xy[tr.split:])):
            if len(part) < cfg.min_part_points or len(part) < 2:
                continue
            m = part.mean(axis=0)
            heading = part[-1] - part[0]
            best, lane = cfg.assign_gate, None
            for ai, k, dd, u, n, off in rays:
                if dd != d or heading @ (-u if d == ENTERING else u) <= 0:
                    continue
                dist = _ray_distance(m, c, u, n, off)
                if dist < best:
                    best, lane = dist, (ai, k)
            if d == ENTERING:
                tr.lane_in = lane
            else:
                tr.lane_out = lane


def lane_id(arm: int, direction: int, k: int) -> str:
    return f'a{arm}_{"in" if direction == ENTERING else "out"}{k}'


def connector_id(a: int, k: int, b: int, j: int) -> str:
    return f'c{a}_{k}-{b}_{j}'


def _extent(trajs, topo, ai, d, stop, cfg, length):
    """Lanelet length of arm ``ai`` direction ``d``: covers its trajectory points."""
    if length is not None:
        return float(length)
    u = topo.arms[ai].direction
    s = [((tr.xy[:tr.split + 1] if d == ENTERING else tr.xy[tr.split:]) - topo.center) @ u
         for tr in trajs if (tr.lane_in if d == ENTERING else tr.lane_out) is not None
         and (tr.lane_in if d == ENTERING else tr.lane_out)[0] == ai]
    far = max((float(np.max(x)) for x in s if len(x)), default=stop + cfg.arm_length_min)
    return float(np.clip(far - stop, cfg.arm_length_min, cfg.arm_length_max))


def _straight_lanes(topo, stops, trajs, cfg, length):
    """Entering/leaving specs and the interior neighbour pairs of each arm."""
    specs, pairs, index = [], [], {}
    ts = topo.traffic_side
    for ai, a in enumerate(topo.arms):
        u, n = a.direction, a.normal
        for d in (ENTERING, LEAVING):
            offs = a.lane_offsets(d, ts)
            if not len(offs):
                continue
            ext = _extent(trajs, topo, ai, d, stops[ai], cfg, length)
            n_st = max(2, int(round(ext / cfg.station_spacing)) + 1)
            s = np.linspace(stops[ai], stops[ai] + ext, n_st)
            if d == ENTERING:
                s = s[::-1]
            lsign = -1.0 if d == ENTERING else 1.0        # left normal of the driving dir in n
            first = len(specs)
            for k, off in enumerate(offs):
                lo, ro = off + lsign * 0.5 * a.lane_width, off - lsign * 0.5 * a.lane_width
                li, ri = (k, k + 1) if abs(lo) < abs(ro) else (k + 1, k)
                base = topo.center + s[:, None] * u
                end = 0 if d == LEAVING else n_st - 1
                lk = [None] * n_st
                rk = [None] * n_st
                lk[end], rk[end] = ('end', ai, d, li), ('end', ai, d, ri)
                specs.append(LaneletSpec(
                    id=lane_id(ai, d, k), kind='entering' if d == ENTERING else 'leaving',
                    arm=ai, left=base + lo * n, right=base + ro * n, left_keys=lk,
                    right_keys=rk, lane_index=k))
                index[(ai, d, k)] = len(specs) - 1
            # neighbour k shares its outer border with k+1's inner border (interior stations)
            for k in range(len(offs) - 1):
                sa, sb = first + k, first + k + 1
                side_a = 1 if specs[sa].right_keys[0 if d == LEAVING else -1][3] == k + 1 else 0
                side_b = 1 - side_a
                for i in range(1, n_st - 1):
                    pairs.append(((sa, i, side_a), (sb, i, side_b), True))
    return specs, pairs, index


def _hermite(p0, t0, p1, t1, s):
    """Cubic Hermite curve with unit end tangents scaled by the chord length."""
    k = float(np.linalg.norm(p1 - p0))
    s = s[:, None]
    return ((2 * s**3 - 3 * s**2 + 1) * p0 + (s**3 - 2 * s**2 + s) * k * t0
            + (-2 * s**3 + 3 * s**2) * p1 + (s**3 - s**2) * k * t1)


def _connector_borders(E: LaneletSpec, O: LaneletSpec, cfg: LaneConfig):
    """Borders of a connector from the end of ``E`` to the start of ``O``.

    Straight (paper §III-A) or, with ``connector_hermite``, a cubic Hermite center
    line tangent to both lanes; equidistant stations, end points exactly those of the
    lanes (they are shared)."""
    L0, R0, L1, R1 = E.left[-1], E.right[-1], O.left[0], O.right[0]
    c0, c1 = 0.5 * (L0 + R0), 0.5 * (L1 + R1)
    chord = float(np.linalg.norm(c1 - c0))
    s = np.linspace(0.0, 1.0, 200)
    if cfg.connector_hermite and len(E.left) >= 2 and len(O.left) >= 2:
        t0 = 0.5 * (E.left[-1] + E.right[-1]) - 0.5 * (E.left[-2] + E.right[-2])
        t1 = 0.5 * (O.left[1] + O.right[1]) - 0.5 * (O.left[0] + O.right[0])
        t0, t1 = t0 / max(np.linalg.norm(t0), 1e-9), t1 / max(np.linalg.norm(t1), 1e-9)
        c = _hermite(c0, t0, c1, t1, s)
    else:
        c = (1 - s[:, None]) * c0 + s[:, None] * c1
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
    n_st = max(cfg.connector_min_stations, int(round(max(arc[-1], chord) / cfg.connector_spacing)) + 1)
    q = np.interp(np.linspace(0.0, arc[-1], n_st), arc, s)
    w = q[:, None]
    # borders: the end cross sections blended along the curve, kept perpendicular-ish
    cc = c0 + 0 * w if arc[-1] < 1e-9 else np.stack(
        [np.interp(q, s, c[:, 0]), np.interp(q, s, c[:, 1])], axis=1)
    hl = (1 - w) * (L0 - c0) + w * (L1 - c1)
    hr = (1 - w) * (R0 - c0) + w * (R1 - c1)
    left, right = cc + hl, cc + hr
    if arc[-1] >= 1e-9:
        t = np.gradient(cc, axis=0)
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
        nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)
        wl = np.linalg.norm(hl, axis=1)
        wr = np.linalg.norm(hr, axis=1)
        left[1:-1] = cc[1:-1] + wl[1:-1, None] * nrm[1:-1]
        right[1:-1] = cc[1:-1] - wr[1:-1, None] * nrm[1:-1]
    left[0], right[0], left[-1], right[-1] = L0, R0, L1, R1
    return left, right


def lane_specs(topo: Intersection, trajs: list[Trajectory], cfg: LaneConfig,
               length: float | None = None, connectors: bool = True):
    """Specs of all entering/leaving lanelets and evidenced straight connectors."""
    stops = stop_distances(topo, cfg)
    specs, pairs, index = _straight_lanes(topo, stops, trajs, cfg, length)
    if not connectors:
        return specs, pairs, index
    count: dict = {}
    for tr in trajs:
        if tr.lane_in is not None and tr.lane_out is not None:
            key = (tr.lane_in, tr.lane_out)
            count[key] = count.get(key, 0) + 1
    for ((a, k), (b, j)), m in sorted(count.items()):
        if m < cfg.min_connector_evidence:
            continue
        e, o = index.get((a, ENTERING, k)), index.get((b, LEAVING, j))
        if e is None or o is None:
            continue
        E, O = specs[e], specs[o]
        left, right = _connector_borders(E, O, cfg)
        n_st = len(left)
        lk = [E.left_keys[-1]] + [None] * (n_st - 2) + [O.left_keys[0]]
        rk = [E.right_keys[-1]] + [None] * (n_st - 2) + [O.right_keys[0]]
        specs.append(LaneletSpec(
            id=connector_id(a, k, b, j), kind='connector', arm=a, arm_to=b, lane_index=k,
            lane_to=j, left=left, right=right,
            left_keys=lk, right_keys=rk, predecessor=e, successor=o, successors=[o],
            evidence=m))
        E.successors.append(len(specs) - 1)
    return specs, pairs, index
