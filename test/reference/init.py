"""References of the compiled initialisation (:mod:`intersection_estimator.topology.init`):
the numpy code ``irls_center`` and ``lane_guess`` replaced, and the loop the vectorised
histogram smoothing of ``initial_arm_angles`` replaced."""

from __future__ import annotations

import math

import numpy as np

from intersection_estimator.model import wrap_angle
from intersection_estimator.topology.likelihood import ObservationSet


def _wmedian_reference(x, w):
    i = np.argsort(x)
    cw = np.cumsum(w[i])
    return float(x[i][np.searchsorted(cw, 0.5 * cw[-1])])


def initial_center_reference(p, o, w, scale=6.0, iters=30):
    """The numpy IRLS the compiled ``irls_center`` replaced."""
    if len(p) == 0:
        return None
    c0 = np.array([_wmedian_reference(p[:, 0], w), _wmedian_reference(p[:, 1], w)])
    nx, ny = -o[:, 1], o[:, 0]
    d = nx * p[:, 0] + ny * p[:, 1]                 # line i: <n_i, x> = d_i
    outer = np.stack([nx * nx, nx * ny, ny * ny])   # n n^T, upper triangle
    c = c0.copy()
    for _ in range(iters):
        wi = w / (1.0 + ((nx * c[0] + ny * c[1] - d) / scale) ** 2)
        mxx, mxy, myy = outer @ wi
        bx, by = (wi * d) @ np.stack([nx, ny], axis=1)
        lam = 1e-3 * max(mxx + myy, 1e-9)
        M = np.array([[mxx + lam, mxy], [mxy, myy + lam]])
        c_new = np.linalg.solve(M, np.array([bx, by]) + lam * c0)
        if np.hypot(*(c_new - c)) < 1e-3:
            c = c_new
            break
        c = c_new
    return c


def _robust_range_reference(x: np.ndarray, w: np.ndarray, tail: float = 0.03) -> tuple[float, float]:
    """Weighted (tail, 1 - tail) quantiles."""
    i = np.argsort(x)
    x, cw = x[i], np.cumsum(w[i])
    lo = int(np.searchsorted(cw, tail * cw[-1], side='right'))
    hi = int(np.searchsorted(cw, (1.0 - tail) * cw[-1], side='left'))
    return float(x[min(lo, len(x) - 1)]), float(x[min(hi, len(x) - 1)])


def initial_lanes_reference(obs: ObservationSet, center, angles, lane_width: float,
                            max_lanes: int, gap_max: float, traffic_side: int = 1, iters: int = 3,
                            width_range=None):
    """The numpy lane guess the compiled ``lane_guess`` replaced."""
    c = np.asarray(center, float).copy()
    n_arm = len(angles)
    u = np.array([[math.cos(a), math.sin(a)] for a in angles]).reshape(n_arm, 2)
    nrm = np.stack([-u[:, 1], u[:, 0]], axis=1)
    params = [(0.0, 1, 1, lane_width)] * n_arm
    if len(obs) == 0 or n_arm == 0:
        return c, params
    p = obs.xy
    o = np.stack([obs.hx, obs.hy], axis=1)
    for _ in range(iters):
        v = p - c
        s = v @ u.T
        t = v @ nrm.T
        par = np.abs(o @ u.T)
        ok = (s > 8.0) & (np.abs(t) < 25.0) & (~obs.has_o[:, None] | (par > math.cos(math.radians(20))))
        cost = np.where(ok, np.abs(t), np.inf)
        arm = np.argmin(cost, axis=1)
        has = np.isfinite(cost[np.arange(len(p)), arm])
        A = np.zeros((2, 2))
        b = np.zeros(2)
        params = []
        for k in range(n_arm):
            m = has & (arm == k)
            ent = np.where(obs.has_o[m], (o[m] @ u[k]) < 0, obs.d[m] > 0)
            tk = t[m, k] * traffic_side
            wk_ = obs.w[m]
            ti, to = tk[ent], -tk[~ent]
            if len(ti) == 0 or len(to) == 0:
                params.append((0.0, 1, 1, lane_width))
                continue
            lo_i, hi_i = _robust_range_reference(ti, wk_[ent])
            lo_o, hi_o = _robust_range_reference(to, wk_[~ent])
            axis = 0.5 * (lo_i - lo_o) * traffic_side       # lateral offset of the median axis
            inner = 0.5 * (lo_i + lo_o)                      # gap/2 + w/2
            gap = float(np.clip(2.0 * (inner - 0.5 * lane_width), 0.0, gap_max))
            nin = int(np.clip(round((hi_i - lo_i) / lane_width) + 1, 1, max_lanes))
            nout = int(np.clip(round((hi_o - lo_o) / lane_width) + 1, 1, max_lanes))
            wd = lane_width
            if width_range is not None and nin + nout > 2:
                wd = ((hi_i - lo_i) + (hi_o - lo_o)) / (nin + nout - 2)
                wd = float(np.clip(wd, *width_range))
            gap = float(np.clip(2.0 * (inner - 0.5 * wd), 0.0, gap_max))
            params.append((gap, nin, nout, wd))
            wk = float(min(len(ti), len(to)))
            A += wk * np.outer(nrm[k], nrm[k])
            b += wk * nrm[k] * (nrm[k] @ c + axis)
        lam = 1e-3 * max(np.trace(A), 1e-9)
        c = np.linalg.solve(A + lam * np.eye(2), b + lam * c)
    if np.hypot(*(c - center)) > 8.0:      # initial_lanes keeps the center (init.BOX_M)
        if iters > 1:                       # ... and the lanes its first pass read
            params = initial_lanes_reference(obs, center, angles, lane_width, max_lanes, gap_max,
                                             traffic_side, 1, width_range)[1]
        c = np.asarray(center, float).copy()
    return c, params


def initial_arm_angles_reference(p: np.ndarray, o: np.ndarray, w: np.ndarray, center, min_sep: float,
                       max_arms: int, min_dist: float = 10.0, peak_frac: float = 0.12,
                       bin_deg: float = 2.0, smooth_deg: float = 4.0) -> list[float]:
    """The loop of ``np.roll`` and the peak list the vectorised smoothing replaced
    (``init.initial_arm_angles`` at 99ef205, verbatim). Arm angles from a histogram of
    outward driving directions around ``center``.

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
