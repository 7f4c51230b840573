"""Do the data show an intersection at all? (beyond the paper; issue 15 part 4)

The topology sampler (paper §II) always explains the data by a center with arms: on a
straight road it still places a center somewhere along it and reports an intersection.
This module decides, from the detections alone and independently of the sampler,
whether any traffic leaves the one axis that a road would have:

1. The *axis*: the dominant driving direction modulo 180 deg (mode of the doubled
   headings of moving detections; without headings -- radar -- the principal axis of
   the moving detections' positions, with the road's lateral position followed along
   it bin by bin).
2. *Off-axis evidence* ``off_axis``: moving detections whose heading deviates more
   than ``axis_tol_deg`` from the axis (radar: that lie more than ``corridor_m`` beside
   it). With track ids: the tracks whose off-axis rows span at least ``min_extent_m``
   (vehicle passages; a short false track or a lane change is no arm). Without ids:
   the off-axis travel in stretches of ``min_extent_m`` (:func:`_cell_evidence`).
   ``on_axis`` likewise for the rows along the axis.
3. ``intersection_confidence = 1 - 2 ** (-off_axis / need)`` (0.5 at the threshold
   ``need`` = ``min_off_passages`` for tracks, ``min_off_stretches`` without);
   state ``'INTERSECTION'`` when ``off_axis >= need``,
   ``'ROAD'`` when traffic moved (almost) only along the axis, ``'NO_DATA'`` without
   moving detections.

:func:`assess` is called by the pipeline after the topology step; the estimate keeps
its arms and lanes (they describe the road) and says ``intersection: false``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
import math

import numpy as np
from numba import njit

from .observations import Detections
from .ranges import check_table

__all__ = ['ObservabilityConfig', 'Observability', 'assess', 'ROAD', 'INTERSECTION', 'NO_DATA']

ROAD, INTERSECTION, NO_DATA = 'ROAD', 'INTERSECTION', 'NO_DATA'

_RANGES = {
    'axis_tol_deg': ('[1.0, 89.0]', 'heading farther than this from the axis is off-axis [deg]'),
    'corridor_m': ('[1.0, 200.0]',
                   'radar: detections farther than this beside the axis are off-axis [m]'),
    'ridge_bin_m': ('[1.0, 200.0]', 'radar: bin length of the road ridge along the axis [m]'),
    'min_extent_m': ('[0.0, 500.0]', 'shortest off-axis stretch of one passage that counts [m]'),
    'min_speed': ('[0.0, 50.0]', 'slower detections (speed or |Doppler|) are not traffic [m/s]'),
    'min_off_passages': ('[0.1, 1000.0]', 'tracks: off-axis passages needed for an intersection'),
    'min_off_stretches': ('[0.1, 1000.0]', 'untracked: off-axis min_extent_m stretches needed'),
    'cell_m': ('[0.5, 50.0]', 'untracked: side of the squares that off-axis travel is counted in [m]'),
    'cell_min': ('[1, 1000]', 'untracked: rows of as many stamps that make a square count'),
    'heading_window': ('[1, 100]', 'tracks without heading: samples either side for the chord'),
}


@dataclass(frozen=True)
class ObservabilityConfig:
    """Thresholds of :func:`assess` (``validate()`` names a bad one)."""

    axis_tol_deg: float = 30.0
    corridor_m: float = 20.0
    ridge_bin_m: float = 10.0
    min_extent_m: float = 8.0
    min_speed: float = 1.0
    min_off_passages: float = 2.0
    min_off_stretches: float = 6.0
    cell_m: float = 4.0
    cell_min: int = 3
    heading_window: int = 5

    def validate(self) -> 'ObservabilityConfig':
        check_table(self, _RANGES)
        return self


@dataclass(frozen=True)
class Observability:
    """Verdict of :func:`assess`; ``to_json()`` is the ``observability`` key of estimate.json."""

    state: str
    intersection_confidence: float
    off_axis: float                # passages (tracks) or min_extent_m stretches (untracked)
    on_axis: float
    axis_deg: float | None
    basis: str                     # 'tracks' | 'headings' | 'positions' | 'none'

    @property
    def intersection(self) -> bool:
        return self.state == INTERSECTION

    def to_json(self) -> dict:
        d = asdict(self)
        d['intersection'] = self.intersection
        return d


def _axis_from_headings(h: np.ndarray) -> float:
    """Mode of the doubled headings (72 bins, circular smoothing), refined by the doubled
    mean of the headings near it; returns the axis angle in [0, pi)."""
    d = np.mod(2.0 * h, 2.0 * math.pi)
    hist = np.bincount((d / (2 * math.pi) * 72).astype(int) % 72, minlength=72).astype(float)
    sm = sum(np.roll(hist, k) for k in range(-3, 4))
    peak = (np.argmax(sm) + 0.5) * 2 * math.pi / 72
    near = np.abs(np.angle(np.exp(1j * (d - peak)))) < math.radians(30.0)
    z = np.exp(1j * d[near]).sum()
    return float(np.mod(0.5 * np.angle(z), math.pi))


def _deviation(h: np.ndarray, axis: float) -> np.ndarray:
    """|heading - axis| modulo 180 deg, in [0, pi/2]."""
    return np.abs(np.angle(np.exp(2j * (h - axis)))) / 2.0


def _chord_headings(xy: np.ndarray, tid: np.ndarray, k: int) -> np.ndarray:
    """Heading of each row from the chord between the rows ``k`` before and after it in
    the same track (rows sorted by track, then time)."""
    n = len(xy)
    i = np.arange(n)
    starts = np.r_[0, np.flatnonzero(np.diff(tid)) + 1]
    first = np.repeat(starts, np.diff(np.r_[starts, n]))
    last = np.repeat(np.r_[starts[1:], n] - 1, np.diff(np.r_[starts, n]))
    a, b = np.maximum(i - k, first), np.minimum(i + k, last)
    d = xy[b] - xy[a]
    return np.arctan2(d[:, 1], d[:, 0])


#: largest dense square grid counted in one pass (:func:`_occupied_squares`); beyond it a sort
_DENSE_CELLS = 1 << 22


@njit(cache=True)
def _occupied_squares(x, y, t, sel, want, cell_m, cell_min, max_cells):
    """Squares of side ``cell_m`` that rows ``sel == want`` visit with at least ``cell_min``
    distinct stamps, counted in one pass (a row adds a stamp when its square last saw
    another); -1 when those rows are not in time order or span more than ``max_cells``
    squares (the caller sorts then). Squares as ``floor(xy / cell_m)``."""
    n = x.shape[0]
    ix = np.empty(n, np.int64)
    iy = np.empty(n, np.int64)
    rows = np.empty(n, np.int64)
    m = 0
    for i in range(n):
        if sel[i] != want:
            continue
        if m > 0 and t[i] < t[rows[m - 1]]:
            return -1
        ix[m] = np.int64(math.floor(x[i] / cell_m))
        iy[m] = np.int64(math.floor(y[i] / cell_m))
        rows[m] = i
        m += 1
    if m == 0:
        return 0
    x0, y0 = ix[:m].min(), iy[:m].min()
    ny = iy[:m].max() - y0 + 1
    n_cells = (ix[:m].max() - x0 + 1) * ny
    if n_cells > max_cells:
        return -1
    last = np.full(n_cells, np.nan)
    count = np.zeros(n_cells, np.int64)
    for q in range(m):
        c = (ix[q] - x0) * ny + iy[q] - y0
        if last[c] != t[rows[q]]:       # in time order: equal stamps are consecutive
            last[c] = t[rows[q]]
            count[c] += 1
    occupied = 0
    for c in range(n_cells):
        if count[c] >= cell_min:
            occupied += 1
    return occupied


def _cell_evidence(xy: np.ndarray, t: np.ndarray, cfg: ObservabilityConfig, sel=None,
                   want: bool = True) -> float:
    """Untracked rows (those with ``sel == want``; all without ``sel``): off-axis travel in
    stretches of ``min_extent_m``. The ground is cut into ``cell_m`` squares; a square
    counts when ``cell_min`` rows of as many different stamps fall into it (a vehicle
    crossing it at urban speed leaves one row per cycle; clutter with random positions
    rarely does) -> occupied squares x cell_m / min_extent_m. Rows in time order are
    counted in one compiled pass (:func:`_occupied_squares`), others by a sort."""
    sel = np.ones(len(xy), np.bool_) if sel is None else np.asarray(sel, np.bool_)
    k = _occupied_squares(np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
                          np.ascontiguousarray(t, np.float64), sel, bool(want), float(cfg.cell_m),
                          int(cfg.cell_min), _DENSE_CELLS)
    if k < 0:
        rows = sel == want
        k = _occupied_by_sort(xy[rows], t[rows], cfg)
    return float(k) * cfg.cell_m / max(cfg.min_extent_m, 1e-9)


def _occupied_by_sort(xy: np.ndarray, t: np.ndarray, cfg: ObservabilityConfig) -> int:
    """:func:`_occupied_squares` for any row order and extent: the sorted (square, stamp)
    pairs, run lengths = stamps per square."""
    c = np.floor(xy / cfg.cell_m).astype(np.int64)
    c -= c.min(axis=0)
    code = c[:, 0] * (int(c[:, 1].max()) + 1) + c[:, 1]
    ti = np.unique(t, return_inverse=True)[1].ravel()
    k = int(ti.max()) + 1
    cell = np.unique(code * k + ti) // k       # (square, stamp) once each, sorted
    starts = np.flatnonzero(np.r_[True, cell[1:] != cell[:-1]])
    return int((np.diff(np.r_[starts, len(cell)]) >= cfg.cell_min).sum())


def _passages(xy, ids, off, cfg) -> tuple[float, float]:
    """(off-axis, on-axis) passages: tracks whose off-axis / on-axis rows span
    ``min_extent_m`` (bounding-box diagonal, :func:`_track_extents`)."""
    if len(ids) == 0:
        return 0.0, 0.0
    if (ids[1:] >= ids[:-1]).all():           # rows sorted by track, as _by_heading makes them
        lab = np.r_[0, np.cumsum(ids[1:] != ids[:-1])]
    else:
        lab = np.unique(ids, return_inverse=True)[1].ravel()
    n_off, n_on = _track_extents(np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
                                 lab, off, int(lab.max()) + 1, float(cfg.min_extent_m))
    return float(n_off), float(n_on)


@njit(cache=True)
def _track_extents(x, y, lab, off, n, min_extent):
    """Tracks (labels ``0..n-1``) whose off-axis rows (``off``), and whose on-axis rows,
    have a bounding-box diagonal of at least ``min_extent`` (0 for a track without such
    rows); returns (off count, on count). Diagonal as ``numpy.linalg.norm``:
    ``sqrt(dx * dx + dy * dy)``."""
    lo = np.full((2, n, 2), np.inf)
    hi = np.full((2, n, 2), -np.inf)
    for i in range(x.shape[0]):
        g = 0 if off[i] else 1
        j = lab[i]
        lo[g, j, 0] = min(lo[g, j, 0], x[i])
        lo[g, j, 1] = min(lo[g, j, 1], y[i])
        hi[g, j, 0] = max(hi[g, j, 0], x[i])
        hi[g, j, 1] = max(hi[g, j, 1], y[i])
    out = np.zeros(2, np.int64)
    for g in range(2):
        for j in range(n):
            e = 0.0
            if math.isfinite(lo[g, j, 0]):
                dx = hi[g, j, 0] - lo[g, j, 0]
                dy = hi[g, j, 1] - lo[g, j, 1]
                e = math.sqrt(dx * dx + dy * dy)
            if e >= min_extent:
                out[g] += 1
    return out[0], out[1]


def _moving(dets: Detections, cfg: ObservabilityConfig) -> np.ndarray:
    """Rows that are traffic: speed (or |Doppler| for radar rows) >= ``min_speed`` where
    known, every row where neither is (finite position and stamp)."""
    return _moving_mask(dets.xy, dets.t, dets.speed, dets.doppler, float(cfg.min_speed))


@njit(cache=True)
def _moving_mask(xy, t, speed, doppler, min_speed):
    """:func:`_moving` in one pass: finite row, and speed (else |Doppler|) unknown or at
    least ``min_speed``."""
    n = t.shape[0]
    out = np.empty(n, np.bool_)
    for i in range(n):
        sp = speed[i] if math.isfinite(speed[i]) else abs(doppler[i])
        out[i] = (math.isfinite(xy[i, 0]) and math.isfinite(xy[i, 1]) and math.isfinite(t[i])
                  and not (math.isfinite(sp) and sp < min_speed))
    return out


def _by_heading(xy, t, heading, tid, cfg: ObservabilityConfig):
    """Axis and evidence from headings (tracked: passages per track id, else cells); the
    moving rows' columns."""
    tracked = tid >= 0
    if tracked.any():
        i = np.flatnonzero(tracked)
        o = i[np.lexsort((t[i], tid[i]))]           # by track, then time
        xy, tid, h = xy[o], tid[o], heading[o]
        miss = ~np.isfinite(h)
        if miss.any():
            h[miss] = _chord_headings(xy, tid, cfg.heading_window)[miss]
        axis = _axis_from_headings(h)
        off = _deviation(h, axis) > math.radians(cfg.axis_tol_deg)
        return axis, _passages(xy, tid, off, cfg), 'tracks'
    ok = np.isfinite(heading)
    xy, t, h = xy[ok], t[ok], heading[ok]
    axis = _axis_from_headings(h)
    off = _deviation(h, axis) > math.radians(cfg.axis_tol_deg)
    return axis, (_cell_evidence(xy, t, cfg, off, True),
                  _cell_evidence(xy, t, cfg, off, False)), 'headings'


