"""Halted vehicles: where the stop lines are and where the entering lanes run (beyond the paper).

An entering lane ends at its stop line, and its connectors start there (paper §III-A). The
topology gives rays, not stop lines: ``init.stop_distances`` places them by the corner
geometry of neighbouring arms, and ``stops.fit_stops`` moves them a little (``stop_search``)
to the turning traffic. On real junctions that geometry puts them far out: skewed arms and
wide approaches push the corner back, so lanes end 7 m (median; p90 21 m) before SUMO's
stop lines and the connectors carry the last stretch of every approach
(``docs/real_junctions.md``, "Halted vehicles: stop lines and lanes").

Vehicles show the line themselves: at a red light or a yield sign the first vehicle of each
lane halts just behind it. So:

* a *halt* is a stretch of one track slower than ``halt_speed`` for at least ``halt_min_s``
  (the speed median-filtered over about a second; positions and circular-mean heading
  averaged over the stretch) -- :func:`halt_positions`;
* a halt belongs to arm ``a``'s entering side when it faces the box (heading within
  ``HEADING_DEG`` of ``-u``), lies outside the center (``s > 0`` along the arm) and within
  the arm's entering lanes across (half a lane beyond the outer ones);
* the stop line is the innermost halt that another vehicle confirms: a second track halted
  within ``halt_pair_m`` of it along the arm (the head of the next lane, or the next
  cycle's first vehicle). A vehicle waiting alone inside the box to turn, the most common
  halt short of the line, has no such partner;
* the reported position is the vehicle's center, ``HALF_CAR_M`` behind the line (half a car
  and the gap a driver keeps); the line moves in only (:func:`halt_stops`): a queue
  standing farther out says nothing about where the lanes end.

Without track identities or without confirmed halts an arm keeps the stop line it had.

``halt_stops`` (off by default) moves the lines so, by at most ``halt_max_move`` (5 m). It
gains recall, but on curved approaches the stretch the lanes gain runs beside its queue, and
the connectors that start there lose more than recall gains on two of three seed ranges (the
docs section above).

The halted vehicles also show where the entering lanes run next to the box
(:func:`entering_halts`, ``halt_follow``, on): a queue that stood through a red phase is
often the only traffic there, and the follow fit (``lanes/follow.py``) weighs each point by
the metres driven around it, so a standing vehicle weighed nothing and the lanes ran
straight past the curve its queue stands on. Each halt now becomes one point of the lane
nearest it, weighing ``follow_corr_length`` metres -- the metres of driving that count as
one observation there: a halted vehicle is one observation of where its lane runs.
"""

from __future__ import annotations

import math

import numpy as np

from ..observations import Detections
from ..topology.preprocess import track_bounds

__all__ = ['halt_positions', 'halt_stops', 'entering_halts', 'HALF_CAR_M', 'HEADING_DEG']

#: a halted vehicle's position (its box center) lies this far behind the stop line [m]:
#: half a car (2.3 m) and about a metre to the line
HALF_CAR_M = 3.5
#: a halt faces the box when its heading is within this of the arm's inward direction [deg]
HEADING_DEG = 25.0
#: the speed is median-filtered over this many seconds (a tracked object's speed is noisy)
SPEED_FILTER_S = 1.0
#: without a speed column the speed is read from positions this far apart in time [s]
POSITION_BASELINE_S = 2.0


