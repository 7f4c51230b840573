"""Lane-course prior (paper §III-C): P(I_2) = s(I_2)^tau * prod_l N(delta_l; mu_l, sigma_delta).

``delta_l`` is the sum of absolute direction changes along the center line of
lanelet ``l``; for connectors it includes the junctions with the predecessor and
successor lanelet (their neighbouring center points), so a connector that kinks
where it meets its lanes pays for it. The paper leaves the mean of the normal
distribution open; we use ``mu_l`` = the turn the lanelet has to make (``delta_l`` of
its initial shape: 0 for straight lanes, the turn angle for a connector), so every
turn is free and only wiggles on top of it cost. ``s(I_2)`` is the number of shared
(merged) border points; we use ``tau * log(1 + s)`` so that ``s = 0`` stays finite.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ['station_angle', 'all_angles', 'log_prior', 'angle_csr']


@njit(cache=True)
def station_angle(C, prev_st, next_st, g):
    """|angle between (c_g - c_prev) and (c_next - c_g)|, 0 at open ends."""
    a, b = prev_st[g], next_st[g]
    if a < 0 or b < 0:
        return 0.0
    ux, uy = C[g, 0] - C[a, 0], C[g, 1] - C[a, 1]
    vx, vy = C[b, 0] - C[g, 0], C[b, 1] - C[g, 1]
    return abs(math.atan2(ux * vy - uy * vx, ux * vx + uy * vy))


@njit(cache=True)
def all_angles(C, prev_st, next_st, st_ll, ang, delta):
    """Reference recomputation of every station angle and every delta_l."""
    delta[:] = 0.0
    for g in range(len(ang)):
        ang[g] = station_angle(C, prev_st, next_st, g)
        delta[st_ll[g]] += ang[g]


@njit(cache=True)
def log_prior(delta, mu, inv2sd2, tau, n_shared):
    """log s(I2)^tau + sum_l log N(delta_l; mu_l, sigma_delta) (unnormalised)."""
    s = 0.0
    for i in range(len(delta)):
        d = delta[i] - mu[i]
        s -= d * d * inv2sd2
    return s + tau * math.log(1.0 + n_shared)


def angle_csr(prev_st: np.ndarray, next_st: np.ndarray):
    """CSR (ptr, idx): for each station the stations whose angle uses its center."""
    n = len(prev_st)
    h = np.flatnonzero((prev_st >= 0) & (next_st >= 0))
    src = np.concatenate([h, prev_st[h], next_st[h]])
    dst = np.concatenate([h, h, h])
    order = np.argsort(src, kind='stable')
    ptr = np.zeros(n + 1, np.int64)
    ptr[1:] = np.cumsum(np.bincount(src, minlength=n))
    return ptr, dst[order].astype(np.int64)