def _bin_medians(bin_m: float, s: np.ndarray, lat: np.ndarray, min_count: int):
    """Per ``bin_m`` bin of ``s`` (bins from the smallest ``s``, in increasing order) with at
    least ``min_count`` rows: the medians of ``s`` and of ``lat`` (``numpy.median``
    semantics; :func:`_bin_median_pass`)."""
    mids, ridge, ok = _bin_median_pass(np.ascontiguousarray(s, np.float64),
                                       np.ascontiguousarray(lat, np.float64), float(bin_m))
    keep = ok >= min_count
    return mids[keep], ridge[keep]


@njit(cache=True)
def _middle_pair(v):
    """The values at ranks ``(n - 1) // 2`` and ``n // 2`` of ``v`` (``n`` rows) in sorted
    order, by selection (a partitioned copy): the two values ``numpy.median`` averages."""
    n = v.shape[0]
    hi = n // 2
    p = np.partition(v, hi)
    if n % 2:
        return p[hi], p[hi]
    return p[:hi].max(), p[hi]


@njit(cache=True)
def _bin_median_pass(s, lat, bin_m):
    """Rows bucketed by their bin ``floor((s - min s) / bin_m)`` (a counting pass), each
    nonempty bucket's two middle values selected (:func:`_middle_pair`): per bin in increasing order the medians of ``s``
    and of ``lat`` and the row count. ``lat`` is sorted as the key ``bin * width + (lat -
    min lat)`` and read back as ``key - bin * width + min lat`` (``width`` = its range +
    1), so each median is the same float as from one sort of all rows under that key."""
    n = s.shape[0]
    s0 = s.min()
    lmin = lat.min()
    width = (lat.max() - lmin) + 1.0
    rows = np.empty(n, np.int64)
    for i in range(n):
        rows[i] = np.int64(math.floor((s[i] - s0) / bin_m))
    nb = rows.max() + 1
    start = np.zeros(nb + 1, np.int64)
    for i in range(n):
        start[rows[i] + 1] += 1
    for b in range(nb):
        start[b + 1] += start[b]
    fill = start[:nb].copy()
    sv = np.empty(n)
    kv = np.empty(n)
    for i in range(n):
        q = fill[rows[i]]
        sv[q] = s[i]
        kv[q] = rows[i] * width + (lat[i] - lmin)
        fill[rows[i]] += 1
    mids = np.empty(nb)
    ridge = np.empty(nb)
    count = np.empty(nb, np.int64)
    m = 0
    for b in range(nb):
        a, e = start[b], start[b + 1]
        if e == a:
            continue
        s_lo, s_hi = _middle_pair(sv[a:e])
        k_lo, k_hi = _middle_pair(kv[a:e])
        mids[m] = 0.5 * (s_lo + s_hi)
        ridge[m] = 0.5 * ((k_lo - b * width + lmin) + (k_hi - b * width + lmin))
        count[m] = e - a
        m += 1
    return mids[:m], ridge[:m], count[:m]


