"""Lanes that the traffic shows side by side (beyond the paper).

The likelihood scores a trajectory part by its mean point (paper §II-A). On a curved
approach the means of one lane spread over metres and those of two neighbouring lanes mix,
so a lane that one or two vehicles drove beside the busy one does not pay for its cost and
the MAP keeps too few lanes. Two parts of one arm and driving direction that overlap along
the arm show their lateral separation station by station, ``t_i(s) - t_j(s)``, whatever
the curve of the road; its median over the overlap is the separation of their lanes.

:func:`lanes_side_by_side` places the parts of an arm and direction on one lateral line
(least squares over the separations of the overlapping pairs, per connected group) and
counts the lanes that groups of positions a whole number of lane widths apart (within
``TOL``) span: over the whole profiles and over their first ``NEAR_M`` (36 m), where a turn
pocket's vehicles drive beside the others before they join the main lane's course farther
out; entering profiles also over their first ``POCKET_M`` (24 m). A pocket whose vehicles
drive beside the others over its first 16-20 m only shows half its stretches within 36 m
at a lane's separation and half at none, and the median of the two is no whole lane (SUMO
dev seed 16: two vehicles 3.3 m beside the others from 14 to 32 m out, on their course
beyond). Leaving profiles are not read so short: leaving lanes have no pockets, and near
the box their parts still settle out of their turns (a Table I arm read a fifth lane
there; docs/real_junctions.md, "Stop 57").

:func:`fit_counts` sets an arm's lane count from it (:func:`counted`) and refits its gap,
width and axis offset for the new counts (:func:`.refit.refit_lane_candidates`):

* a lower bound, kept where the part means alone would pay for fewer lanes;
* an upper bound of one lane more than shown, once ``side_by_side_cap`` (2) parts were
  compared: on a curved approach the straight lane rays need an extra lane to cover the
  means' drift, which side by side shows as one lane. Lowering to the lanes shown lost more
  than it fixed: lanes that no pair of vehicles drove at one stretch are not visible here;
* within that bound, a count the MAP keeps above the lanes shown drops by one lane when
  one of its lanes holds no part's median lateral position (:func:`occupied`,
  ``side_by_side_occupied``): the extra lane covered the spread of the parts beside it,
  and no vehicle drove it (SUMO ``topology_observed`` +2 to +4 points on dev, held-out and
  never-tuned seeds, nothing broken on the latter two; docs/real_junctions.md, "Stop 50");
* one lane where no two parts overlap at all (``side_by_side_single``): nothing shows a
  lane beside another, and the lanes the MAP keeps there pay for the spread of a few short
  parts' means (leaving parts that end a few metres beyond the box, on an arm the recording
  cuts short). Offline on the SUMO dev directions it fixed 16 and broke 1; Table I never has
  such a direction with more than one lane.

The lanes are read at the arm's width capped at ``lane_width`` (``side_by_side_width``): a
MAP state that holds two lanes as one widens that lane to cover both lanes' vehicles (on the
SUMO family up to the 4 m limit), and read at that width two lanes 2.75-2.8 m apart lie 0.7
widths apart, no whole lane (SUMO ``topology_observed`` +0-2 points on four seed ranges,
tracked and radar; Table I tracked and AV2 unchanged; docs/real_junctions.md, "Stop 48").

The entering profiles reach ``side_by_side_reach`` (50 m) beyond ``track_radius``, read
as a window of their own (:func:`lanes_beyond`): vehicles that leave a lane for their turn
before the radius show it side by side farther out (on the SUMO family a lane whose only
vehicles were seen 75-100 m out). Read with the stations within the radius, the far stretch
diluted their separations. Far out the profiles' lateral band (``REACH`` lanes beyond the
MAP's lanes) can hold another road, so parts more than ``ROAD_GAP`` lane widths beside the
others are read as one (SUMO held-out seed 1067: a road 19 m beside read as lanes 3-6).
Leaving lanes are not read there: beyond the box a road may gain lanes that the arm does
not have at the box (AV2 scenario 2 gains one 75-100 m out; docs/real_junctions.md,
"Stop 49").

A queue shows its lane too (``side_by_side_queues``, the fewest vehicles of a queue; 3).
Tracks that are never fast are not trajectory parts (:func:`.preprocess.moving_tracks`),
so a lane whose vehicles only queued at the light -- a turn lane through a red phase beside
the lane the moving traffic took -- showed nothing here. Its vehicles stand one behind the
other on the lane (:func:`.standing.queue_groups`), so the line through their positions is
a lateral profile of that lane over the queue's stretch and is compared with the moving
parts like one (:func:`_queue_profiles`). Two vehicles are not a queue here (on the SUMO
family three dev arms gained a lane from a pair parked at the kerb), and a queue farther
than ``ROAD_GAP`` lane widths from every moving part stands on another road (one dev arm
read a 10-vehicle queue on a parallel road as lanes 3-6). SUMO ``topology_observed`` +2.5
points on dev seeds, +7 on held-out seeds (docs/real_junctions.md, "Stop 51").

A row enters a profile only while it heads along the arm (``ALIGN_DEG``), by the tracker's
heading where the rows carry one: headings from noisy positions let turning rows inside a
large box through and raised 10 of 400 Table I arms, the tracker's none. Measured on the
SUMO family and Table I (docs/real_junctions.md, "Lanes side by side"). Only tracked
windows (trajectories); bent arms are measured in their straight frame (the separation at
one station barely depends on it).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..observations import Detections
from .preprocess import moving_mask, track_bounds
from .refit import refit_lane_candidates
from .standing import QUEUE_GAP_M, queue_groups, standing_tracks
from .state import ANG, GAP, HDR, NARMS, NIN, NOUT, STRIDE, WID, arm_origin

__all__ = ['Tracks', 'tracks_of', 'nearest_arm', 'entering_rows', 'arm_frame', 'aligned',
           'arm_profiles', 'lanes_side_by_side', 'side_by_side', 'lanes_beyond', 'counted', 'fit_counts']

#: station step of the lateral profiles [m]
STEP = 2.0
#: rows whose heading is within this of the arm axis enter the profiles [deg]
ALIGN_DEG = 10.0
#: positions farther apart than this share of a lane width are different lanes
SPLIT = 0.5
#: a group is a lane when its distance to the reference is within this share of a whole
#: number of lane widths
TOL = 0.3
#: a profile is not interpolated over more than this between two of its rows [m]
MAX_GAP = 6.0
#: rows up to this many lane widths beyond an arm's outermost lane enter its profiles
REACH = 2.0
#: at most this many parts per arm and direction (the longest) are compared
MAX_PARTS = 64
#: beyond the radius, parts more than this many lane widths beside the others drive another
#: road (:func:`lanes_beyond`)
ROAD_GAP = 2.5
#: the lanes are counted over the whole profiles and over their first this many metres:
#: a turn pocket's vehicles drive beside the others near the box only [m]
NEAR_M = 36.0
#: entering profiles are also counted over their first this many metres: where a pocket's
#: vehicles share the main lane's course over the second half of ``NEAR_M``, the median
#: separation there mixes both (module doc) [m]
POCKET_M = 24.0
#: the near stretches of the entering and the leaving profiles (leaving lanes have no
#: pockets, and near the box their parts still settle out of their turns)
NEARS = ((NEAR_M, POCKET_M), (NEAR_M,))


class Tracks(NamedTuple):
    """Tracked rows sorted by track and time: positions, unit headings from the path and
    the track index of every row; and the vehicles that stand in queues (mean positions,
    unit headings, queue index; :func:`tracks_of`)."""

    xy: np.ndarray
    h: np.ndarray
    tix: np.ndarray
    qxy: np.ndarray = np.zeros((0, 2))
    qh: np.ndarray = np.zeros((0, 2))
    qix: np.ndarray = np.zeros(0, np.int64)


def tracks_of(dets: Detections, skip_labels=(), min_speed: float = 0.0,
              queue: tuple[float, int] | None = None) -> Tracks | None:
    """The tracked rows of ``dets`` (``track_id >= 0``) sorted per track, without road
    users that do not keep to a lane (labels in ``skip_labels``) and without static (false)
    tracks, never faster than ``min_speed`` where the speed is known (as
    :func:`.preprocess.tracked_observations`); None without tracks. ``queue = (min_s,
    min_len)``: also the static tracks that lived ``min_s`` and stand in a queue of at least
    ``min_len`` (:mod:`.standing`), one row each."""
    sel = dets.track_id >= 0
    if len(skip_labels):
        sel &= ~np.isin(dets.label, np.asarray(skip_labels, np.int64))
    order, starts, ends = track_bounds(dets, sel)
    moving = moving_mask(dets, order, starts, min_speed)
    still = (standing_tracks(dets, order, starts, ends, ~moving, queue[0])
             if queue is not None else None)
    starts, ends = starts[moving], ends[moving]
    if len(starts) == 0:
        return None
    rows = np.concatenate([order[a:b] for a, b in zip(starts, ends)])
    tid, xy, hd = dets.track_id[rows], dets.xy[rows], dets.heading[rows]
    new = np.r_[True, tid[1:] != tid[:-1]]
    known = np.isfinite(hd)                       # the tracker's heading where it gives one
    h = np.stack([np.cos(hd), np.sin(hd)], axis=1)
    if not known.all():
        h[~known] = _path_directions(xy, new)[~known]
    if still is None:
        return Tracks(xy, h, np.cumsum(new) - 1)
    qxy, qh, _ = still
    ok = np.isfinite(qh[:, 0])
    qxy, qh = qxy[ok], qh[ok]
    qix = queue_groups(qxy, qh, queue[1])
    q = qix >= 0
    return Tracks(xy, h, np.cumsum(new) - 1, qxy[q], qh[q], qix[q])


def _path_directions(xy: np.ndarray, new: np.ndarray) -> np.ndarray:
    """Unit direction of every row from its track's positions (central differences over
    two rows each way, one-sided at a track's ends; ``new`` marks a track's first row)."""
    tix = np.cumsum(new) - 1
    n = len(xy)
    first = np.flatnonzero(new)[tix]
    last = np.r_[np.flatnonzero(new)[1:] - 1, n - 1][tix]
    i = np.arange(n)
    d = xy[np.minimum(i + 2, last)] - xy[np.maximum(i - 2, first)]
    norm = np.hypot(d[:, 0], d[:, 1])
    return np.where(norm[:, None] > 1e-6, d / np.maximum(norm, 1e-6)[:, None], 0.0)


def nearest_arm(S, xy: np.ndarray) -> np.ndarray:
    """Per row the arm of ``S`` whose direction is closest to the row's bearing from the
    center."""
    n = int(S[NARMS])
    angs = S[HDR + ANG:HDR + n * STRIDE:STRIDE]
    bearing = np.arctan2(xy[:, 1] - S[1], xy[:, 0] - S[0])
    diff = np.abs((bearing[:, None] - angs[None, :] + math.pi) % (2 * math.pi) - math.pi)
    return diff.argmin(axis=1)


def entering_rows(S, tr: Tracks) -> np.ndarray:
    """Per row: does it belong to its track's entering part (up to the track's row closest
    to the center of ``S``, paper §II-A)?"""
    r2 = (tr.xy[:, 0] - S[0]) ** 2 + (tr.xy[:, 1] - S[1]) ** 2
    starts = np.flatnonzero(np.r_[True, tr.tix[1:] != tr.tix[:-1]])
    split = np.array([a + int(np.argmin(r2[a:b]))
                      for a, b in zip(starts, np.r_[starts[1:], len(r2)])], np.int64)
    return np.arange(len(r2)) <= split[tr.tix]


def arm_frame(S, k, xy: np.ndarray, h: np.ndarray):
    """``(s, t, c)`` of rows ``xy`` with unit headings ``h`` in the straight frame of arm
    ``k`` of ``S``: distance along its axis from the axis origin, lateral offset (left
    positive) and the cosine between heading and axis."""
    a = S[HDR + k * STRIDE + ANG]
    ux, uy = math.cos(a), math.sin(a)
    ox, oy = arm_origin(S, k, ux, uy)
    return ((xy[:, 0] - ox) * ux + (xy[:, 1] - oy) * uy,
            (xy[:, 1] - oy) * ux - (xy[:, 0] - ox) * uy,
            h[:, 0] * ux + h[:, 1] * uy)


def _across(S, k: int, t, sign: float, traffic_side: int) -> np.ndarray:
    """Lateral offsets ``t`` (:func:`arm_frame`) of arm ``k`` of ``S`` as the distance
    across the lanes of one direction (``sign`` 1 entering, -1 leaving) from its median
    edge: lane ``j`` spans ``[j w, (j + 1) w)`` (the likelihood's lateral coordinate)."""
    return sign * traffic_side * np.asarray(t) - 0.5 * S[HDR + k * STRIDE + GAP]


def stations(inner: float, outer: float) -> np.ndarray:
    """The profiles' stations along an arm: ``inner, inner + STEP, ... < outer`` [m]
    (:func:`arm_profiles`; :func:`fit_counts` counts those within ``track_radius``)."""
    return np.arange(inner, outer, STEP)


def arm_profiles(S, k, tr: Tracks, arm_of_row, entering, inner: float, outer: float,
                 traffic_side: int = 1, reach: float = 0.0,
                 arm_of_queue: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Lateral profiles of the trajectory parts on arm ``k`` of ``S``, entering and
    leaving: rows ``t(s)`` on the stations ``inner, inner + STEP, ... < outer + reach``
    (NaN off the part; leaving parts end at ``outer``, module doc) from the part's rows
    (``entering``, :func:`entering_rows`) on the arm (``arm_of_row``, :func:`nearest_arm`)
    heading along the axis within ``ALIGN_DEG`` the part's way, beyond ``inner`` and within
    ``REACH`` lane widths beyond the arm's lanes of that direction (the likelihood's
    lateral coordinate, :func:`.likelihood._closest_lane`); the entering side also from
    the queues on the arm (``arm_of_queue``, :func:`nearest_arm` of ``tr.qxy``; None: read
    here)."""
    grid = stations(inner, outer + reach)
    mine = np.flatnonzero(arm_of_row == k)
    tix, entering = tr.tix[mine], entering[mine]
    s, t, c = arm_frame(S, k, tr.xy[mine], tr.h[mine])
    i0 = HDR + k * STRIDE
    w = S[i0 + WID]
    base = (s >= inner) & aligned(c)
    out = []
    for sign, nl, part, end in ((1.0, S[i0 + NIN], entering, outer + reach),
                                (-1.0, S[i0 + NOUT], ~entering, outer)):
        q = _across(S, k, t, sign, traffic_side)
        rows = np.flatnonzero(base & part & (sign * c < 0) & _in_band(q, w, nl))
        profiles = []
        for g in np.split(rows, np.flatnonzero(np.diff(tix[rows])) + 1):
            if len(g) >= 3 and np.ptp(s[g]) >= STEP:
                profiles.append(_profile(grid, s[g], t[g], MAX_GAP, end))
        if sign > 0 and profiles and len(tr.qxy):
            on = (nearest_arm(S, tr.qxy) if arm_of_queue is None else arm_of_queue) == k
            profiles += _queue_profiles(S, k, tr, on, grid, inner, end, traffic_side,
                                        np.array(profiles))
        out.append(_longest(profiles, len(grid)))
    return out[0], out[1]


def aligned(c: np.ndarray) -> np.ndarray:
    """Rows whose heading lies within ``ALIGN_DEG`` of an arm's axis, either way (``c``:
    the cosine between heading and axis, :func:`arm_frame`)."""
    return np.abs(c) >= math.cos(math.radians(ALIGN_DEG))


def _in_band(q: np.ndarray, w: float, nl: float) -> np.ndarray:
    """Lateral positions ``q`` (:func:`_across`) within the profiles' band: from one lane
    width inside the median gap to ``REACH`` lanes beyond the ``nl`` lanes of the direction."""
    return (q > -w) & (q < (nl + REACH) * w)


def _profile(grid: np.ndarray, s: np.ndarray, t: np.ndarray, max_gap: float,
             end: float) -> np.ndarray:
    """Lateral offsets ``t`` at stations ``s`` (any order) interpolated onto ``grid``; NaN
    off their stretch, across gaps wider than ``max_gap`` and from ``end`` on."""
    o = np.argsort(s)
    ss, tt = s[o], t[o]
    prof = np.interp(grid, ss, tt)
    j = np.clip(np.searchsorted(ss, grid), 1, len(ss) - 1)
    prof[(grid < ss[0]) | (grid > ss[-1]) | (ss[j] - ss[j - 1] > max_gap) | (grid >= end)] = np.nan
    return prof


def _queue_profiles(S, k, tr: Tracks, on, grid, inner: float, end: float, traffic_side: int,
                    T: np.ndarray) -> list:
    """Lateral profiles of the queues standing on arm ``k``'s entering side (its queue
    vehicles: mask ``on``) beside its moving parts ``T`` (module doc): a queue's vehicles
    stand one behind the other on their lane, so the line through them is the lane's course
    over the queue's stretch, as a trajectory part's rows are. A queue farther than
    ``ROAD_GAP`` lane widths from every part at every station they share stands on another
    road."""
    w, nl = S[HDR + k * STRIDE + WID], S[HDR + k * STRIDE + NIN]
    s, t, c = arm_frame(S, k, tr.qxy[on], tr.qh[on])
    ok = ((s >= inner) & aligned(c) & (c < 0)
          & _in_band(_across(S, k, t, 1.0, traffic_side), w, nl))
    s, t, qix = s[ok], t[ok], tr.qix[on][ok]
    out = []
    for g in np.unique(qix):
        m = qix == g
        if m.sum() < 2:
            continue
        prof = _profile(grid, s[m], t[m], QUEUE_GAP_M[1], end)
        if np.nanmin(np.abs(T - prof), initial=np.inf) <= ROAD_GAP * w:
            out.append(prof)
    return out


def _longest(rows: list, m: int) -> np.ndarray:
    """At most ``MAX_PARTS`` profiles, the longest first (ties: track order)."""
    if not rows:
        return np.empty((0, m))
    T = np.array(rows)
    keep = np.argsort(-np.isfinite(T).sum(1), kind='stable')[:MAX_PARTS]
    return T[keep]


def _positions(T: np.ndarray, min_overlap: float) -> list[np.ndarray]:
    """Lateral position of every part per connected group of overlapping parts (least
    squares over the pairwise median separations, the group's first part at 0)."""
    P = len(T)
    if P < 2:
        return []
    ok = np.isfinite(T)
    both = ok[:, None, :] & ok[None, :, :]
    overlap = both.sum(-1) * STEP >= min_overlap
    iu, ju = np.nonzero(np.triu(overlap, 1))
    if len(iu) == 0:
        return []
    sep = _row_medians(np.where(both[iu, ju], T[iu] - T[ju], np.nan))
    lab = _components(overlap | overlap.T)
    out = []
    for g in np.unique(lab):
        members = np.flatnonzero(lab == g)
        if len(members) < 2:
            continue
        pos = np.full(P, -1)
        pos[members] = np.arange(len(members))
        e = np.flatnonzero(lab[iu] == g)
        A = np.zeros((len(e) + 1, len(members)))
        A[np.arange(len(e)), pos[iu[e]]] = 1.0
        A[np.arange(len(e)), pos[ju[e]]] = -1.0
        A[-1, 0] = 1.0
        out.append(np.linalg.lstsq(A, np.r_[sep[e], 0.0], rcond=None)[0])
    return out


def _row_medians(D: np.ndarray) -> np.ndarray:
    """Median of every row's finite entries (each row has at least one): NaN sorts last,
    so the middle of the first ``count`` entries (``np.nanmedian`` without its masked-array
    cost on many short rows)."""
    D = np.sort(D, axis=1)
    cnt = np.isfinite(D).sum(1)
    r = np.arange(len(D))
    return 0.5 * (D[r, (cnt - 1) // 2] + D[r, cnt // 2])


def _components(adj: np.ndarray) -> np.ndarray:
    """Connected-component label (its smallest member) of every node of the symmetric
    boolean adjacency ``adj``: labels spread to neighbours until they stop changing."""
    lab = np.arange(len(adj))
    big = len(adj)
    while True:
        nxt = np.minimum(lab, np.where(adj, lab[None, :], big).min(axis=1))
        if np.array_equal(nxt, lab):
            return lab
        lab = nxt


def _lanes_spanned(p: np.ndarray, w: float) -> int:
    """Lanes that the positions ``p`` of one group span: groups split where neighbours are
    more than ``SPLIT * w`` apart; from each group as reference, the farthest group within
    ``TOL`` lane widths of a whole number of widths."""
    p = np.sort(p)
    cuts = np.flatnonzero(np.diff(p) > SPLIT * w) + 1
    cen = np.array([g.mean() for g in np.split(p, cuts)])
    best = 1
    for r in cen:
        slots = np.abs(cen - r) / w
        whole = np.abs(slots - np.round(slots)) < TOL
        best = max(best, int(np.round(slots[whole]).max()) + 1)
    return best


def lanes_side_by_side(T: np.ndarray, w: float, min_overlap: float,
                       near: tuple = (NEAR_M,)) -> int:
    """Lanes that the profiles ``T`` (one arm and direction, :func:`arm_profiles`) show
    side by side, over their whole length or one of their first ``near`` stretches [m]
    (entering: ``NEAR_M`` and ``POCKET_M``): 0 when no two parts overlap by
    ``min_overlap`` metres."""
    return side_by_side(T, w, min_overlap, near)[0]


def side_by_side(T: np.ndarray, w: float, min_overlap: float,
                 near: tuple = (NEAR_M,)) -> tuple[int, int]:
    """(:func:`lanes_side_by_side`, the number of parts compared: in a group of the whole
    profiles)."""
    whole = _positions(T, min_overlap)
    groups = whole + [p for m in near for p in _positions(T[:, :int(m / STEP)], min_overlap)]
    return (max((_lanes_spanned(p, w) for p in groups), default=0),
            int(sum(len(p) for p in whole)))


def lanes_beyond(T: np.ndarray, w: float, min_overlap: float) -> int:
    """Lanes that the stations ``T`` beyond ``track_radius`` show side by side, read on
    their own (module doc: read with the stations within, the stretch where the vehicles
    have not yet taken their lanes dilutes the separations near the box); 0 when no two
    parts overlap there. Parts more than ``ROAD_GAP`` lane widths beside the others drive
    another road: far out the lateral band of the profiles is wide enough to hold one."""
    best = 0
    for p in _positions(T, min_overlap):
        p = np.sort(p)
        for road in np.split(p, np.flatnonzero(np.diff(p) > ROAD_GAP * w) + 1):
            best = max(best, _lanes_spanned(road, w))
    return best


def occupied(S, k: int, T: np.ndarray, side: int, traffic_side: int = 1) -> int:
    """Lanes of arm ``k`` of ``S`` in direction ``side`` (0 entering, 1 leaving) that hold
    the median lateral position of at least one profile of ``T`` (:func:`arm_profiles`),
    counted from the median side; positions beyond the outermost lane count for it."""
    i0 = HDR + k * STRIDE
    ok = np.isfinite(T).any(1)
    if not ok.any():
        return 0
    q = _across(S, k, np.nanmedian(T[ok], axis=1), 1.0 if side == 0 else -1.0, traffic_side)
    n = int(S[i0 + (NIN if side == 0 else NOUT)])
    return len(np.unique(np.clip(np.floor(q / S[i0 + WID]), 0, n - 1)))


def counted(n: int, shown: int, compared: int, cfg, beyond: int = 0) -> int:
    """Lane count of one arm direction given the MAP's ``n``, the lanes ``shown`` side by
    side within ``track_radius``, the parts ``compared`` there and the lanes shown
    ``beyond`` it (0 without the reach): at least the lanes shown within or beyond (up to
    ``max_lanes``); with at least ``side_by_side_cap`` parts compared and a lane shown, at
    most one lane beyond the most shown; with ``side_by_side_single``, no two parts side by
    side within and no second lane shown beyond, one lane."""
    most = max(shown, beyond)
    want = min(cfg.max_lanes, max(n, most))
    if cfg.side_by_side_cap > 0 and compared >= cfg.side_by_side_cap and most >= 1:
        want = min(want, most + 1)
    if cfg.side_by_side_single and shown == 0 and beyond <= 1:
        want = max(cfg.min_lanes, min(want, 1))
    return want


def fit_counts(post, S: np.ndarray, tr: Tracks | None, cfg) -> tuple[np.ndarray, float | None]:
    """``S`` with every arm's lane counts set by what the traffic shows side by side
    (:func:`counted`), gap / width / offset of a changed arm refitted; returns
    ``(S, log posterior)``, the log posterior None when nothing changed."""
    if tr is None or cfg.side_by_side_overlap <= 0:
        return S, None
    arm_of_row, entering = nearest_arm(S, tr.xy), entering_rows(S, tr)
    arm_of_queue = nearest_arm(S, tr.qxy)      # center and angles stay: the refits below keep them
    inner = max(cfg.part_outside, STEP)
    outer = cfg.track_radius if math.isfinite(cfg.track_radius) else 150.0
    inside = len(stations(inner, outer))                 # stations within track_radius
    lpost = None
    for k in range(int(S[NARMS])):
        i0 = HDR + k * STRIDE
        profiles = arm_profiles(S, k, tr, arm_of_row, entering, inner, outer, cfg.traffic_side,
                                cfg.side_by_side_reach, arm_of_queue)
        now = [int(S[i0 + NIN]), int(S[i0 + NOUT])]
        w = min(S[i0 + WID], cfg.lane_width) if cfg.side_by_side_width else S[i0 + WID]   # module doc
        ov = cfg.side_by_side_overlap
        want = []
        for side, (n, T) in enumerate(zip(now, profiles)):
            shown, compared = side_by_side(T[:, :inside], w, ov, NEARS[side])
            beyond = lanes_beyond(T[:, inside:], w, ov)
            m = counted(n, shown, compared, cfg, beyond)
            if (cfg.side_by_side_occupied and m == n > max(shown, beyond, 1)
                    and occupied(S, k, T[:, :inside], side, cfg.traffic_side) < n):
                m = n - 1                     # a lane no part drove, beyond those shown
            want.append(m)
        if want != now:
            (S, lpost), = refit_lane_candidates(post, S, k, [want])
    return S, lpost
