"""Initialisation of the lane-course step from the topology (paper §III-A, Fig. 5).

1. Trajectories (rows with ``track_id >= 0``, sorted by ``t``) are split at the point
   closest to the center (paper §II-A).
2. Each part goes to the lane of its driving direction whose center line (a ray of the
   topology model) is closest to the part's mean point.
3. Every entering/leaving lane of the topology becomes a straight lanelet between the
   arm's *stop distance* and the extent of the observed traffic; a pair of entering and
   leaving lanes that a trajectory connects gets a straight connector lanelet.

Stop distance (where lanes end at the intersection): the road edges of two adjacent
arms ``a``, ``b`` (half widths ``h_a``, ``h_b``, angle ``D`` between them) meet at
``(h_b + h_a cos D) / sin D`` along ``a``; a kerb of radius ``kerb_radius`` rounding
that corner needs ``kerb_radius * tan((pi - D) / 2)`` more. The stop line of ``a`` is
the larger of its two corners (at least its own half width) plus ``stop_margin``,
clipped to ``[stop_min, stop_max]``; neighbours 160 deg or more away do not constrain
it. Lanelets of both directions of an arm end/start at that distance.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math

import numpy as np
from numba import njit

from ..model import ENTERING, LEAVING, Intersection
from ..observations import Detections
from .config import LaneConfig
from .model import LaneletSpec
from .follow import arm_shift, driven_lanes, follow_borders, nearest_lanes, with_points
from .halts import entering_halts
from .spline import noise_variance, traffic_connector

__all__ = ['Trajectory', 'trajectories', 'split_at_center', 'stop_distances', 'assign_parts',
           'lane_specs', 'add_connectors', 'lane_id', 'connector_id']


@dataclass
class Trajectory:
    """One tracked object: positions sorted by time, split index at the center."""

    track_id: int
    xy: np.ndarray
    split: int = 0
    lane_in: tuple | None = None     # (arm, k) of the entering part
    lane_out: tuple | None = None    # (arm, k) of the leaving part


def track_rows(dets: Detections | None, skip_labels=()) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """``(track id, xy, t)`` per track of the rows with ``track_id >= 0``, sorted by ``t``;
    id -1 ignored, and rows whose classification label is in ``skip_labels`` (beyond the
    paper: road users that do not keep to a lane center, ``LaneConfig.skip_labels``)."""
    if dets is None or len(dets) == 0:
        return []
    ok = dets.track_mask(skip_labels)
    if not ok.any():
        return []
    ids, xy, t = dets.track_id[ok], dets.xy[ok], dets.t[ok]
    order = np.lexsort((t, ids))
    ids, xy, t = ids[order], xy[order], t[order]
    cuts = np.flatnonzero(np.diff(ids)) + 1
    return [(int(i[0]), p, q) for i, p, q in zip(np.split(ids, cuts), np.split(xy, cuts), np.split(t, cuts))]


def trajectories(dets: Detections | None, skip_labels=()) -> list[Trajectory]:
    """:func:`track_rows` as :class:`Trajectory` objects (positions in time order)."""
    return [Trajectory(i, xy) for i, xy, _ in track_rows(dets, skip_labels)]


def split_at_center(xy: np.ndarray, center: np.ndarray) -> int:
    """Index of the point closest to the center; parts are ``xy[:k+1]`` and ``xy[k:]``."""
    return int(np.argmin(np.sum((xy - center) ** 2, axis=1)))


def _corner(hw_i: float, hw_j: float, theta: float, kerb: float) -> float:
    """Distance along arm i to clear neighbour j at angle ``theta`` with a kerb radius."""
    if theta >= math.radians(160.0) or theta < 1e-3:
        return 0.0
    corner = (hw_j + hw_i * math.cos(theta)) / math.sin(theta)
    return max(0.0, corner + kerb * math.tan(0.5 * (math.pi - theta)))


def stop_distances(topo: Intersection, cfg: LaneConfig) -> np.ndarray:
    """Stop-line distance from the center per arm (module docstring)."""
    arms = topo.arms
    n = len(arms)
    out = np.full(n, cfg.stop_min)
    if n == 0:
        return out
    hw = np.array([a.half_width() for a in arms])
    ang = np.array([a.angle for a in arms])
    for i in range(n):
        s = hw[i]
        if n > 1:
            nxt, prv = (i + 1) % n, (i - 1) % n
            s = max(s, _corner(hw[i], hw[nxt], float((ang[nxt] - ang[i]) % (2 * math.pi)),
                               cfg.kerb_radius),
                    _corner(hw[i], hw[prv], float((ang[i] - ang[prv]) % (2 * math.pi)),
                            cfg.kerb_radius))
        out[i] = min(max(s + cfg.stop_margin, cfg.stop_min), cfg.stop_max)
    return out


def _lane_rays(topo: Intersection, frames=None):
    """(arm, k, direction, origin, u, n, lateral position) of every topology lane."""
    frames = arm_frames(topo) if frames is None else frames
    for ai, f in enumerate(frames):
        for (d, k), lat in sorted(f.lat.items()):
            yield ai, k, d, f.origin, f.u, f.n, lat


@njit(cache=True)
def _assign_nb(pts, tptr, split, r_arm, r_dir, r_o, r_u, r_n, r_lat, stops, inside, min_pts,
               min_len, gate, out_in, out_out, reach):
    """Best ray per trajectory part (see :func:`assign_parts`); -1 where none qualifies. An
    entering part is placed by its points within ``reach`` beyond the stop line when it has
    ``min_pts`` of them, else by all its points that count (from ``inside`` into the box on)."""
    for i in range(len(tptr) - 1):
        a0, a1, sp = tptr[i], tptr[i + 1], tptr[i] + split[i]
        for part in range(2):
            lo, hi = (a0, sp + 1) if part == 0 else (sp, a1)
            d = 1 if part == 0 else -1
            best, lane = gate, -1
            if hi - lo >= max(2, min_pts):
                for r in range(len(r_arm)):
                    if r_dir[r] != d:
                        continue
                    cnt, first, last, lat = 0, 0.0, 0.0, 0.0
                    cn, ln = 0, 0.0         # the entering part next to the stop line
                    for q in range(lo, hi):
                        rx, ry = pts[q, 0] - r_o[r, 0], pts[q, 1] - r_o[r, 1]
                        s = rx * r_u[r, 0] + ry * r_u[r, 1]
                        if s > stops[r_arm[r]] - inside:
                            if cnt == 0:
                                first = s
                            last = s
                            lat += rx * r_n[r, 0] + ry * r_n[r, 1]
                            cnt += 1
                            if part == 0 and stops[r_arm[r]] < s <= stops[r_arm[r]] + reach:
                                ln += rx * r_n[r, 0] + ry * r_n[r, 1]
                                cn += 1
                    if cnt < min_pts or (last - first) * (-d) < min_len:
                        continue
                    dist = abs((ln / cn if cn >= min_pts else lat / cnt) - r_lat[r])
                    if dist < best:
                        best, lane = dist, r
            if part == 0:
                out_in[i] = lane
            else:
                out_out[i] = lane


def assign_parts(trajs: list[Trajectory], topo: Intersection, cfg: LaneConfig,
                 stops: np.ndarray | None = None, frames=None) -> None:
    """Split every trajectory and assign its parts to lanes (paper §III-A).

    A part goes to the lane of its direction whose ray is closest to the mean of the
    part's points beyond that arm's stop line (the paper takes the mean of the whole
    part; points inside the intersection belong to the turn and would bias it). The
    part must head the lane's way and have ``min_part_points`` points there spanning
    at least ``min_part_length`` metres.

    An entering part is placed by its points between the stop line and ``assign_reach``
    metres beyond it (when it has ``min_part_points`` there; beyond the paper): a lane is
    the lane at the stop line, where its connectors start. Farther out the approach curves
    and turn pockets end, so the whole part's mean lies metres from the lane the vehicle
    drives at the stop line, in the straight frame of §III-A (on SUMO dev seed 4 at 9-12 m
    against 2.1-2.7 m next to the stop line); ``lanes/follow.py`` bends the lanes to the
    far traffic afterwards (docs/real_junctions.md, "Lanes placed next to the stop line").

    "Beyond the stop line" reaches ``assign_inside`` metres into the box (beyond the
    paper): the stop line here is a construction from the arms' corners, and on real
    junctions it lies metres farther out than the lane's true end (docs/real_junctions.md,
    "Parts that end near the box"); a vehicle the sensor saw only a few metres past it --
    a track that begins in the box or leaves the sensor's range just after it -- would
    otherwise give no part, and its turn no connector.
    """
    if stops is None:
        stops = stop_distances(topo, cfg)
    rays = list(_lane_rays(topo, frames))
    for tr in trajs:
        tr.lane_in = tr.lane_out = None
        tr.split = split_at_center(tr.xy, topo.center) if len(tr.xy) else 0
    if not rays or not trajs:
        return
    pts = np.ascontiguousarray(np.concatenate([tr.xy for tr in trajs]), dtype=float)
    tptr = np.concatenate([[0], np.cumsum([len(tr.xy) for tr in trajs])]).astype(np.int64)
    split = np.array([tr.split for tr in trajs], np.int64)
    r_arm = np.array([r[0] for r in rays], np.int64)
    r_dir = np.array([r[2] for r in rays], np.int64)
    r_o, r_u, r_n = (np.array([r[i] for r in rays], float) for i in (3, 4, 5))
    r_lat = np.array([r[6] for r in rays], float)
    li = np.full(len(trajs), -1, np.int64)
    lo = np.full(len(trajs), -1, np.int64)
    _assign_nb(pts, tptr, split, r_arm, r_dir, r_o, r_u, r_n, r_lat,
               np.asarray(stops, float), cfg.assign_inside, cfg.min_part_points,
               cfg.min_part_length, cfg.assign_gate, li, lo, cfg.assign_reach)
    for tr, a, b in zip(trajs, li, lo):
        tr.lane_in = (int(r_arm[a]), rays[a][1]) if a >= 0 else None
        tr.lane_out = (int(r_arm[b]), rays[b][1]) if b >= 0 else None


def lane_id(arm: int, direction: int, k: int) -> str:
    return f'a{arm}_{"in" if direction == ENTERING else "out"}{k}'


def connector_id(a: int, k: int, b: int, j: int) -> str:
    return f'c{a}_{k}-{b}_{j}'


@dataclass
class ArmFrame:
    """Straight lanes of one arm: ``origin + s * u + lat * n`` (``n`` left of ``u``).

    ``lat[(direction, k)]`` is the lateral position of lane ``k``'s center line."""

    origin: np.ndarray
    u: np.ndarray
    n: np.ndarray
    lat: dict
    width: float

    def point(self, s, lat):
        return self.origin + np.multiply.outer(s, self.u) + np.multiply.outer(lat, self.n)