def _by_position(xy, t, cfg: ObservabilityConfig):
    """Radar: the principal axis of the positions, the road's lateral position along it
    as the median per ``ridge_bin_m`` bin (follows a bend), off-axis = farther than
    ``corridor_m`` from that ridge; evidence in cells. ``xy, t``: the moving rows."""
    c = np.median(xy, axis=0)
    d = xy - c
    u = np.linalg.eigh(np.cov(d.T))[1][:, 1]
    s, lat = d @ u, d @ np.array([-u[1], u[0]])
    mids, ridge = _bin_medians(cfg.ridge_bin_m, s, lat, min_count=10)
    keep = np.abs(lat - np.interp(s, mids, ridge)) <= cfg.corridor_m if len(mids) else \
        np.ones(len(xy), bool)
    axis = float(np.mod(math.atan2(u[1], u[0]), math.pi))
    return axis, (_cell_evidence(xy, t, cfg, keep, False),
                  _cell_evidence(xy, t, cfg, keep, True)), 'positions'


@njit(cache=True)
def _any_tracks_or_heading(rows, tid, heading):
    """Does any row with ``rows`` carry a track id or a heading?"""
    for i in range(rows.shape[0]):
        if rows[i] and (tid[i] >= 0 or math.isfinite(heading[i])):
            return True
    return False


