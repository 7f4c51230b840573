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

Also the data-driven initialisation: center where the observed driving lines meet
(robust least squares) and arm angles from a histogram of outward driving directions.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import NamedTuple

import numpy as np

from ._kernels import (arm_voxels, grid_voxel_index, irls_center, lane_guess, local_pca,
                       nearest_rays, radar_frame, radar_voxels, split_tracks)
from .likelihood import ObservationSet
from .model import wrap_angle
from .observations import Detections

__all__ = ['PreprocessConfig', 'tracked_observations', 'radar_observations', 'RadarRows',
           'radar_rows', 'heading_observations', 'preprocess', 'voxelise', 'seed_lines',
           'initial_center', 'initial_arm_angles']


@dataclass(frozen=True)
class PreprocessConfig:
    sigma_track: float = 0.5            # [m] sigma_perp of a trajectory part's mean point
    sigma_point: float = 1.2            # [m] sigma_perp of a single detection / voxel
    sigma_angle_deg: float = 5.0        # heading of a trajectory part / detection
    pca_radius: float = 8.0             # [m] initial center: local PCA of radar voxels
    voxel_size: float = 2.0             # [m] raw / heading voxel edge
    voxel_length: float = 10.0          # [m] radar voxels along an arm (0: square voxels)
    voxel_width: float = 1.0            # [m] ... and across it
    straight_run: bool = True           # drop radar voxels off straight lane runs
    voxel_merge: int = 3                # then merge this many along-arm voxels (radar)
    heading_voxel_merge: int = 2        # ... (lidar / camera rows: one per vehicle and cycle,
                                        # a third of the radar's detections)
    heading_sectors: int = 8            # heading voxelisation: sectors of 360/n deg
    passage_gap: float = 1.0            # [s] stamps further apart: another vehicle passage
                                        # (0: weights in raw detection counts)
    weight_power: float = 1.0           # voxel weight = passages ** power * weight_scale
    weight_scale: float = 1.0
    min_doppler: float = 0.5            # [m/s] |doppler| below: static -> dropped
    min_rcs: float = 0.0                # [dBsm] below: clutter -> dropped (NaN rcs kept)
    min_rcs_static: float = 5.0         # [dBsm] |doppler| small but RCS this high: a vehicle
    keep_unknown_direction: bool = True  # radar rows of unknown direction kept (d = 0)
    min_radial_cos: float = 0.25        # |<r, los>| below: direction ambiguous -> dropped
    min_part_points: int = 3            # trajectory parts with fewer points are dropped
    min_part_length: float = 5.0        # [m] ... or shorter extent (static false tracks)
    min_track_speed: float = 3.0        # [m/s] tracks never faster than this are static
    trim_turn_deg: float = 15.0         # keep a part's straight run (0: whole part, paper)
    min_center_dist: float = 0.0        # [m] observations closer to the center dropped
    arm_reach: float = 18.0             # [m] rows farther from every arm's axis: on no arm


def _unit(vx, vy):
    n = np.hypot(vx, vy)
    ok = n > 1e-9
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(ok, vx / n, 0.0), np.where(ok, vy / n, 0.0), ok


def _direction_class(x, y, hx, hy, center):
    """+1 entering (moving toward the center), -1 leaving."""
    return np.where(hx * (center[0] - x) + hy * (center[1] - y) > 0, 1.0, -1.0)