#: how far out the lane step's straight arm meets a bent arm's axis [m] (:func:`chord_arms`)
CHORD_M = 50.0


def chord_arms(topo: Intersection, reach: float = CHORD_M) -> Intersection:
    """``topo`` with every bent arm (``Arm.bend``, topology/arm_bend.py) replaced by the
    straight arm from its axis origin to the point ``reach`` metres along its bent axis:
    the lane step starts from straight lanes (§III-A) and bends them to the traffic itself
    (``follow.py``); a bent arm's angle is that of its piece next to the box, and a straight
    lane at that angle runs off the traffic beyond the kink. Unchanged (the same object)
    when no arm bends."""
    if all(a.bend == 0.0 for a in topo.arms):
        return topo
    arms = []
    for a in topo.arms:
        if a.bend != 0.0 and a.bend_at < reach:
            u2 = np.array([math.cos(a.angle + a.bend), math.sin(a.angle + a.bend)])
            p = a.bend_at * a.direction + (reach - a.bend_at) * u2
            a = replace(a, angle=math.atan2(p[1], p[0]))
        arms.append(replace(a, bend=0.0, bend_at=0.0))
    out = replace(topo, arms=arms)
    # the lane ids and supports go by arm index: a chord that would reorder the arms is not taken
    if [id(a) for a in out.arms] != [id(a) for a in arms]:
        return replace(topo, arms=[replace(a, bend=0.0, bend_at=0.0) for a in topo.arms])
    return out


