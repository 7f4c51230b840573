"""Trajectory likelihood of the lane course (paper §III-C, eq. for P(t_i | I_2)).

Every trajectory is assigned to its lane sequence (entering lanelet, connector,
leaving lanelet), so the sum over lanes ``sum_l 1(t_i, l)`` has one term and

    log P(t_i | I_2) = sum_{p in t_i} log N(d_perp(p, M_l); 0, sigma_perp)

with ``M_l`` the center line of the sequence. Each point keeps a window of three
center-line segments around its nearest one (``win_lo``..``win_hi`` stations), so a
move re-scores only the points whose window touches a changed center point.
A small uniform outlier weight makes the term robust: ``log(exp(-d^2/2s^2) + eps)``.
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
    """log of N(d_perp) (unnormalised) mixed with a uniform outlier weight."""
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
    counts = np.zeros(n_stations + 1, np.int64)
    lens = hi - lo + 1
    if len(lo):
        np.add.at(counts, np.concatenate([np.arange(a, b + 1) for a, b in zip(lo, hi)]) + 1, 1)
    ptr = np.cumsum(counts)
    idx = np.empty(int(lens.sum()) if len(lo) else 0, np.int64)
    fill = ptr[:-1].copy()
    for q, (a, b) in enumerate(zip(lo, hi)):
        for g in range(a, b + 1):
            idx[fill[g]] = q
            fill[g] += 1
    return ptr, idx


def _seg_dist_matrix(pts: np.ndarray, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    d = B - A
    L2 = np.maximum((d * d).sum(1), 1e-18)
    t = np.clip(((pts[:, None, :] - A[None]) * d[None]).sum(-1) / L2[None], 0.0, 1.0)
    e = pts[:, None, :] - (A[None] + t[..., None] * d[None])
    return (e * e).sum(-1)


def assign_points(C: np.ndarray, st_off, st_n, seqs: list, gate: float):
    """Nearest segment of each trajectory point within its lane sequence.

    ``seqs``: list of (points (m, 2), [lanelet indices]). Returns the kept points
    ``Q`` (k, 2), their window ``win_lo``/``win_hi`` (global station indices, three
    segments around the nearest, clipped to the lanelet) and lanelet ``q_ll``.
    """
    Q, lo, hi, ll = [], [], [], []
    for pts, lanes in seqs:
        segs = [(l, g) for l in lanes for g in range(st_off[l], st_off[l] + st_n[l] - 1)]
        if not segs or not len(pts):
            continue
        gs = np.array([g for _, g in segs])
        D = _seg_dist_matrix(pts, C[gs], C[gs + 1])
        j = np.argmin(D, axis=1)
        ok = D[np.arange(len(pts)), j] <= gate * gate
        for q in np.flatnonzero(ok):
            l, g = segs[j[q]]
            a, b = st_off[l], st_off[l] + st_n[l] - 1
            Q.append(pts[q])
            lo.append(max(a, g - 1))
            hi.append(min(b, g + 2))
            ll.append(l)
    return (np.array(Q, float).reshape(-1, 2), np.array(lo, np.int64), np.array(hi, np.int64),
            np.array(ll, np.int64))