def assess(dets: Detections | None, cfg: ObservabilityConfig | None = None) -> Observability:
    """Observability of an intersection in ``dets`` (module docstring)."""
    cfg = (cfg or ObservabilityConfig()).validate()
    if dets is None or len(dets) == 0:
        return Observability(NO_DATA, 0.0, 0, 0, None, 'none')
    moving = _moving(dets, cfg)
    if np.count_nonzero(moving) < 2:
        return Observability(NO_DATA, 0.0, 0, 0, None, 'none')
    xy, t = dets.xy[moving], dets.t[moving]        # the moving rows' columns, no full copy
    if _any_tracks_or_heading(moving, dets.track_id, dets.heading):
        axis, (off, on), basis = _by_heading(xy, t, dets.heading[moving],
                                             dets.track_id[moving], cfg)
    else:
        axis, (off, on), basis = _by_position(xy, t, cfg)
    if off == 0 and on == 0:
        return Observability(NO_DATA, 0.0, 0, 0, math.degrees(axis), basis)
    need = cfg.min_off_passages if basis == 'tracks' else cfg.min_off_stretches
    conf = 1.0 - 2.0 ** (-off / need)
    state = INTERSECTION if off >= need else ROAD
    return Observability(state, float(conf), off, on, math.degrees(axis), basis)