def arm_frames(topo: Intersection) -> list[ArmFrame]:
    """Frames exactly as the topology model has them (paper §II-B)."""
    out = []
    for a in topo.arms:
        lat = {(d, k): float(o) for d in (ENTERING, LEAVING)
               for k, o in enumerate(a.lane_offsets(d, topo.traffic_side))}
        out.append(ArmFrame(topo.center.copy(), a.direction, a.normal, lat, a.lane_width))
    return out


def _part_points(tr: Trajectory, d: int) -> np.ndarray:
    return tr.xy[:tr.split + 1] if d == ENTERING else tr.xy[tr.split:]


def fit_frames(topo: Intersection, trajs: list[Trajectory], stops: np.ndarray,
               cfg: LaneConfig) -> list[ArmFrame]:
    """Re-fit each arm's direction and lane positions to its assigned trajectory parts.

    The topology step treats lanes as rays with one width per arm; its angle and
    center errors shift the lanes sideways. Per arm we take the principal direction
    of the pooled part points (each lane's mean removed) ``fit_margin`` beyond the stop
    line (clear of the turns even if the stop line is off), and per
    lane the mean lateral position, shrunk towards a line across the lanes of that
    direction (:func:`_fit_lane_positions`, ``lane_prior_points`` pseudo points).
    Entering parts count up to ``assign_reach`` beyond the stop line, as their assignment
    (:func:`assign_parts`).
    """
    frames = arm_frames(topo)
    groups: dict = {}
    for tr in trajs:
        for d, lane in ((ENTERING, tr.lane_in), (LEAVING, tr.lane_out)):
            if lane is None:
                continue
            a, k = lane
            P = _part_points(tr, d)
            sa = (P - topo.center) @ frames[a].u
            near = sa <= stops[a] + cfg.assign_reach if d == ENTERING else True
            P = P[(sa > stops[a] + cfg.fit_margin) & near]
            if len(P):
                groups.setdefault(a, {}).setdefault((d, k), []).append(P)
    for a, lanes in groups.items():
        f = frames[a]
        pts = {key: np.concatenate(v) for key, v in lanes.items()}
        centred = np.concatenate([P - P.mean(0) for P in pts.values()])
        if len(centred) >= cfg.min_fit_points:
            w, V = np.linalg.eigh(centred.T @ centred)
            u = V[:, 1] * np.sign(V[:, 1] @ f.u)
            if u @ f.u > math.cos(math.radians(cfg.max_refit_angle_deg)):
                f.u, f.n = u, np.array([-u[1], u[0]])
        obs = {key: float(np.mean((P - f.origin) @ f.n)) for key, P in pts.items()}
        cnt = {key: len(P) for key, P in pts.items()}
        for d in (ENTERING, LEAVING):
            _fit_lane_positions(f, d, obs, cnt, cfg.lane_prior_points)
    return frames