def _speeds(key: np.ndarray, xy: np.ndarray, speed: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Each row's speed [m/s]: the reported one where it is finite, else the displacement over
    ``POSITION_BASELINE_S`` (centred, within its track; ``key``: time offset by track so that
    one sorted search serves all tracks)."""
    v = np.asarray(speed, float).copy()
    miss = ~np.isfinite(v)
    if miss.any():
        a = np.maximum(np.searchsorted(key, key - 0.5 * POSITION_BASELINE_S), lo)
        b = np.minimum(np.searchsorted(key, key + 0.5 * POSITION_BASELINE_S, side='right'), hi) - 1
        dt = np.maximum(key[b] - key[a], 1e-6)
        est = np.hypot(*(xy[b] - xy[a]).T) / dt
        est[b <= a] = np.inf                       # a lone row: no speed, no halt
        v[miss] = est[miss]
    return v


def _majority(flag: np.ndarray, k: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``flag`` by majority over ``k`` rows centred on each row, within its track: the median
    filter of the speed, thresholded (median < v  <=>  most of the window < v)."""
    c = np.r_[0, np.cumsum(flag)]
    i = np.arange(len(flag))
    a = np.maximum(i - k // 2, lo)
    b = np.minimum(i + k // 2 + 1, hi)
    return 2 * (c[b] - c[a]) > (b - a)


def halt_positions(dets: Detections | None, skip_labels=(), max_speed: float = 0.5,
                   min_s: float = 2.0):
    """``(xy (n, 2), heading unit vectors (n, 2), track id (n,))`` of every halt of every
    track (module doc); halts without a heading are left out (which way they face is the
    test). Road users of ``skip_labels`` do not drive lanes and are left out."""
    empty = (np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, np.int64))
    if dets is None or len(dets) == 0:
        return empty
    idx, starts, ends = track_bounds(dets, dets.track_mask(skip_labels))
    if len(idx) < 3:
        return empty
    tid, t, xy = dets.track_id[idx], dets.t[idx], dets.xy[idx]
    rank = np.repeat(np.arange(len(starts)), ends - starts)       # each row's track
    lo, hi = starts[rank], ends[rank]
    t0 = t - t.min()
    key = t0 + rank * (t0.max() + 10.0 * POSITION_BASELINE_S)
    same = np.diff(tid) == 0
    step = np.diff(t)[same]
    dt = float(np.median(step[step > 0])) if np.any(step > 0) else 1.0
    k = max(1, int(round(SPEED_FILTER_S / max(dt, 1e-3))) | 1)
    slow = _majority(_speeds(key, xy, dets.speed[idx], lo, hi) < max_speed, k, lo, hi)
    # runs of slow rows within one track
    start = np.flatnonzero(np.r_[True, (slow[1:] != slow[:-1]) | ~same])
    stop = np.r_[start[1:], len(idx)]
    run = slow[start] & (t[stop - 1] - t[start] >= min_s)
    start, stop = start[run], stop[run]
    if not len(start):
        return empty
    h = dets.heading[idx]
    ok = np.isfinite(h)
    cs = np.stack([np.where(ok, np.cos(h), 0.0), np.where(ok, np.sin(h), 0.0)], 1)
    return _finish(xy, cs, start, stop, tid)


def _finish(xy, cs, start, stop, tid):
    """Mean position and heading of the rows ``start[i]:stop[i]`` of each halt; halts without
    a heading dropped."""
    pos = np.array([xy[a:b].mean(axis=0) for a, b in zip(start, stop)])
    hv = np.array([cs[a:b].sum(axis=0) for a, b in zip(start, stop)])
    norm = np.hypot(hv[:, 0], hv[:, 1])
    ok = norm > 1e-9
    return pos[ok], hv[ok] / norm[ok, None], tid[start][ok].astype(np.int64)


def _on_entering_side(f, halts) -> np.ndarray:
    """Mask of the halts on arm frame ``f``'s entering side: facing the box, outside the
    center, and across within its entering lanes and half a lane beyond them."""
    from ..model import ENTERING
    xy, hv, _ = halts
    lat = [o for (d, _), o in f.lat.items() if d == ENTERING]
    if not lat or not len(xy):
        return np.zeros(len(xy), bool)
    half = 0.5 * float(f.width)
    rel = xy - f.origin
    s, across = rel @ f.u, rel @ f.n
    return (((hv @ -np.asarray(f.u)) > math.cos(math.radians(HEADING_DEG))) & (s > 0.0)
            & (across >= min(lat) - half) & (across <= max(lat) + half))


def entering_halts(f, halts, lo: float, hi: float) -> np.ndarray:
    """Positions (m, 2) of the halts on arm frame ``f``'s entering side between ``lo`` and
    ``hi`` along the arm (the lanes' extent beyond the stop line)."""
    xy = halts[0]
    m = _on_entering_side(f, halts)
    s = (xy - f.origin) @ f.u if len(xy) else np.zeros(0)
    return xy[m & (s >= lo) & (s <= hi)]


def halt_stops(frames, stops: np.ndarray, halts, pair_m: float, stop_min: float,
               max_move: float = math.inf) -> np.ndarray:
    """Stop distances moved in to where the vehicles halt (module doc), by at most
    ``max_move`` each. ``frames``: the arm frames (origin, ``u`` outwards, ``n``, lane offsets
    ``lat``); ``halts``: the triple of :func:`halt_positions`. Returns a new array."""
    out = np.asarray(stops, float).copy()
    xy, _, ids = halts
    if not len(xy):
        return out
    for a, f in enumerate(frames):
        mine = np.flatnonzero(_on_entering_side(f, halts))
        s = (xy[mine] - f.origin) @ f.u
        for i in _confirmed(s, ids[mine], pair_m):
            out[a] = max(min(out[a], s[i] - HALF_CAR_M), stop_min, out[a] - max_move)
            break
    return out


def _confirmed(s: np.ndarray, ids: np.ndarray, pair_m: float):
    """Indices of the halts, innermost first, with a halt of another track within ``pair_m``
    of them along the arm."""
    for i in np.argsort(s, kind='stable'):
        if np.any((np.abs(s - s[i]) <= pair_m) & (ids != ids[i])):
            yield int(i)
