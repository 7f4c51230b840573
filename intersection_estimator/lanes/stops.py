"""Path model of the turning traffic (extensions of paper §III-A).

``fit_stops``: the stop-line distance per arm from the turning traffic.
``complete_partial``: the missing lane of a trajectory seen on one side only.

The topology gives rays; where an arm's lanes end (and its connectors begin) is not
part of it. ``init.stop_distances`` guesses it from the arm geometry; here we fit it:
every trajectory with an entering and a leaving lane defines a path -- straight along
its entering lane up to the stop line of arm ``a``, an arc-like cubic Bezier
(``init.arc_bezier``, handles ``init.arc_handle``) to the stop line of arm ``b``, straight out along its leaving
lane. Coordinate descent over the arms, a 1-D grid search per arm, minimises the
robust (Huber-like, clipped) squared distance of the trajectories' points near the
intersection to their paths. Straight-through traffic hardly constrains the stop
line; turning traffic does.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .init import arc_handle
from .likelihood import window_d2

__all__ = ['fit_stops', 'path_cost', 'complete_partial']

_NB = 12          # Bezier samples per path
_EXT = 25.0       # straight extension before/after the connector [m]


@njit(cache=True)
def _path(p0x, p0y, t0x, t0y, p1x, p1y, t1x, t1y, out):
    """Polyline: straight in, arc-like Bezier, straight out (``out``: (_NB + 2, 2))."""
    h = arc_handle(math.hypot(p1x - p0x, p1y - p0y), t0x * t1x + t0y * t1y)
    q0x, q0y, q1x, q1y = p0x + h * t0x, p0y + h * t0y, p1x - h * t1x, p1y - h * t1y
    out[0, 0], out[0, 1] = p0x - _EXT * t0x, p0y - _EXT * t0y
    for i in range(_NB):
        s = i / (_NB - 1)
        a, b, cc, d = (1 - s) ** 3, 3 * (1 - s) ** 2 * s, 3 * (1 - s) * s ** 2, s ** 3
        out[i + 1, 0] = a * p0x + b * q0x + cc * q1x + d * p1x
        out[i + 1, 1] = a * p0y + b * q0y + cc * q1y + d * p1y
    out[_NB + 1, 0], out[_NB + 1, 1] = p1x + _EXT * t1x, p1y + _EXT * t1y


@njit(cache=True)
def path_cost(stops, arm_in, off_in, arm_out, off_out, pptr, pts, O, U, N, sel, clip2):
    """Sum over the trajectories ``sel`` of the clipped squared point-to-path distances.

    Arm ``a`` has lanes ``O[a] + s U[a] + off N[a]``."""
    buf = np.empty((_NB + 2, 2))
    total = 0.0
    for k in range(len(sel)):
        i = sel[k]
        a, b = arm_in[i], arm_out[i]
        p0x = O[a, 0] + stops[a] * U[a, 0] + off_in[i] * N[a, 0]
        p0y = O[a, 1] + stops[a] * U[a, 1] + off_in[i] * N[a, 1]
        p1x = O[b, 0] + stops[b] * U[b, 0] + off_out[i] * N[b, 0]
        p1y = O[b, 1] + stops[b] * U[b, 1] + off_out[i] * N[b, 1]
        _path(p0x, p0y, -U[a, 0], -U[a, 1], p1x, p1y, U[b, 0], U[b, 1], buf)
        for q in range(pptr[i], pptr[i + 1]):
            total += min(window_d2(buf, 0, _NB + 1, pts[q, 0], pts[q, 1]), clip2)
    return total


def fit_stops(topo, frames, trajs, stops0: np.ndarray, search: float, step: float,
              radius: float, clip: float = 2.0, sweeps: int = 2) -> np.ndarray:
    """Coordinate descent over the arms' stop distances (module docstring)."""
    from ..model import ENTERING, LEAVING
    stops = np.asarray(stops0, float).copy()
    rows = [tr for tr in trajs if tr.lane_in is not None and tr.lane_out is not None]
    if not rows or not len(frames):
        return stops
    O = np.array([f.origin for f in frames])
    U = np.array([f.u for f in frames])
    N = np.array([f.n for f in frames])
    arm_in = np.array([t.lane_in[0] for t in rows], np.int64)
    arm_out = np.array([t.lane_out[0] for t in rows], np.int64)
    off_in = np.array([frames[t.lane_in[0]].lat[(ENTERING, t.lane_in[1])] for t in rows])
    off_out = np.array([frames[t.lane_out[0]].lat[(LEAVING, t.lane_out[1])] for t in rows])
    arms = frames
    # points on the straight parts farther out than any candidate stop line cost the
    # same for every candidate: keep the turn and a margin around the stop lines
    reach = search + 3.0
    near = [t.xy[(np.linalg.norm(t.xy - topo.center, axis=1) < radius)
                 & ((t.xy - O[a]) @ U[a] < stops0[a] + reach)
                 & ((t.xy - O[b]) @ U[b] < stops0[b] + reach)]
            for t, a, b in zip(rows, arm_in, arm_out)]
    pptr = np.concatenate([[0], np.cumsum([len(x) for x in near])]).astype(np.int64)
    pts = np.concatenate(near) if pptr[-1] else np.zeros((0, 2))
    coarse = np.arange(-search, search + 1e-9, 4 * step)
    fine = np.arange(-1.5 * step * 2, 1.5 * step * 2 + 1e-9, step)
    for _ in range(sweeps):
        for a in range(len(arms)):
            sel = np.flatnonzero(((arm_in == a) | (arm_out == a)) & (arm_in != arm_out))
            if not len(sel):
                continue
            sel = sel.astype(np.int64)

            def cost(v):
                stops[a] = v
                return path_cost(stops, arm_in, off_in, arm_out, off_out, pptr, pts, O, U, N,
                                 sel, clip * clip)
            lo, hi = stops0[a] - search, stops0[a] + search
            best = min(stops0[a] + coarse, key=cost)                  # coarse grid, then
            stops[a] = min(np.clip(best + fine, lo, hi), key=cost)    # refine around it
    return stops