def _fit_lane_positions(f: ArmFrame, d: int, obs: dict, cnt: dict, n0: float) -> None:
    """Lane positions of one direction of an arm: line ``lat_k = alpha + beta k`` fitted
    to the lanes' mean lateral positions (weights = point counts; one observed lane
    fits only ``alpha`` with the topology's spacing), each lane then shrunk towards
    the line with ``n0`` pseudo points. Lanes without points sit on the line."""
    keys = sorted(k for k in f.lat if k[0] == d)
    if not keys:
        return
    ks = np.array([k for _, k in keys], float)
    prior = np.array([f.lat[key] for key in keys])
    seen = [i for i, key in enumerate(keys) if key in obs]
    if not seen:
        return
    y = np.array([obs[keys[i]] for i in seen])
    w = np.array([cnt[keys[i]] for i in seen], float)
    beta = (prior[-1] - prior[0]) / (ks[-1] - ks[0]) if len(keys) > 1 else 0.0
    if len(seen) >= 2 and np.ptp(ks[seen]) > 0:
        A = np.stack([np.ones(len(seen)), ks[seen]], axis=1) * np.sqrt(w)[:, None]
        alpha, beta = np.linalg.lstsq(A, y * np.sqrt(w), rcond=None)[0]
    else:
        alpha = float(np.sum(w * (y - beta * ks[seen])) / w.sum())
    line = alpha + beta * ks
    for i, key in enumerate(keys):
        f.lat[key] = (cnt[key] * obs[key] + n0 * line[i]) / (cnt[key] + n0) if key in obs \
            else float(line[i])


def _farthest(trajs, frames) -> dict:
    """(arm, direction) -> farthest projection of an assigned part's point on the arm."""
    far: dict = {}
    for tr in trajs:
        for d, lane in ((ENTERING, tr.lane_in), (LEAVING, tr.lane_out)):
            if lane is not None:
                f = frames[lane[0]]
                P = _part_points(tr, d)
                if len(P):
                    v = float(np.max((P - f.origin) @ f.u))
                    far[(lane[0], d)] = max(far.get((lane[0], d), -np.inf), v)
    return far