def voxelise(xy: np.ndarray, cls: np.ndarray, size: float, vec: np.ndarray | None = None,
             t: np.ndarray | None = None, gap: float = 1.0):
    """Merge points per (voxel, class): mean position, count (and summed vectors); voxels
    in the order of (x bin, y bin, class), classes in [0, 64) (grouping compiled:
    :func:`_kernels.grid_voxel_index`).

    With stamps ``t`` the counts are divided by the mean number of detections per vehicle
    passage (see :func:`passages`), i.e. expressed in vehicles."""
    if len(xy) == 0:
        return np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 2))
    if cls.min() < 0 or cls.max() >= 64:
        raise ValueError('voxelise: classes must lie in [0, 64)')
    inv, m = grid_voxel_index(np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
                              np.asarray(cls, np.int64), float(size))
    cnt = np.bincount(inv, minlength=m)
    mx = np.bincount(inv, xy[:, 0], m) / cnt
    my = np.bincount(inv, xy[:, 1], m) / cnt
    first = np.zeros(m, np.int64)
    first[inv[::-1]] = np.arange(len(inv))[::-1]
    sv = np.zeros((m, 2))
    if vec is not None:
        sv = np.stack([np.bincount(inv, vec[:, 0], m), np.bincount(inv, vec[:, 1], m)], axis=1)
    if t is not None and gap > 0:   # counts in vehicle passages (global detections/passage)
        per_pass = len(xy) / max(passages(inv, t, m, gap).sum(), 1.0)
        return np.stack([mx, my], axis=1), cls[first], cnt / per_pass, sv
    return np.stack([mx, my], axis=1), cls[first], cnt.astype(np.float64), sv


def passages(inv: np.ndarray, t: np.ndarray, n: int, gap: float) -> np.ndarray:
    """Per voxel: number of vehicle passages = clusters of its detection stamps separated
    by more than ``gap`` seconds. Detections of one passing vehicle are not independent;
    weights in units of passages give each vehicle (about) one vote per voxel whatever the
    sensor rate or the number of points per vehicle."""
    if len(inv) == 0:
        return np.zeros(n)
    o = np.lexsort((t, inv))
    vi, ts = inv[o], t[o]
    new = np.r_[True, (vi[1:] != vi[:-1]) | (np.diff(ts) > gap)]
    return np.bincount(vi[new], minlength=n).astype(np.float64)