def complete_partial(topo, frames, trajs, stops, min_points: int = 5, max_cost: float = 1.5,
                     min_ratio: float = 1.5, clip: float = 2.0) -> int:
    """Give a trajectory seen only on one side of the intersection its other lane.

    A track that starts or ends inside the intersection has one part too short to be
    assigned, so it would connect nothing. Its points inside the stop line of its
    known lane are scored against the path to every lane of the other direction on
    the other arms; the best is taken when it fits (mean clipped squared distance
    below ``max_cost``) and is clearly better (``min_ratio``) than the runner-up.
    Returns the number of completed trajectories.
    """
    from ..model import ENTERING, LEAVING
    if not len(frames):
        return 0
    O = np.array([f.origin for f in frames])
    U = np.array([f.u for f in frames])
    N = np.array([f.n for f in frames])
    lanes = {d: [(a, k, lat) for a, f in enumerate(frames) for (dd, k), lat in f.lat.items()
                 if dd == d] for d in (ENTERING, LEAVING)}
    done = 0
    for tr in trajs:
        if (tr.lane_in is None) == (tr.lane_out is None):
            continue
        known_in = tr.lane_in is not None
        a, k = tr.lane_in if known_in else tr.lane_out
        lat = frames[a].lat[(ENTERING if known_in else LEAVING, k)]
        s = (tr.xy - O[a]) @ U[a]
        inside = tr.xy[s < stops[a]]
        cands = [(b, j, o) for b, j, o in lanes[LEAVING if known_in else ENTERING] if b != a]
        if len(inside) < min_points or not cands:
            continue
        K, m = len(cands), len(inside)
        mine = np.full(K, a, np.int64)
        other = np.array([b for b, _, _ in cands], np.int64)
        lat_m, lat_o = np.full(K, lat), np.array([o for _, _, o in cands])
        pts = np.tile(inside, (K, 1))
        pptr = np.arange(K + 1, dtype=np.int64) * m
        costs = np.array([path_cost(stops, *((mine, lat_m, other, lat_o) if known_in else
                                             (other, lat_o, mine, lat_m)),
                                    pptr, pts, O, U, N, np.array([i], np.int64), clip * clip)
                          for i in range(K)]) / m
        order = np.argsort(costs)
        best = costs[order[0]]
        second = costs[order[1]] if K > 1 else np.inf
        if best <= max_cost and second >= min_ratio * best:
            b, j, _ = cands[order[0]]
            if known_in:
                tr.lane_out = (b, j)
            else:
                tr.lane_in = (b, j)
            done += 1
    return done