def _extent(far: dict, ai, d, stop, cfg, length):
    """Lanelet length of arm ``ai`` direction ``d``: covers its trajectory points."""
    if length is not None:
        return float(length)
    v = far.get((ai, d), stop + cfg.arm_length_min)
    return float(np.clip(v - stop, cfg.arm_length_min, cfg.arm_length_max))


def _border_positions(lat: list[float], width: float) -> np.ndarray:
    """Lateral positions of the K+1 borders of K lanes ordered from the median out."""
    lat = np.asarray(lat, float)
    side = 1.0 if lat[-1] >= lat[0] else -1.0
    if len(lat) == 1:
        side = 1.0 if lat[0] >= 0 else -1.0
    b = np.empty(len(lat) + 1)
    b[0] = lat[0] - side * 0.5 * width
    b[-1] = lat[-1] + side * 0.5 * width
    b[1:-1] = 0.5 * (lat[:-1] + lat[1:])
    return b


def _lane_points(trajs) -> dict:
    """(arm, direction, k) -> the trajectory parts (m, 2) assigned to that lane."""
    out: dict = {}
    for tr in trajs:
        for d, lane in ((ENTERING, tr.lane_in), (LEAVING, tr.lane_out)):
            if lane is not None:
                out.setdefault((lane[0], d, lane[1]), []).append(_part_points(tr, d))
    return out


def _follow_shifts(f, a, ai, stop, exts, lane_pts, cfg, trajs=(), halts=None) -> tuple[dict, dict]:
    """direction -> common lateral shift of its lanes fitted to their traffic
    (``lanes/follow.py``; None: straight), and direction -> that traffic per lane
    (``follow.driven_lanes``). With ``follow_reassign`` the parts of a direction whose axis
    bends are then re-assigned to its lanes along the bent axis (:func:`_reassign`, updates
    ``lane_pts`` and the trajectories). The shift is not refitted: the parts that move lie
    about a lane width from the lane they had, mostly beyond ``follow_gate``, and barely
    shaped it (refitted: SUMO dev 100-129 / 130-159 lanes 27.7 / 29.0 cm instead of 27.9 /
    28.9). ``halts`` (``lanes/halts.py``, ``halt_follow``): the halted vehicles, one point
    each of the entering lane nearest them."""
    if not cfg.follow_lanes or not (lane_pts or halts is not None and len(halts[0])):
        return {}, {}
    out, driven = {}, {}
    for d, ext in exts.items():
        n_lanes = a.lanes_in if d == ENTERING else a.lanes_out
        lats = [f.lat[(d, k)] for k in range(n_lanes)]
        parts = [lane_pts.get((ai, d, k), []) for k in range(n_lanes)]
        held = entering_halts(f, halts, stop, stop + ext) \
            if d == ENTERING and halts is not None and cfg.halt_follow else np.zeros((0, 2))
        if not any(parts) and not len(held):
            continue
        # halted vehicles: one observation each, on the lane nearest them
        driven[d] = with_points(f, None, lats, driven_lanes(parts, f, stop, stop + ext, cfg),
                                held, cfg.follow_corr_length, stop, stop + ext)
        out[d] = arm_shift(f, lats, driven[d], stop, stop + ext, cfg)
        if cfg.follow_reassign and n_lanes > 1 and out[d] is not None and \
                _reassign(trajs, f, out[d], ai, d, lats, stop, stop + ext, lane_pts, cfg):
            parts = [lane_pts.get((ai, d, k), []) for k in range(n_lanes)]
            driven[d] = with_points(f, out[d], lats, driven_lanes(parts, f, stop, stop + ext, cfg),
                                    held, cfg.follow_corr_length, stop, stop + ext)
    return out, driven


def _reassign(trajs, f, g, ai, d, lats, lo, hi, lane_pts, cfg) -> bool:
    """Re-assign the parts of arm ``ai``, direction ``d`` to its lanes by their offset from
    the shifted axis (``follow.nearest_lanes``); True when any part moved."""
    mine = [tr for tr in trajs if _lane_of(tr, d) is not None and _lane_of(tr, d)[0] == ai]
    if not mine:
        return False
    new = nearest_lanes(f, g, lats, [_part_points(tr, d) for tr in mine], lo, hi, cfg)
    moved = False
    for tr, k in zip(mine, new):
        if 0 <= k != _lane_of(tr, d)[1]:
            moved = True
            if d == ENTERING:
                tr.lane_in = (ai, int(k))
            else:
                tr.lane_out = (ai, int(k))
    if moved:
        for k in range(len(lats)):
            lane_pts.pop((ai, d, k), None)
        lane_pts.update({key: parts for key, parts in _lane_points(mine).items()
                         if key[:2] == (ai, d)})
    return moved


