"""Trajectory likelihood of the lane course (paper §III-C, eq. for P(t_i | I_2)).

Every trajectory is assigned to its lane sequence (entering lanelet, connector,
leaving lanelet), so the sum over lanes ``sum_l 1(t_i, l)`` has one term and

    log P(t_i | I_2) = sum_{p in t_i} log N(d_perp(p, M_l); 0, sigma_perp)

with ``M_l`` the center line of the sequence. Each point keeps a window of one
(``window_segments``) or two center-line segments -- its nearest one at assignment --
(``win_lo``..``win_hi`` stations), so a move re-scores only the points whose window
touches a changed center point.
Points farther than ``point_gate`` from their sequence are dropped at assignment; an
optional uniform outlier weight makes the term robust: ``log(exp(-d^2/2s^2) + eps)``
(``eps = 0``: the plain Gaussian, cheapest).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ['seg_dist2', 'point_term', 'window_d2', 'all_terms', 'assign_points', 'station_csr']


@njit(cache=True)
def seg_dist2(px, py, ax, ay, bx, by):
    """Squared distance of point p to segment ab."""
    dx, dy = bx - ax, by - ay
    L2 = dx * dx + dy * dy
    t = 0.0
    if L2 > 1e-18:
        t = ((px - ax) * dx + (py - ay) * dy) / L2
        t = min(1.0, max(0.0, t))
    ex, ey = px - (ax + t * dx), py - (ay + t * dy)
    return ex * ex + ey * ey


@njit(cache=True)
def point_term(d2, inv2s2, eps):
    """log of N(d_perp) (unnormalised), mixed with a uniform outlier weight if eps > 0."""
    if eps <= 0.0:
        return -d2 * inv2s2
    return math.log(math.exp(-d2 * inv2s2) + eps)


@njit(cache=True)
def window_d2(C, lo, hi, px, py):
    """Smallest squared distance of p to the segments between stations lo..hi."""
    best = 1e300
    for g in range(lo, hi):
        d = seg_dist2(px, py, C[g, 0], C[g, 1], C[g + 1, 0], C[g + 1, 1])
        if d < best:
            best = d
    return best


@njit(cache=True)
def all_terms(C, Q, win_lo, win_hi, inv2s2, eps, out):
    """Reference (full) recomputation of every point term; returns their sum."""
    s = 0.0
    for q in range(len(Q)):
        out[q] = point_term(window_d2(C, win_lo[q], win_hi[q], Q[q, 0], Q[q, 1]), inv2s2, eps)
        s += out[q]
    return s


def station_csr(n_stations: int, lo: np.ndarray, hi: np.ndarray):
    """CSR (ptr, idx): for each station the points whose window contains it."""
    lens = (hi - lo + 1).astype(np.int64)
    q = np.repeat(np.arange(len(lo), dtype=np.int64), lens)
    g = np.repeat(lo, lens) + (np.arange(len(q)) - np.repeat(np.cumsum(lens) - lens, lens))
    order = np.argsort(g, kind='stable')
    ptr = np.zeros(n_stations + 1, np.int64)
    ptr[1:] = np.cumsum(np.bincount(g, minlength=n_stations))
    return ptr, q[order]


@njit(cache=True)
def _assign_nb(C, st_off, st_n, tptr, pts, lptr, lanes, gate2, nseg, lo, hi, ll, keep):
    for i in range(len(tptr) - 1):
        for q in range(tptr[i], tptr[i + 1]):
            px, py = pts[q, 0], pts[q, 1]
            best, bl, bg = gate2, -1, -1
            for j in range(lptr[i], lptr[i + 1]):
                l = lanes[j]
                for g in range(st_off[l], st_off[l] + st_n[l] - 1):
                    d = seg_dist2(px, py, C[g, 0], C[g, 1], C[g + 1, 0], C[g + 1, 1])
                    if d < best:
                        best, bl, bg = d, l, g
            if bl < 0:
                continue
            keep[q] = True
            ll[q] = bl
            # two segments: the nearest and its neighbour on the side of the foot point
            dx, dy = C[bg + 1, 0] - C[bg, 0], C[bg + 1, 1] - C[bg, 1]
            t = ((px - C[bg, 0]) * dx + (py - C[bg, 1]) * dy) / max(dx * dx + dy * dy, 1e-18)
            first, last = st_off[bl], st_off[bl] + st_n[bl] - 1
            if nseg == 1:
                lo[q], hi[q] = bg, bg + 1
                continue
            a = bg - 1 if t < 0.5 else bg
            a = max(first, min(a, last - 2))
            lo[q] = a
            hi[q] = min(last, a + 2)


def assign_points(C: np.ndarray, st_off, st_n, seqs: list, gate: float, nseg: int = 2):
    """Nearest segment of each trajectory point within its lane sequence.

    ``seqs``: list of (points (m, 2), [lanelet indices]). Returns the kept points
    ``Q`` (k, 2), their window ``win_lo``/``win_hi`` (global station indices: the
    nearest segment, with ``nseg=2`` also its neighbour towards the foot point, within
    the lanelet) and lanelet ``q_ll``.
    """
    seqs = [(p, l) for p, l in seqs if len(p) and len(l)]
    if not seqs:
        z = np.zeros(0, np.int64)
        return np.zeros((0, 2)), z, z.copy(), z.copy()
    pts = np.ascontiguousarray(np.concatenate([p for p, _ in seqs]), dtype=float)
    tptr = np.concatenate([[0], np.cumsum([len(p) for p, _ in seqs])]).astype(np.int64)
    lptr = np.concatenate([[0], np.cumsum([len(l) for _, l in seqs])]).astype(np.int64)
    lanes = np.array([x for _, l in seqs for x in l], np.int64)
    n = len(pts)
    lo, hi, ll = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64)
    keep = np.zeros(n, np.bool_)
    _assign_nb(np.ascontiguousarray(C), np.asarray(st_off, np.int64), np.asarray(st_n, np.int64),
               tptr, pts, lptr, lanes, gate * gate, nseg, lo, hi, ll, keep)
    return pts[keep], lo[keep], hi[keep], ll[keep]