def tracked_observations(dets: Detections, center, cfg: PreprocessConfig) -> ObservationSet:
    """Split trajectories at the point closest to ``center``; mean point + direction."""
    sel = dets.track_id >= 0
    if not sel.any():
        return ObservationSet.empty()
    tid, t, xy, hd = dets.track_id[sel], dets.t[sel], dets.xy[sel], dets.heading[sel]
    sp = dets.speed[sel]
    order = np.lexsort((t, tid))
    tid, xy, hd, sp = tid[order], xy[order], hd[order], sp[order]
    starts = np.flatnonzero(np.r_[True, tid[1:] != tid[:-1]])
    ends = np.r_[starts[1:], len(tid)]
    if cfg.min_track_speed > 0 and np.isfinite(sp).any():   # static (false) tracks
        vmax = np.maximum.reduceat(np.where(np.isfinite(sp), sp, np.inf), starts)
        moving = vmax >= cfg.min_track_speed
        starts, ends = starts[moving], ends[moving]
        if len(starts) == 0:
            return ObservationSet.empty()
    c = np.asarray(center, float)
    if not np.isfinite(hd).all():      # rows without heading: direction from positions
        for a, b in zip(starts, ends):
            h = hd[a:b]
            if not np.isfinite(h).all():
                hd[a:b] = _path_heading(xy[a:b])
    o = split_tracks(xy[:, 0].copy(), xy[:, 1].copy(), hd, starts, ends, float(c[0]), float(c[1]),
                     cfg.min_part_points, cfg.min_part_length, math.radians(cfg.trim_turn_deg), 5)
    if len(o) == 0:
        return ObservationSet.empty()
    hx, hy, ok = _unit(o[:, 2], o[:, 3])
    d = _direction_class(o[:, 0], o[:, 1], hx, hy, c)
    obs = ObservationSet(o[:, 0].copy(), o[:, 1].copy(), hx, hy, ok, d, np.ones(len(o)),
                         np.full(len(o), cfg.sigma_track),
                         np.full(len(o), math.radians(cfg.sigma_angle_deg)), np.ones(len(o)))
    return _drop_near_center(obs, c, cfg)


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
    voxels and the near-center drop run in one compiled pass (:func:`_kernels.radar_voxels`).
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
        return _radar_set(vx, vy, dcls, cnt, cfg)
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
    frame from :func:`_kernels.radar_frame`). Rows on no current arm are voxelised along
    rays from the center (:func:`_ray_voxels`), so that an arm the chain has not found yet
    keeps its data (aligned with a neighbouring arm they would look like crossing
    traffic and be filtered out, and the arm could never be added)."""
    n = len(xy)
    if not _arms_known(arm_angles, cfg) or n == 0:
        z = np.zeros(n)
        return np.zeros(n, np.int64), z, z, np.zeros(n, bool)
    arm, s, t = _assign_arms(xy, c, np.asarray(arm_angles, float))
    return arm, s, t, (s > 0) & (np.abs(t) <= cfg.arm_reach)


#: Rays every 10 deg: the frame of rows on no current arm (see :func:`radar_observations`).
RAYS = np.radians(np.arange(-180.0, 180.0, 10.0))


def _ray_voxels(xy, cls, c, stamp, cfg: PreprocessConfig, vec=None, merge=None):
    """Rows on no current arm: voxels aligned with the nearest of :data:`RAYS` from the
    center, with the straight-run filter -- an unfound arm's traffic runs radially and
    survives, isolated clutter and turning traffic do not."""
    arm, s, t = _assign_arms(xy, c, RAYS)
    ok = s > 0
    return _arm_voxels(xy[ok], cls[ok], arm[ok], s[ok], t[ok], stamp[ok], cfg,
                       None if vec is None else vec[ok], merge)


def _assign_arms(xy, c, angles):
    """Nearest arm (smallest lateral offset among arms the point lies ahead of), s, t;
    s = 0 where it lies ahead of none (compiled: :func:`_kernels.nearest_rays`, the rule
    :func:`_kernels.radar_frame` applies to radar rows)."""
    return nearest_rays(np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
                        float(c[0]), float(c[1]), np.asarray(angles, float))


def _arm_voxels(xy, cls, arm, s, t, stamp, cfg: PreprocessConfig, vec=None, merge=None):
    """Arm-aligned voxels with the straight-run filter (see :func:`radar_observations`;
    compiled: :func:`_kernels.arm_voxels`).

    Returns mean position, class, weight in vehicle passages (and summed ``vec``)."""
    v = np.zeros((len(xy), 2)) if vec is None else np.asarray(vec, float)
    mx, my, c, w, svx, svy = arm_voxels(
        np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
        np.asarray(cls, np.int64), np.asarray(arm, np.int64), np.asarray(s, float),
        np.asarray(t, float), np.asarray(stamp, float), np.ascontiguousarray(v[:, 0]),
        np.ascontiguousarray(v[:, 1]), float(cfg.voxel_length), float(cfg.voxel_width),
        bool(cfg.straight_run), int(cfg.voxel_merge if merge is None else merge),
        float(cfg.passage_gap))
    mean = np.stack([mx, my], axis=1)
    if vec is not None:
        return mean, c, w, np.stack([svx, svy], axis=1)
    return mean, c, w


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
        vxy, _, cnt, sv = _arm_voxels(xy[on], cls[on], arm[on], s_arm[on], t_arm[on], ts[on],
                                      cfg, vec[on], cfg.heading_voxel_merge)
        parts.append((vxy, cnt, sv))
    if (~on).any():
        if on.any():   # arms known: the rest along rays from the center
            rad = np.arctan2(xy[~on, 1] - c[1], xy[~on, 0] - c[0])
            cls = (vec[~on, 0] * np.cos(rad) + vec[~on, 1] * np.sin(rad) < 0).astype(np.int64)
            vxy, _, cnt, sv = _ray_voxels(xy[~on], cls, c, ts[~on], cfg, vec[~on],
                                          cfg.heading_voxel_merge)
        else:
            sector = np.floor((np.mod(h, 2 * math.pi)) / (2 * math.pi) * cfg.heading_sectors)
            vxy, _, cnt, sv = voxelise(xy, sector.astype(np.int64) % cfg.heading_sectors,
                                       cfg.voxel_size, vec, t=ts, gap=cfg.passage_gap)
        parts.append((vxy, cnt, sv))
    vxy, cnt, sv = (np.concatenate(p) for p in zip(*parts))
    hx, hy, okh = _unit(sv[:, 0], sv[:, 1])
    d = _direction_class(vxy[:, 0], vxy[:, 1], hx, hy, c)
    obs = ObservationSet(vxy[:, 0].copy(), vxy[:, 1].copy(), hx, hy, okh, d,
                         cfg.weight_scale * cnt ** cfg.weight_power,
                         np.full(len(vxy), cfg.sigma_point),
                         np.full(len(vxy), math.radians(cfg.sigma_angle_deg)), cnt)
    return _drop_near_center(obs, c, cfg)


def _drop_near_center(obs: ObservationSet, c, cfg: PreprocessConfig) -> ObservationSet:
    if cfg.min_center_dist <= 0 or len(obs) == 0:
        return obs
    return obs.subset(np.hypot(obs.x - c[0], obs.y - c[1]) >= cfg.min_center_dist)


def preprocess(dets: Detections, center, cfg: PreprocessConfig, arm_angles=None,
               radar: RadarRows | None = None) -> ObservationSet:
    """All observation kinds of ``dets`` for the current ``center`` (paper §II-A);
    ``radar``: :func:`radar_rows` of ``dets.finite()`` when already at hand."""
    dets = dets.finite()
    return ObservationSet.concat([tracked_observations(dets, center, cfg),
                                  radar_observations(dets, center, cfg, arm_angles, radar),
                                  heading_observations(dets, center, cfg, arm_angles)])


# ----------------------------------------------------------------------------- initialisation

def seed_lines(dets: Detections, cfg: PreprocessConfig):
    """Driving lines (point, unit direction, weight) for the initial center, center-free.

    Rows with a heading (tracked or not) are voxelised per heading sector; radar rows
    surviving the clutter filter are voxelised and get their direction from a local PCA
    of neighbouring voxels (weighted by its anisotropy).
    """
    dets = dets.finite()
    m = np.isfinite(dets.heading) & ~np.isfinite(dets.doppler)
    pts, dirs, wts = [], [], []
    if m.any():
        h = dets.heading[m]
        sector = np.floor(np.mod(h, 2 * math.pi) / (2 * math.pi) * cfg.heading_sectors)
        vec = np.stack([np.cos(h), np.sin(h)], axis=1)
        vxy, _, cnt, sv = voxelise(dets.xy[m], sector.astype(np.int64), 2.0 * cfg.voxel_size, vec)
        hx, hy, ok = _unit(sv[:, 0], sv[:, 1])
        pts.append(vxy[ok])
        dirs.append(np.stack([hx, hy], axis=1)[ok])
        wts.append(np.sqrt(cnt[ok]))
    r = radar_filter(dets, cfg)
    if r.any():
        vxy, _, cnt, _ = voxelise(dets.xy[r], np.zeros(int(r.sum()), np.int64), 2.0 * cfg.voxel_size)
        if len(vxy) > 1500:
            keep = np.argsort(-cnt, kind='stable')[:1500]
            vxy, cnt = vxy[keep], cnt[keep]
        theta, aniso = local_pca(vxy[:, 0].copy(), vxy[:, 1].copy(), cnt, cfg.pca_radius)
        pts.append(vxy)
        dirs.append(np.stack([np.cos(theta), np.sin(theta)], axis=1))
        wts.append(np.sqrt(cnt) * aniso ** 2)
    if not pts:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    return np.concatenate(pts), np.concatenate(dirs), np.concatenate(wts)


def initial_center(p: np.ndarray, o: np.ndarray, w: np.ndarray, scale: float = 6.0,
                   iters: int = 30) -> np.ndarray | None:
    """Robust point where the driving lines (p_i, o_i) meet (IRLS, Cauchy loss).

    Starts at the weighted median of the points; a small ridge toward it keeps the
    solution defined when all lines are parallel (a single road).
    """
    if len(p) == 0:
        return None
    c0 = (_wmedian(p[:, 0], w), _wmedian(p[:, 1], w))
    c = irls_center(np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]),
                    np.ascontiguousarray(-o[:, 1]), np.ascontiguousarray(o[:, 0]),
                    np.ascontiguousarray(w, dtype=np.float64), c0[0], c0[1], float(scale),
                    int(iters))
    return np.array(c)


def _wmedian(x, w):
    i = np.argsort(x)
    cw = np.cumsum(w[i])
    return float(x[i][np.searchsorted(cw, 0.5 * cw[-1])])


def initial_arm_angles(p: np.ndarray, o: np.ndarray, w: np.ndarray, center, min_sep: float,
                       max_arms: int, min_dist: float = 10.0, peak_frac: float = 0.12,
                       bin_deg: float = 2.0, smooth_deg: float = 4.0) -> list[float]:
    """Arm angles from a histogram of outward driving directions around ``center``.

    Only lines far enough from the center and roughly radial are used; the direction is
    flipped to point away from the center, so every lane of an arm votes for the arm's
    angle regardless of its lateral offset.
    """
    if len(p) == 0:
        return []
    v = p - np.asarray(center, float)
    dist = np.hypot(v[:, 0], v[:, 1])
    with np.errstate(invalid='ignore', divide='ignore'):
        radial = np.sum(o * v, axis=1) / np.maximum(dist, 1e-9)
    use = (dist > min_dist) & (np.abs(radial) > math.cos(math.radians(35.0)))
    if not use.any():
        return []
    out = o[use] * np.sign(radial[use])[:, None]
    ang = np.arctan2(out[:, 1], out[:, 0])
    nb = int(round(360.0 / bin_deg))
    idx = np.floor(np.mod(ang, 2 * math.pi) / (2 * math.pi) * nb).astype(int) % nb
    hist = np.bincount(idx, w[use], nb)
    k = np.arange(-3 * int(smooth_deg / bin_deg) - 1, 3 * int(smooth_deg / bin_deg) + 2)
    ker = np.exp(-0.5 * (k * bin_deg / smooth_deg) ** 2)
    sm = np.zeros(nb)
    for kk, kv in zip(k, ker):
        sm += kv * np.roll(hist, kk)
    peaks = [i for i in range(nb) if sm[i] >= sm[i - 1] and sm[i] > sm[(i + 1) % nb]]
    peaks.sort(key=lambda i: -sm[i])
    chosen: list[float] = []
    top = sm.max()
    for i in peaks:
        if sm[i] < peak_frac * top or len(chosen) >= max_arms:
            break
        a = float(wrap_angle((i + 0.5) * 2 * math.pi / nb))
        if all(abs(float(wrap_angle(a - b))) >= min_sep for b in chosen):
            chosen.append(a)
    return chosen


def initial_lanes(obs: ObservationSet, center, angles, lane_width: float, max_lanes: int,
                  gap_max: float, traffic_side: int = 1, iters: int = 3, width_range=None):
    """Refine the center from the arms' median axes and guess gap / lane counts per arm.

    Observations are assigned to the arm whose axis they run along (outside 8 m, roughly
    parallel when oriented); per arm the median axis lies halfway between the innermost
    entering and the innermost leaving observations; the center is the least-squares
    meeting point of these axes; lane counts (and, with ``width_range``, the lane width)
    follow from the lateral spread. Returns
    (center, [(gap, lanes_in, lanes_out, width), ...]).
    """
    c = np.asarray(center, float).copy()
    params = [(0.0, 1, 1, lane_width)] * len(angles)
    if len(obs) == 0 or len(angles) == 0:
        return c, params
    cx, cy, P = lane_guess(obs.x, obs.y, obs.hx, obs.hy, obs.has_o, obs.d,
                           np.asarray(obs.w, float), float(c[0]), float(c[1]),
                           np.asarray(angles, float), float(lane_width), int(max_lanes),
                           float(gap_max), float(traffic_side), int(iters),
                           *((float(width_range[0]), float(width_range[1]), True)
                             if width_range is not None else (lane_width, lane_width, False)))
    return np.array([cx, cy]), [(float(g), int(ni), int(no), float(wd)) for g, ni, no, wd in P]