def _lane_of(tr: Trajectory, d: int) -> tuple | None:
    """(arm, k) of the trajectory's part in direction ``d``."""
    return tr.lane_in if d == ENTERING else tr.lane_out


def _lane_deviation(mode: int, d: int) -> str | None:
    """What each lane of direction ``d`` gets beside the common shift under
    ``LaneConfig.follow_per_lane`` ``mode``: 'shape' (its own deviation), 'constant' (a
    constant offset) or None."""
    if mode == 1 or (mode in (2, 3) and d == ENTERING):
        return 'shape'
    return 'constant' if mode == 3 and d == LEAVING else None


def _arm_borders(f, d, b, stop, ext, n_st, n_lanes, cfg, shifts, driven):
    """(K + 1, n_st, 2) border polylines from the stop line outwards: straight (paper
    §III-A) or, with ``follow_lanes``, shaped by the lanes' traffic (``lanes/follow.py``;
    ``shifts`` / ``driven`` of :func:`_follow_shifts`)."""
    if cfg.follow_lanes and d in driven:
        shaped = follow_borders(f, [f.lat[(d, k)] for k in range(n_lanes)], b, stop,
                                stop + ext, n_st, driven[d], cfg, shifts.get(d),
                                _lane_deviation(cfg.follow_per_lane, d))
        if shaped is not None:
            return shaped
    s = np.linspace(stop, stop + ext, n_st)
    return np.stack([f.point(s, bj) for bj in b])


def _straight_lanes(topo, frames, stops, trajs, cfg, length, halts=None):
    """Entering/leaving specs and the interior neighbour pairs of each arm."""
    specs, pairs, index = [], [], {}
    far = _farthest(trajs, frames) if length is None else {}
    lane_pts = _lane_points(trajs) if cfg.follow_lanes else {}
    for ai, a in enumerate(topo.arms):
        f = frames[ai]
        exts = {d: _extent(far, ai, d, stops[ai], cfg, length) for d in (ENTERING, LEAVING)
                if (a.lanes_in if d == ENTERING else a.lanes_out) > 0}
        shifts, driven = _follow_shifts(f, a, ai, stops[ai], exts, lane_pts, cfg, trajs, halts)
        for d in (ENTERING, LEAVING):
            n_lanes = a.lanes_in if d == ENTERING else a.lanes_out
            if n_lanes <= 0:
                continue
            b = _border_positions([f.lat[(d, k)] for k in range(n_lanes)], f.width)
            ext = exts[d]
            n_st = max(2, int(round(ext / cfg.station_spacing)) + 1)
            geo = _arm_borders(f, d, b, stops[ai], ext, n_st, n_lanes, cfg, shifts, driven)
            if d == ENTERING:
                geo = geo[:, ::-1]
            end = 0 if d == LEAVING else n_st - 1
            first = len(specs)
            for k in range(n_lanes):
                # left of the driving direction is -n when entering, +n when leaving
                inner_left = (b[k] < b[k + 1]) == (d == ENTERING)
                li, ri = (k, k + 1) if inner_left else (k + 1, k)
                lk = [None] * n_st
                rk = [None] * n_st
                lk[end], rk[end] = ('end', ai, d, li), ('end', ai, d, ri)
                specs.append(LaneletSpec(
                    id=lane_id(ai, d, k), kind='entering' if d == ENTERING else 'leaving',
                    arm=ai, left=geo[li].copy(), right=geo[ri].copy(), left_keys=lk,
                    right_keys=rk, lane_index=k))
                index[(ai, d, k)] = len(specs) - 1
            # neighbour k shares its outer border with k+1's inner border (interior stations)
            for k in range(n_lanes - 1):
                sa, sb = first + k, first + k + 1
                side_a = 1 if specs[sa].right_keys[end][3] == k + 1 else 0
                for i in range(1, n_st - 1):
                    pairs.append(((sa, i, side_a), (sb, i, 1 - side_a), True))
    return specs, pairs, index


