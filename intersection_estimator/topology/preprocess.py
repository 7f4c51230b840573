"""Preprocessing of the topology step (paper §II-A): detections -> ObservationSet.

Three input kinds, decided per row of :class:`observations.Detections`:

* tracked objects (``track_id >= 0``): each trajectory is split at its point closest to
  the current center; each part becomes one observation (mean point, mean direction,
  weight 1). Parts that are too short (false tracks of static clutter) are dropped.
* radar (finite ``doppler``, no id): clutter filter (|doppler| and RCS), driving direction
  from the Doppler sign generalised with the center estimate -- with the line of sight
  ``los = (p - s)/|p - s|`` and radial ``r = (p - c)/|p - c|`` a detection is *leaving* iff
  ``doppler * <r, los> > 0`` (the paper's rule "v > 0 leaving, flipped behind the
  sensor" is the special case of a sensor on an arm); rows with ``|<r, los>|`` small are
  ambiguous and dropped. Then voxelisation per direction class (count-weighted voxels).
* lidar / camera objects (finite ``heading``, no id, no doppler): voxelised per heading
  sector with the mean heading as orientation.

Voxels: :mod:`.voxels`; the initialisation (center, arms, lanes): :mod:`.init`. The
trajectory split is compiled here (:func:`split_tracks`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..model import direction_class, unit_vectors
from ..observations import Detections
from .bend import straighten
from .config import PreprocessConfig
from .likelihood import ObservationSet
from .standing import standing_observations
from .state import wrap
from .voxels import (RAYS, arm_voxel_set, assign_arms, radar_frame, radar_voxels,
                     ray_voxel_set, voxelise)

__all__ = ['PreprocessConfig', 'tracked_observations', 'radar_observations', 'RadarRows',
           'radar_rows', 'radar_filter', 'heading_observations', 'preprocess', 'split_tracks',
           'moving_tracks', 'track_bounds', 'moving_mask']


def tracked_observations(dets: Detections, center, cfg: PreprocessConfig,
                         arm_angles=None, moving=None) -> ObservationSet:
    """Split trajectories at the point closest to ``center``; mean point + direction.
    With ``arm_angles`` and ``bend_min_deg > 0`` the rows of bent approaches are first
    straightened along their arms (:mod:`.bend`, beyond the paper). ``moving``:
    :func:`moving_tracks` of the tracked rows when at hand."""
    order, starts, ends = (moving if moving is not None else
                           moving_tracks(dets, dets.track_id >= 0, cfg.min_track_speed))
    if len(starts) == 0:
        return ObservationSet.empty()
    tid, xy, hd, lab = (dets.track_id[order], dets.xy[order], dets.heading[order],
                        dets.label[order])
    c = np.asarray(center, float)
    if math.isfinite(cfg.track_radius):   # parts made of the rows near the box only
        starts, ends, tid, xy, hd, lab = _rows_within(c, cfg.track_radius, starts, ends, tid, xy,
                                                      hd, lab)
        if len(starts) == 0:
            return ObservationSet.empty()
    track_label = lab[starts]             # per track of the bounds split_tracks reads
    if not np.isfinite(hd).all():      # rows without heading: direction from positions
        for a, b in zip(starts, ends):
            h = hd[a:b]
            if not np.isfinite(h).all():
                hd[a:b] = _path_heading(xy[a:b])
    x, y = xy[:, 0].copy(), xy[:, 1].copy()
    if arm_angles is not None and cfg.bend_min_deg > 0:
        reach = cfg.track_radius + 10.0 if math.isfinite(cfg.track_radius) else 150.0
        x, y, hd, _ = straighten(x, y, hd, starts, ends, c, arm_angles, cfg.part_outside,
                                 reach, cfg.bend_bin, cfg.bend_min_deg)
    o = split_tracks(x, y, hd, starts, ends, float(c[0]), float(c[1]),
                     cfg.min_part_points, cfg.min_part_length, math.radians(cfg.trim_turn_deg), 5,
                     bool(cfg.trim_longest), float(cfg.part_outside), float(cfg.part_piece_m))
    if len(o) == 0:
        return ObservationSet.empty()
    hx, hy, ok = unit_vectors(o[:, 2], o[:, 3])
    d = direction_class(o[:, 0], o[:, 1], hx, hy, c)
    obs = ObservationSet(o[:, 0].copy(), o[:, 1].copy(), hx, hy, ok, d, o[:, 5].copy(),
                         _part_sigma(track_label, o[:, 4].astype(np.int64), cfg),
                         np.full(len(o), math.radians(cfg.sigma_angle_deg)), o[:, 5].copy())
    # parts cut at part_outside: that radius is also their box radius
    return _drop_near_center(obs, c, cfg, far=False,
                             inner=cfg.part_outside if cfg.part_outside > 0 else None)


def _part_sigma(track_label, part_track, cfg: PreprocessConfig) -> np.ndarray:
    """Orthogonal-distance sigma per trajectory part: ``sigma_track``, and
    ``sigma_track_weak`` for road users that do not keep to a lane's center
    (``weak_labels``, Autoware classification ids; by default bicycle 6 and pedestrian 7:
    a cyclist rides at the kerb side of its lane). Beyond the paper: such a part still
    shows that its arm exists and carries traffic, but its lateral position cannot ask for
    a lane of its own."""
    sig = np.full(len(part_track), cfg.sigma_track)
    if cfg.weak_labels and len(part_track):
        weak = np.isin(track_label[part_track], np.asarray(cfg.weak_labels, np.int64))
        sig[weak] = cfg.sigma_track_weak
    return sig


def track_bounds(dets: Detections, sel: np.ndarray):
    """``(order, starts, ends)``: the rows ``sel`` of ``dets`` sorted by track id and time
    (indices into ``dets``) and the bounds in ``order`` of each track."""
    idx = np.flatnonzero(sel)
    order = idx[np.lexsort((dets.t[idx], dets.track_id[idx]))]
    tid = dets.track_id[order]
    starts = np.flatnonzero(np.r_[True, tid[1:] != tid[:-1]]) if len(tid) else np.zeros(0, np.int64)
    return order, starts, np.r_[starts[1:], len(tid)].astype(np.int64)


def moving_mask(dets: Detections, order, starts, min_speed: float) -> np.ndarray:
    """Per track of :func:`track_bounds`: is it not static? With ``min_speed > 0`` and
    speeds known, a track never faster than ``min_speed`` is static: a false track of
    static clutter or a standing vehicle (:mod:`.standing`)."""
    sp = dets.speed[order]
    if min_speed <= 0 or not np.isfinite(sp).any() or len(starts) == 0:
        return np.ones(len(starts), bool)
    return np.maximum.reduceat(np.where(np.isfinite(sp), sp, np.inf), starts) >= min_speed


def moving_tracks(dets: Detections, sel: np.ndarray, min_speed: float):
    """``(order, starts, ends)`` of :func:`track_bounds` for the tracks that are not static
    (:func:`moving_mask`)."""
    order, starts, ends = track_bounds(dets, sel)
    moving = moving_mask(dets, order, starts, min_speed)
    return order, starts[moving], ends[moving]


def _rows_within(c, radius: float, starts, ends, tid, xy, hd, lab):
    """The rows of the kept tracks within ``radius`` of ``c`` (track order kept), and the
    new track bounds (a track with no row within ``radius`` is gone)."""
    keep = np.zeros(len(tid), bool)
    for a, b in zip(starts, ends):
        keep[a:b] = True
    keep &= np.hypot(xy[:, 0] - c[0], xy[:, 1] - c[1]) <= radius
    tid, xy, hd, lab = tid[keep], xy[keep], hd[keep], lab[keep]
    starts = np.flatnonzero(np.r_[True, tid[1:] != tid[:-1]]) if len(tid) else np.zeros(0, np.int64)
    return starts, np.r_[starts[1:], len(tid)].astype(np.int64), tid, xy, hd, lab


def _path_heading(p: np.ndarray) -> np.ndarray:
    """Heading from the positions (central differences) when the rows carry none."""
    if len(p) < 2:
        return np.zeros(len(p))
    d = np.gradient(p, axis=0)
    return np.arctan2(d[:, 1], d[:, 0])


def radar_filter(dets: Detections, cfg: PreprocessConfig, moving_only: bool = True) -> np.ndarray:
    """Mask of radar rows that survive the Doppler / RCS clutter filter (paper §II-A).

    ``moving_only=False`` keeps rows with small |Doppler| whose RCS is known and at least
    ``min_rcs_static`` (vehicles crossing the line of sight, not clutter)."""
    rcs = dets.rcs
    radar = (dets.track_id < 0) & np.isfinite(dets.doppler)
    m = radar & (np.abs(dets.doppler) >= cfg.min_doppler)
    m &= ~(np.isfinite(rcs) & (rcs < cfg.min_rcs))
    if not moving_only and cfg.min_rcs_static < np.inf:
        with np.errstate(invalid='ignore'):
            m |= radar & np.isfinite(rcs) & (rcs >= cfg.min_rcs_static)
    return m


class RadarRows(NamedTuple):
    """Radar rows surviving the clutter filter, center-free (see :func:`radar_rows`)."""

    x: np.ndarray
    y: np.ndarray
    t: np.ndarray
    doppler: np.ndarray
    sensor_x: np.ndarray
    sensor_y: np.ndarray


def radar_rows(dets: Detections, cfg: PreprocessConfig) -> RadarRows:
    """The rows :func:`radar_observations` voxelises, filtered once per data set: callers
    that preprocess the same detections around several centers pass it along."""
    m = radar_filter(dets, cfg, moving_only=False)
    return RadarRows(np.ascontiguousarray(dets.xy[m, 0]), np.ascontiguousarray(dets.xy[m, 1]),
                     dets.t[m], dets.doppler[m], np.ascontiguousarray(dets.sensor_xy[m, 0]),
                     np.ascontiguousarray(dets.sensor_xy[m, 1]))


def radar_observations(dets: Detections, center, cfg: PreprocessConfig,
                       arm_angles=None, rows: RadarRows | None = None) -> ObservationSet:
    """Doppler -> driving direction relative to ``center``, then voxelise per class.

    With ``arm_angles`` (the current arms) the voxels are aligned with the nearest arm:
    ``voxel_length`` along it, ``voxel_width`` across, so a voxel never mixes lanes yet
    covers a long piece of one; voxels without an occupied neighbour voxel in the same
    lateral band on both sides along the arm are dropped -- they are not on a straight
    lane (turning vehicles inside the box, isolated clutter). Rows on no current arm
    (farther than ``arm_reach`` from every arm's axis) are voxelised along :data:`RAYS`
    from the center, so that an arm the chain has not found yet keeps its data. Frame,
    voxels and the near-center drop run in one compiled pass (:func:`.voxels.radar_voxels`).
    Without arms: square voxels.
    """
    rows = radar_rows(dets, cfg) if rows is None else rows
    if not len(rows.t):
        return ObservationSet.empty()
    c = np.asarray(center, float)
    if _arms_known(arm_angles, cfg):
        vx, vy, dcls, cnt = radar_voxels(
            rows.x, rows.y, rows.t, rows.doppler, rows.sensor_x, rows.sensor_y, float(c[0]),
            float(c[1]), np.asarray(arm_angles, float), float(cfg.arm_reach),
            float(cfg.min_radial_cos), float(cfg.min_doppler), bool(cfg.keep_unknown_direction),
            RAYS, float(cfg.voxel_length), float(cfg.voxel_width), bool(cfg.straight_run),
            int(cfg.voxel_merge), float(cfg.passage_gap), float(cfg.min_center_dist))
        obs = _radar_set(vx, vy, dcls, cnt, cfg)
        return _drop_near_center(obs, c, cfg) if math.isfinite(cfg.max_center_dist) else obs
    _, _, _, group, cls = radar_frame(
        rows.x, rows.y, rows.doppler, rows.sensor_x, rows.sensor_y, float(c[0]), float(c[1]),
        np.zeros(0), float(cfg.arm_reach), float(cfg.min_radial_cos), float(cfg.min_doppler),
        bool(cfg.keep_unknown_direction), np.zeros(0))
    b = group == 2
    vxy, vcls, cnt = voxelise(np.stack([rows.x[b], rows.y[b]], axis=1), cls[b],
                              cfg.voxel_size, t=rows.t[b], gap=cfg.passage_gap)[:3]
    dcls = np.select([vcls == 1, vcls == 0], [1.0, -1.0], 0.0)
    obs = _radar_set(vxy[:, 0].copy(), vxy[:, 1].copy(), dcls, cnt, cfg)
    return _drop_near_center(obs, c, cfg)


def _radar_set(x, y, dcls, cnt, cfg: PreprocessConfig) -> ObservationSet:
    """Radar voxels as observations: no orientation, direction class, weight from count."""
    n = len(x)
    z = np.zeros(n)
    return ObservationSet(x, y, z, z.copy(), np.zeros(n, np.bool_), dcls,
                          cfg.weight_scale * cnt ** cfg.weight_power,
                          np.full(n, cfg.sigma_point), np.full(n, 1.0), cnt)


def _arms_known(arm_angles, cfg: PreprocessConfig) -> bool:
    """Are voxels aligned with arms (arms given and arm-aligned voxels configured)?"""
    return arm_angles is not None and len(arm_angles) > 0 and cfg.voxel_length > 0


def _on_arms(xy, c, arm_angles, cfg: PreprocessConfig):
    """Nearest arm, s, t of every row and whether it lies on that arm: ahead of the center
    and within ``arm_reach`` of its axis (lidar / camera rows; radar rows get the same
    frame from :func:`.voxels.radar_frame`). Rows on no current arm are voxelised along
    rays from the center (:func:`.voxels.ray_voxel_set`), so that an arm the chain has not found yet
    keeps its data (aligned with a neighbouring arm they would look like crossing
    traffic and be filtered out, and the arm could never be added)."""
    n = len(xy)
    if not _arms_known(arm_angles, cfg) or n == 0:
        z = np.zeros(n)
        return np.zeros(n, np.int64), z, z, np.zeros(n, bool)
    arm, s, t = assign_arms(xy, c, np.asarray(arm_angles, float))
    return arm, s, t, (s > 0) & (np.abs(t) <= cfg.arm_reach)


def heading_observations(dets: Detections, center, cfg: PreprocessConfig,
                         arm_angles=None) -> ObservationSet:
    """Lidar/camera rows (heading, no id, no Doppler) -> voxels with their mean heading.

    With ``arm_angles``: arm-aligned voxels per direction class (entering iff the heading
    points against the arm) and the straight-run filter, like radar; otherwise square
    voxels per heading sector.
    """
    m = (dets.track_id < 0) & np.isfinite(dets.heading) & ~np.isfinite(dets.doppler)
    if not m.any():
        return ObservationSet.empty()
    c = np.asarray(center, float)
    xy, h, ts = dets.xy[m], dets.heading[m], dets.t[m]
    vec = np.stack([np.cos(h), np.sin(h)], axis=1)
    arm, s_arm, t_arm, on = _on_arms(xy, c, arm_angles, cfg)
    parts = []
    if on.any():
        ang = np.asarray(arm_angles, float)
        cls = (vec[:, 0] * np.cos(ang)[arm] + vec[:, 1] * np.sin(ang)[arm] < 0).astype(np.int64)
        vxy, _, cnt, sv = arm_voxel_set(xy[on], cls[on], arm[on], s_arm[on], t_arm[on], ts[on],
                                      cfg, vec[on], cfg.heading_voxel_merge)
        parts.append((vxy, cnt, sv))
    if (~on).any():
        if on.any():   # arms known: the rest along rays from the center
            rad = np.arctan2(xy[~on, 1] - c[1], xy[~on, 0] - c[0])
            cls = (vec[~on, 0] * np.cos(rad) + vec[~on, 1] * np.sin(rad) < 0).astype(np.int64)
            vxy, _, cnt, sv = ray_voxel_set(xy[~on], cls, c, ts[~on], cfg, vec[~on],
                                          cfg.heading_voxel_merge)
        else:
            sector = np.floor((np.mod(h, 2 * math.pi)) / (2 * math.pi) * cfg.heading_sectors)
            vxy, _, cnt, sv = voxelise(xy, sector.astype(np.int64) % cfg.heading_sectors,
                                       cfg.voxel_size, vec, t=ts, gap=cfg.passage_gap)
        parts.append((vxy, cnt, sv))
    vxy, cnt, sv = (np.concatenate(p) for p in zip(*parts))
    hx, hy, okh = unit_vectors(sv[:, 0], sv[:, 1])
    d = direction_class(vxy[:, 0], vxy[:, 1], hx, hy, c)
    obs = ObservationSet(vxy[:, 0].copy(), vxy[:, 1].copy(), hx, hy, okh, d,
                         cfg.weight_scale * cnt ** cfg.weight_power,
                         np.full(len(vxy), cfg.sigma_point),
                         np.full(len(vxy), math.radians(cfg.sigma_angle_deg)), cnt)
    return _drop_near_center(obs, c, cfg)


def _drop_near_center(obs: ObservationSet, c, cfg: PreprocessConfig, far: bool = True,
                      inner: float | None = None) -> ObservationSet:
    """Observations in the ring ``inner <= r <= max_center_dist`` around ``c`` (``inner``
    defaults to ``min_center_dist``; ``far`` False: no outer bound)."""
    inner = cfg.min_center_dist if inner is None else inner
    far = far and math.isfinite(cfg.max_center_dist)
    if (inner <= 0 and not far) or len(obs) == 0:
        return obs
    r = np.hypot(obs.x - c[0], obs.y - c[1])
    return obs.subset((r >= inner) & (r <= cfg.max_center_dist) if far else r >= inner)


def preprocess(dets: Detections, center, cfg: PreprocessConfig, arm_angles=None,
               radar: RadarRows | None = None) -> ObservationSet:
    """All observation kinds of ``dets`` for the current ``center`` (paper §II-A);
    ``radar``: :func:`radar_rows` of ``dets.finite()`` when already at hand."""
    dets = dets.finite()
    order, starts, ends = track_bounds(dets, dets.track_id >= 0)   # one sort for both kinds
    moving = moving_mask(dets, order, starts, cfg.min_track_speed)
    return ObservationSet.concat([tracked_observations(dets, center, cfg, arm_angles,
                                                       (order, starts[moving], ends[moving])),
                                  standing_observations(dets, center, order, starts, ends,
                                                        ~moving, cfg),
                                  radar_observations(dets, center, cfg, arm_angles, radar),
                                  heading_observations(dets, center, cfg, arm_angles)])


@njit(cache=True)
def _run_from(h, first, step, q0, n, tol, win):
    """Length of the straight run of rows ``q0..n-1`` (row ``q`` is ``h[first + step * q]``):
    up to the first row where the moving average (``win`` rows) of the heading deviation
    from the run's start direction (mean of its first rows) exceeds ``tol``; >= 3 rows."""
    m = n - q0
    k = max(3, m // 5)
    sx = 0.0
    sy = 0.0
    for q in range(q0, min(q0 + k, n)):
        sx += math.cos(h[first + step * q])
        sy += math.sin(h[first + step * q])
    ref = math.atan2(sy, sx)
    dev = np.empty(m)
    for q in range(m):
        dev[q] = abs(wrap(h[first + step * (q0 + q)] - ref))
    half = win // 2
    run = m
    for q in range(m):
        acc = 0.0
        for r in range(q - half, q - half + win):
            if 0 <= r < m:
                acc += dev[r]
        if acc / win > tol:
            run = q
            break
    return max(run, min(m, 3))


@njit(cache=True)
def straight_run(h, first, step, n, tol, win, longest):
    """(start, length) of the rows of a trajectory part kept for its mean (§II-A, the turn
    trimmed): the straight run from the far end (paper-like), or with ``longest`` (beyond
    the paper) the longest of the consecutive straight runs the part splits into -- on a
    curved approach within the radius the piece next to the box, not the bend; the first
    run wins ties, so a straight approach keeps exactly the far-end run."""
    run = _run_from(h, first, step, 0, n, tol, win)
    if not longest:
        return 0, run
    best_start, best = 0, run
    q0 = run
    while q0 < n:
        r = _run_from(h, first, step, q0, n, tol, win)
        if r > best:
            best_start, best = q0, r
        q0 += r
    return best_start, best


@njit(cache=True)
def _far_portion(x, y, lo, hi, cx, cy, r2, entering):
    """The rows ``[lo, hi)`` of a trajectory part that lie on its far side of the circle of
    squared radius ``r2`` around the center: the contiguous run from the far end (the
    start of an entering part, the end of a leaving one) up to the first row inside."""
    if r2 <= 0.0:
        return lo, hi
    if entering:
        for i in range(lo, hi):
            if (x[i] - cx) ** 2 + (y[i] - cy) ** 2 < r2:
                return lo, i
        return lo, hi
    for i in range(hi - 1, lo - 1, -1):
        if (x[i] - cx) ** 2 + (y[i] - cy) ** 2 < r2:
            return i + 1, hi
    return lo, hi


@njit(cache=True)
def split_tracks(x, y, h, starts, ends, cx, cy, min_pts, min_len, tol, win, longest,
                 outside=0.0, piece=0.0):
    """Paper §II-A for tracked objects: split each trajectory at its point closest to the
    center ``(cx, cy)`` and reduce each part to its mean point and mean direction.

    With ``outside > 0`` (beyond the paper) a part is first cut to its rows beyond that
    distance from the center, counted from its far end (:func:`_far_portion`): a vehicle
    seen only over the last tens of metres before the box (a short recording, a near
    neighbouring junction, a limited view) still gives its approach, instead of a mean
    point inside the box radius that is then dropped as a vehicle in the box.

    Rows are sorted by (track, time); ``h`` is the heading per row. With ``tol > 0`` a part
    is first cut to its straight run from the far end (moving average of ``win`` heading
    deviations from the far-end direction below ``tol``): the turn inside the intersection
    box would bias the mean point and direction; with ``longest`` the longest straight run
    of the part is kept instead of the first (:func:`straight_run`). With ``piece > 0``
    (beyond the paper) the kept rows give one mean per ``piece`` metres driven instead of
    one per part (:func:`_pieces`), each weighted by its share of the part. Returns (mx,
    my, vx, vy, trajectory index, weight) per kept part or piece.

    Length (over 80 lines): one pass per trajectory (closest point, split, straight-run
    trim, means); helpers would need the same dozen loop-carried variables.
    """
    nt = starts.shape[0]
    out = np.empty((2 * nt + (x.shape[0] if piece > 0.0 else 0), 6))
    m = 0
    for t in range(nt):
        a = starts[t]
        b = ends[t]
        best = np.inf
        imin = a
        for i in range(a, b):
            d = (x[i] - cx) ** 2 + (y[i] - cy) ** 2
            if d < best:
                best = d
                imin = i
        for part in range(2):
            lo = a if part == 0 else imin
            hi = imin + 1 if part == 0 else b
            lo, hi = _far_portion(x, y, lo, hi, cx, cy, outside * outside, part == 0)
            n = hi - lo
            if n < min_pts:
                continue
            x0 = x[lo]
            x1 = x[lo]
            y0 = y[lo]
            y1 = y[lo]
            for i in range(lo, hi):
                x0 = min(x0, x[i])
                x1 = max(x1, x[i])
                y0 = min(y0, y[i])
                y1 = max(y1, y[i])
            if math.hypot(x1 - x0, y1 - y0) < min_len:
                continue
            # far end first: entering part (0) starts far, leaving part (1) ends far
            step = 1 if part == 0 else -1
            first = lo if part == 0 else hi - 1
            start, keep = 0, n
            if tol > 0.0:
                start, keep = straight_run(h, first, step, n, tol, win, longest)
            if piece > 0.0:
                m = _pieces(x, y, h, first + step * start, step, keep, piece, t, out, m)
                continue
            mx = 0.0
            my = 0.0
            vx = 0.0
            vy = 0.0
            for q in range(start, start + keep):
                i = first + step * q
                mx += x[i]
                my += y[i]
                vx += math.cos(h[i])
                vy += math.sin(h[i])
            out[m, 0] = mx / keep
            out[m, 1] = my / keep
            out[m, 2] = vx
            out[m, 3] = vy
            out[m, 4] = t
            out[m, 5] = 1.0
            m += 1
    return out[:m]


@njit(cache=True)
def _pieces(x, y, h, first, step, keep, piece, t, out, m):
    """The ``keep`` rows from ``first`` (by ``step``) of a trajectory part cut into runs of
    ``piece`` metres driven (a last run shorter than half a piece joins the one before):
    per run its mean point, summed direction, trajectory ``t`` and weight = its metres /
    the part's, written from ``out[m]``. Returns the next free row. A curved approach keeps
    its shape (:mod:`.arm_bend` can then follow it) instead of one mean point beside it."""
    total = 0.0
    for q in range(1, keep):
        i, j = first + step * q, first + step * (q - 1)
        total += math.hypot(x[i] - x[j], y[i] - y[j])
    n_runs = max(1, int(total / piece + 0.5))
    m0 = m
    run = 0
    mx = my = vx = vy = 0.0
    cnt = 0
    done = 0.0
    for q in range(keep):
        i = first + step * q
        if q > 0:
            j = first + step * (q - 1)
            done += math.hypot(x[i] - x[j], y[i] - y[j])
        r = min(int(done / total * n_runs), n_runs - 1) if total > 0.0 else 0
        if r != run and cnt > 0:
            out[m, 0], out[m, 1], out[m, 2], out[m, 3], out[m, 4] = mx / cnt, my / cnt, vx, vy, t
            m += 1
            mx = my = vx = vy = 0.0
            cnt = 0
            run = r
        mx += x[i]
        my += y[i]
        vx += math.cos(h[i])
        vy += math.sin(h[i])
        cnt += 1
    if cnt > 0:
        out[m, 0], out[m, 1], out[m, 2], out[m, 3], out[m, 4] = mx / cnt, my / cnt, vx, vy, t
        m += 1
    for k in range(m0, m):
        out[k, 5] = 1.0 / (m - m0)
    return m