@njit(cache=True)
def arc_handle(chord, cos_phi):
    """Handle length of the cubic Bezier that approximates a circular arc through the turn
    angle ``phi`` between its unit end tangents (``cos_phi = <t0, t1>``):
    ``h = chord * 2/3 tan(phi/4) / sin(phi/2)``, at most chord/2 (chord/3 when straight).
    The one copy of this formula (connectors, their initial shape, the stop-line paths)."""
    phi = math.acos(min(1.0, max(-1.0, cos_phi)))
    ratio = 2.0 / 3.0 * math.tan(phi / 4) / math.sin(phi / 2) if phi > 1e-6 else 1.0 / 3.0
    return chord * min(ratio, 0.5)


def arc_bezier(p0, t0, p1, t1, s):
    """Cubic Bezier tangent to unit ``t0`` at ``p0`` and ``t1`` at ``p1``, evaluated at ``s``:
    the usual cubic approximation of a circular arc (handles: :func:`arc_handle`)."""
    h = arc_handle(float(np.linalg.norm(p1 - p0)), float(np.dot(t0, t1)))
    q0, q1 = p0 + h * t0, p1 - h * t1
    s = s[:, None]
    return ((1 - s) ** 3 * p0 + 3 * (1 - s) ** 2 * s * q0 + 3 * (1 - s) * s ** 2 * q1
            + s ** 3 * p1)


@njit(cache=True)
def _connector_geometry(L0, R0, L1, R1, t0, t1, arc_shape, spacing, min_st):
    """Left/right borders of a connector (see :func:`_connector_borders`)."""
    c0, c1 = 0.5 * (L0 + R0), 0.5 * (L1 + R1)
    chord = math.hypot(c1[0] - c0[0], c1[1] - c0[1])
    h = 0.0
    if arc_shape:
        h = arc_handle(chord, t0[0] * t1[0] + t0[1] * t1[1])
    q0, q1 = c0 + h * t0, c1 - h * t1         # h = 0: the straight chord
    m = 64
    s = np.linspace(0.0, 1.0, m)
    arc = np.zeros(m)
    px, py = c0[0], c0[1]
    for i in range(1, m):
        u = s[i]
        a, b, c, d = (1 - u) ** 3, 3 * (1 - u) ** 2 * u, 3 * (1 - u) * u ** 2, u ** 3
        x = a * c0[0] + b * q0[0] + c * q1[0] + d * c1[0]
        y = a * c0[1] + b * q0[1] + c * q1[1] + d * c1[1]
        arc[i] = arc[i - 1] + math.hypot(x - px, y - py)
        px, py = x, y
    n = max(min_st, int(round(max(arc[-1], chord) / spacing)) + 1)
    q = np.interp(np.linspace(0.0, arc[-1], n), arc, s)
    left, right = np.empty((n, 2)), np.empty((n, 2))
    for i in range(n):
        u = q[i]
        a, b, c, d = (1 - u) ** 3, 3 * (1 - u) ** 2 * u, 3 * (1 - u) * u ** 2, u ** 3
        cx = a * c0[0] + b * q0[0] + c * q1[0] + d * c1[0]
        cy = a * c0[1] + b * q0[1] + c * q1[1] + d * c1[1]
        tx = 3 * (1 - u) ** 2 * (q0[0] - c0[0]) + 6 * (1 - u) * u * (q1[0] - q0[0]) \
            + 3 * u ** 2 * (c1[0] - q1[0])
        ty = 3 * (1 - u) ** 2 * (q0[1] - c0[1]) + 6 * (1 - u) * u * (q1[1] - q0[1]) \
            + 3 * u ** 2 * (c1[1] - q1[1])
        tn = max(math.hypot(tx, ty), 1e-12)
        nx, ny = -ty / tn, tx / tn
        wl = math.hypot((1 - u) * (L0[0] - c0[0]) + u * (L1[0] - c1[0]),
                        (1 - u) * (L0[1] - c0[1]) + u * (L1[1] - c1[1]))
        wr = math.hypot((1 - u) * (R0[0] - c0[0]) + u * (R1[0] - c1[0]),
                        (1 - u) * (R0[1] - c0[1]) + u * (R1[1] - c1[1]))
        left[i, 0], left[i, 1] = cx + wl * nx, cy + wl * ny
        right[i, 0], right[i, 1] = cx - wr * nx, cy - wr * ny
    left[0], right[0], left[n - 1], right[n - 1] = L0, R0, L1, R1
    return left, right


def _connector_borders(E: LaneletSpec, O: LaneletSpec, cfg: LaneConfig):
    """Borders of a connector from the end of ``E`` to the start of ``O``.

    Straight (paper §III-A) or, with ``connector_arc``, a circular-arc-like cubic
    Bezier center line tangent to both lanes (``arc_bezier``); equidistant stations
    (``connector_spacing``), half widths blended from the end cross sections along
    the curve's normal, end points exactly those of the lanes (they are shared)."""
    L0, R0, L1, R1 = E.left[-1], E.right[-1], O.left[0], O.right[0]
    t0 = 0.5 * (E.left[-1] + E.right[-1]) - 0.5 * (E.left[-2] + E.right[-2]) \
        if len(E.left) >= 2 else np.zeros(2)
    t1 = 0.5 * (O.left[1] + O.right[1]) - 0.5 * (O.left[0] + O.right[0]) \
        if len(O.left) >= 2 else np.zeros(2)
    arc_shape = bool(cfg.connector_arc) and len(E.left) >= 2 and len(O.left) >= 2
    t0, t1 = t0 / max(np.linalg.norm(t0), 1e-9), t1 / max(np.linalg.norm(t1), 1e-9)
    return _connector_geometry(np.asarray(L0, float), np.asarray(R0, float),
                               np.asarray(L1, float), np.asarray(R1, float), t0, t1,
                               arc_shape, float(cfg.connector_spacing),
                               int(cfg.connector_min_stations))


def lane_specs(topo: Intersection, trajs: list[Trajectory], cfg: LaneConfig,
               length: float | None = None, connectors: bool = True, stops=None, frames=None,
               halts=None):
    """Specs of all entering/leaving lanelets and (``connectors``) the evidenced
    connectors (:func:`add_connectors`); also the interior neighbour pairs and the index
    ``(arm, direction, k) -> spec``. ``halts``: the halted vehicles
    (``halts.halt_positions``) that shape the entering lanes too."""
    stops = stop_distances(topo, cfg) if stops is None else stops
    frames = arm_frames(topo) if frames is None else frames
    specs, pairs, index = _straight_lanes(topo, frames, stops, trajs, cfg, length, halts)
    if connectors:
        add_connectors(specs, index, trajs, cfg)
    return specs, pairs, index


def add_connectors(specs: list, index: dict, trajs: list[Trajectory], cfg: LaneConfig) -> None:
    """Append to ``specs`` a connector for every pair of entering / leaving lanes that
    ``min_connector_evidence`` trajectories connect (§III-A), shaped by their traffic
    (``connector_traffic``, lanes/spline.py); ``specs`` / ``index`` as :func:`lane_specs`
    made them without connectors."""
    count: dict = {}
    driven: dict = {}
    for tr in trajs:
        if tr.lane_in is not None and tr.lane_out is not None:
            key = (tr.lane_in, tr.lane_out)
            count[key] = count.get(key, 0) + 1
            driven.setdefault(key, []).append(tr.xy)
    # the positions' noise, read once from all the scene's vehicles (lanes/spline.py)
    noise = noise_variance([tr.xy for tr in trajs]) \
        if cfg.traffic_noise and cfg.connector_traffic and count else 0.0
    for ((a, k), (b, j)), m in sorted(count.items()):
        if m < cfg.min_connector_evidence:
            continue
        e, o = index.get((a, ENTERING, k)), index.get((b, LEAVING, j))
        if e is None or o is None:
            continue
        E, O = specs[e], specs[o]
        left, right = _connector_borders(E, O, cfg)
        if cfg.connector_traffic:
            shaped = traffic_connector(E, O, driven[((a, k), (b, j))], cfg, (left, right), noise)
            left, right = shaped if shaped is not None else (left, right)
        n_st = len(left)
        lk = [E.left_keys[-1]] + [None] * (n_st - 2) + [O.left_keys[0]]
        rk = [E.right_keys[-1]] + [None] * (n_st - 2) + [O.right_keys[0]]
        specs.append(LaneletSpec(
            id=connector_id(a, k, b, j), kind='connector', arm=a, arm_to=b, lane_index=k,
            lane_to=j, left=left, right=right,
            left_keys=lk, right_keys=rk, predecessor=e, successor=o, successors=[o],
            evidence=m))
        E.successors.append(len(specs) - 1)
