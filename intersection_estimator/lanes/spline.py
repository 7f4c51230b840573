"""Connectors shaped by the traffic: cubic B-splines fitted to the trajectories (beyond the paper).

The paper starts a connector as a straight lanelet (§III-A); our default starts it as a
circular-arc-like cubic Bezier (``init.arc_bezier``) -- the curve family the Table I
simulator draws its connectors from, so that benchmark cannot see the error of that
shape. Here the shape comes from the vehicles that drove the connection instead, as
Meyer, Walter, Lauer 2020 (arXiv 2007.06904) fit 1-D cubic B-splines to the traffic:

1. every trajectory of the connection is cut between its points closest to the end of
   the entering lanelet ``c0`` and the start of the leaving lanelet ``c1``; each piece
   is smoothed lightly (moving average of ``presmooth`` points) and parametrised by its
   own normalised arc length ``u`` in [0, 1];
2. a planar cubic B-spline ``C(u) = sum_j B_j(u) P_j`` (clamped, ``n_ctrl`` control
   points, about one per ``ctrl_spacing`` metres of chord) is fitted by linear least
   squares to all pieces at once, with a second-difference penalty ``smooth`` on the
   control points; the lanes it joins fix it: ``P_0 = c0``, ``P_1 = c0 + alpha t0``,
   ``P_{n-2} = c1 - beta t1``, ``P_{n-1} = c1`` (end points shared, tangents continuous;
   ``alpha``, ``beta`` and the inner control points are the unknowns); the points'
   parameters are then re-set to their foot points on the curve and the fit repeated;
   the penalty is the traffic's choice among ``smooth_grid`` at every round (Mallows'
   criterion against the positions' noise read from all the scene's vehicles,
   :func:`noise_variance`, or Akaike's when it is unknown; :func:`_fit_nb`): a tight turn
   gets a weak one, a wide turn seen through sensor noise a strong one (beyond the 2020
   paper, which fixes it);
3. the curve is sampled at equal arc length (``spacing``) -- the connector's stations;
4. it replaces the start shape only where it explains the traffic better by more than
   ``traffic_select`` per free parameter (:func:`prefer_fit`; 2 = Akaike's criterion; the
   default 1 asks half of it: the start shape is the Table I simulator's own curve family,
   which Akaike's criterion kept on SUMO's real junctions where the traffic's shape was
   closer to the truth, ``docs/real_junctions.md``).

Too little traffic (fewer than ``min_points`` points in the pieces) or a degenerate fit
returns None and the caller keeps its own start shape.

The fit is compiled (``_basis``, ``_data``, ``_reduce``, ``_fit_nb``, ``_combine``: the B-spline
basis by Cox-de Boor, the normal equations assembled from it, the foot-point search); the scipy
least squares it replaced is kept in ``test/reference/spline.py`` and checked against it.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from .likelihood import window_d2

__all__ = ['connector_pieces', 'fit_connector', 'sample_curve', 'prefer_fit', 'traffic_connector',
           'moving_average', 'second_differences', 'aic_prefers', 'noise_variance']


def moving_average(xy: np.ndarray, n: int, tail: bool = True) -> np.ndarray:
    """Points (m, 2) [m] smoothed by a centred moving average of ``n`` points; the first
    and (``tail``) last ``n // 2``, where the window does not fit, stay as they are
    (``tail=False``: zero-padded there, as the connector pieces always had it)."""
    if n <= 1 or len(xy) < n:
        return np.array(xy, float)
    kern = np.ones(n) / n
    out = np.stack([np.convolve(xy[:, d], kern, mode='same') for d in range(2)], 1)
    h = n // 2
    out[:h] = xy[:h]
    if tail and h:
        out[len(xy) - h:] = xy[len(xy) - h:]
    return out


def second_differences(n: int) -> np.ndarray:
    """(n - 2, n) matrix of second differences of n control points (the smoothness rows
    of the connector fit here and of the approach-lane fit in ``lanes/follow.py``)."""
    D = np.zeros((max(n - 2, 0), n))
    for i in range(n - 2):
        D[i, i:i + 3] = (1.0, -2.0, 1.0)
    return D


def aic_prefers(m: float, rss_start: float, rss_fit: float, n_params: float,
                penalty: float) -> bool:
    """The selection rule of :func:`prefer_fit`: ``m log(RSS_start / RSS_fit) > penalty *
    n_params`` (``penalty = 2``: Akaike's criterion for Gaussian residuals; 0: always)."""
    if penalty <= 0:
        return True
    return m * math.log(max(rss_start, 1e-12) / max(rss_fit, 1e-12)) > penalty * n_params


def connector_pieces(trajs_xy: list[np.ndarray], c0: np.ndarray, c1: np.ndarray,
                     presmooth: int = 5) -> list[np.ndarray]:
    """The part of each trajectory between its points closest to ``c0`` and ``c1``
    (in driving order), lightly smoothed; pieces of fewer than 3 points are dropped."""
    out = []
    for xy in trajs_xy:
        if len(xy) < 3:
            continue
        i0 = int(np.argmin(np.sum((xy - c0) ** 2, axis=1)))
        i1 = int(np.argmin(np.sum((xy - c1) ** 2, axis=1)))
        if i1 - i0 < 2:
            continue
        lo, hi = max(0, i0 - presmooth), min(len(xy), i1 + presmooth + 1)
        seg = moving_average(xy[lo:hi], presmooth, tail=False)
        out.append(seg[i0 - lo:i0 - lo + (i1 - i0) + 1])
    return out


def _params(piece: np.ndarray) -> np.ndarray:
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(piece, axis=0), axis=1))])
    return s / s[-1] if s[-1] > 0 else np.linspace(0.0, 1.0, len(piece))


def fit_connector(pieces: list[np.ndarray], c0, t0, c1, t1, *, ctrl_spacing: float = 4.0,
                  smooth: float = 1.0, min_points: int = 10, iters: int = 3,
                  smooth_grid=(), corr_length: float = 4.0, penalty: float = 2.0,
                  clip: float = 3.0, noise_var: float = 0.0):
    """(control points (n, 2), knots) of the clamped cubic B-spline (module docstring),
    or None. The points' parameters start as their pieces' normalised arc length and
    are then ``iters`` times re-set to their foot points on the fitted curve (the spline
    parameter is not arc length: without this the fit is pulled towards the chord).

    ``smooth_grid`` (beyond the paper): candidate penalties; at every step the one of the
    best information criterion is taken (:func:`_fit_nb`); empty: ``smooth`` alone.
    ``noise_var`` > 0: the positions' noise variance is known (:func:`noise_variance`) and
    the criterion is Mallows' instead of Akaike's."""
    pieces = [p for p in pieces if len(p) >= 3]
    if sum(len(p) for p in pieces) < min_points:
        return None
    c0, c1 = np.asarray(c0, float), np.asarray(c1, float)
    t0 = np.asarray(t0, float) / max(np.linalg.norm(t0), 1e-12)
    t1 = np.asarray(t1, float) / max(np.linalg.norm(t1), 1e-12)
    chord = float(np.linalg.norm(c1 - c0))
    n = int(np.clip(round(chord / ctrl_spacing) + 4, 5, 40))
    knots = np.r_[[0.0] * 3, np.linspace(0.0, 1.0, n - 2), [1.0] * 3]
    Q = np.ascontiguousarray(np.concatenate(pieces), dtype=float)
    u = np.concatenate([_params(p) for p in pieces])
    grid = np.asarray(smooth_grid if len(smooth_grid) else [smooth], float)
    metres = sum(float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1))) for p in pieces)
    ctrl = np.empty((n, 2))
    D = second_differences(n)
    ok = _fit_nb(Q, u, knots, D.T @ D, c0, t0, c1, t1, grid * len(Q) / n, int(iters),
                 max(metres / corr_length, 1.0), float(penalty), float(clip), float(noise_var), ctrl)
    return (ctrl, knots) if ok else None


_FINE = 512           # curve samples of the foot-point search
_COARSE = 8           # every _COARSE-th sample is searched globally, then its neighbours


@njit(cache=True)
def _basis(u, knots, n, vals):
    """Index of the first of the four cubic B-splines nonzero at ``u`` (clamped knots),
    their values in ``vals`` (Cox-de Boor, Piegl & Tiller A2.2)."""
    k = 3
    while k < n - 1 and knots[k + 1] <= u:
        k += 1
    left, right = np.empty(4), np.empty(4)
    vals[0] = 1.0
    for j in range(1, 4):
        left[j] = u - knots[k + 1 - j]
        right[j] = knots[k + j] - u
        saved = 0.0
        for r in range(j):
            den = right[r + 1] + left[j - r]
            tmp = vals[r] / den if den > 0 else 0.0
            vals[r] = saved + right[r + 1] * tmp
            saved = left[j - r] * tmp
        vals[j] = saved
    return k - 3


@njit(cache=True)
def _unknown(j, d, n, t0, t1):
    """Control point ``j``, coordinate ``d`` = const + coef * z[idx] (idx -1: fixed).
    Unknowns: z = [alpha, beta, P_2x, P_2y, ..., P_{n-3}x, P_{n-3}y]."""
    if j == 1:
        return 0, t0[d]
    if j == n - 2:
        return 1, -t1[d]
    if 2 <= j <= n - 3:
        return 2 + 2 * (j - 2) + d, 1.0
    return -1, 0.0


@njit(cache=True)
def _reduce(M, R, c0, c1, t0, t1, out_mat, out_vec):
    """Normal equations in the unknowns ``z`` of a block ``P' M P - 2 P' R`` over the control
    points ``P = A z + b`` (module docstring, step 2; ``b`` the fixed end points):
    ``out_mat = A' M A``, ``out_vec = A' (R - M b)``, per coordinate. Data rows:
    ``M = B'B``, ``R = B'Q``; second differences: ``M = D'D``, ``R = 0``."""
    n = len(M)
    b = np.zeros((2, n))              # the fixed part of the control points, per coordinate
    b[:, 0], b[:, 1], b[:, n - 2], b[:, n - 1] = c0, c0, c1, c1
    out_mat[:], out_vec[:] = 0.0, 0.0
    for d in range(2):
        for j in range(n):
            p, cp = _unknown(j, d, n, t0, t1)
            if p < 0:
                continue
            Mb = 0.0
            for k in range(n):
                Mb += M[j, k] * b[d, k]
            out_vec[p] += cp * (R[j, d] - Mb)
            for k in range(n):
                q, cq = _unknown(k, d, n, t0, t1)
                if q >= 0:
                    out_mat[p, q] += cp * cq * M[j, k]


@njit(cache=True)
def _data(Q, u, knots, w):
    """``B'WB`` and ``B'WQ`` of the cubic B-spline design matrix ``B`` at parameters ``u``
    (clamped to the knots' range), ``W = diag(w)``, for data ``Q`` (m, d): the four nonzero
    basis values of each point accumulated into the banded normal equations, without the
    (m, n) design matrix. The connector fit passes unit weights (its ``u`` in [0, 1]),
    ``lanes/follow.py`` the metres driven per point (its ``u`` the axis distance)."""
    n = len(knots) - 4
    BtB, BtQ = np.zeros((n, n)), np.zeros((n, Q.shape[1]))
    vals = np.empty(4)
    lo, hi = knots[0], knots[-1]
    for i in range(len(Q)):
        f = _basis(min(max(u[i], lo), hi), knots, n, vals)
        for a in range(4):
            wa = w[i] * vals[a]
            for d in range(Q.shape[1]):
                BtQ[f + a, d] += wa * Q[i, d]
            for c in range(4):
                BtB[f + a, f + c] += wa * vals[c]
    return BtB, BtQ


@njit(cache=True)
def _basis_table(knots, us):
    """Per parameter of ``us``: the first nonzero cubic B-spline and the four values."""
    n = len(knots) - 4
    first, vals = np.empty(len(us), np.int64), np.empty((len(us), 4))
    for i in range(len(us)):
        first[i] = _basis(min(max(us[i], 0.0), 1.0), knots, n, vals[i])
    return first, vals


@njit(cache=True)
def _combine(ctrl, first, vals, out):
    """Curve points from a :func:`_basis_table` and control points into ``out``."""
    for i in range(len(first)):
        out[i, 0], out[i, 1] = 0.0, 0.0
        for a in range(4):
            out[i, 0] += vals[i, a] * ctrl[first[i] + a, 0]
            out[i, 1] += vals[i, a] * ctrl[first[i] + a, 1]


@njit(cache=True)
def _controls(z, c0, c1, t0, t1, n, out):
    out[0], out[1], out[n - 2], out[n - 1] = c0, c0, c1, c1
    out[1] += z[0] * t0
    out[n - 2] -= z[1] * t1
    for j in range(2, n - 2):
        out[j, 0], out[j, 1] = z[2 + 2 * (j - 2)], z[3 + 2 * (j - 2)]


@njit(cache=True)
def _feet(Q, curve, u, clip, warm):
    """Foot parameters of the points on the sampled curve into ``u`` (downhill along the
    samples from a global search over every ``_COARSE``-th sample, or with ``warm`` from
    the sample at ``u``: the curve moved little since); returns the sum of squared
    distances clipped at ``clip``."""
    m = len(curve)
    rss = 0.0
    for i in range(len(Q)):
        best, bj = np.inf, 0
        if warm:
            bj = min(max(int(round(u[i] * (m - 1))), 0), m - 1)
            best = (curve[bj, 0] - Q[i, 0]) ** 2 + (curve[bj, 1] - Q[i, 1]) ** 2
        else:
            for j in range(0, m, _COARSE):
                d = (curve[j, 0] - Q[i, 0]) ** 2 + (curve[j, 1] - Q[i, 1]) ** 2
                if d < best:
                    best, bj = d, j
        moved = True
        while moved:
            moved = False
            for j in (bj - 1, bj + 1):
                if 0 <= j < m:
                    d = (curve[j, 0] - Q[i, 0]) ** 2 + (curve[j, 1] - Q[i, 1]) ** 2
                    if d < best:
                        best, bj, moved = d, j, True
        u[i] = bj / (m - 1)
        rss += min(best, clip * clip)
    return rss


@njit(cache=True)
def _fit_nb(Q, u0, knots, DtD, c0, t0, c1, t1, weights, iters, m_eff, penalty, clip, noise_var, out):
    """The fit of :func:`fit_connector` into ``out``; False when no weight gives a valid
    fit (the end handles ``alpha``, ``beta`` must point into the turn).

    Each of the ``iters + 1`` rounds solves the penalised normal equations for every
    weight of ``weights``; with several, the one minimising ``m_eff log RSS + penalty *
    edf`` is kept -- a turn's shape is data, not a curve family: a tight turn at a real
    junction needs a weak penalty, a wide arc seen through 1 m of sensor noise a strong
    one, and which the traffic supports is read from it (Akaike's criterion, ``penalty``
    2, as the selection rules here and in ``lanes/follow.py``). ``RSS``: squared
    distances of the points to the curve, clipped at ``clip``; ``m_eff``: the metres the
    pieces cover / ``corr_length`` (the points of one vehicle are not independent);
    ``edf``: trace of the hat matrix ``(G + w S)^-1 G``. With ``noise_var`` > 0 (the
    positions' noise variance, read from all the scene's trajectories) the score is Mallows'
    ``RSS / noise_var + penalty * edf`` instead: a corner cut costs what it costs against
    the known noise, not against the connector's own few points. The points' parameters are
    then re-set to their foot points on the kept curve."""
    n = len(knots) - 4
    nz = 2 + 2 * (n - 4)
    G, S = np.empty((nz, nz)), np.empty((nz, nz))
    g, s = np.empty(nz), np.empty(nz)
    _reduce(DtD, np.zeros((n, 2)), c0, c1, t0, t1, S, s)    # the penalty: the same every round
    first, fine = _basis_table(knots, np.linspace(0.0, 1.0, _FINE))
    curve = np.empty((_FINE, 2))
    ctrl = np.empty((n, 2))
    u, u_try, u_best = u0.copy(), np.empty(len(Q)), np.empty(len(Q))
    rhs = np.empty((nz, nz + 1))
    ones = np.ones(len(Q))
    for it in range(iters + 1):
        BtB, BtQ = _data(Q, u, knots, ones)
        _reduce(BtB, BtQ, c0, c1, t0, t1, G, g)
        best = np.inf
        for w in weights:
            H = G + w * S
            rhs[:, 0] = g + w * s
            rhs[:, 1:] = G
            try:
                sol = np.linalg.solve(H, rhs)
            except Exception:           # singular: no points near some control point
                continue
            z = sol[:, 0]
            if not np.all(np.isfinite(z)) or z[0] <= 0 or z[1] <= 0:
                continue
            _controls(z, c0, c1, t0, t1, n, ctrl)
            _combine(ctrl, first, fine, curve)
            u_try[:] = u
            rss = _feet(Q, curve, u_try, clip, it > 0)
            score = 0.0
            if len(weights) > 1 and noise_var > 0:
                score = rss / noise_var + penalty * np.trace(sol[:, 1:])
            elif len(weights) > 1:
                score = m_eff * np.log(max(rss, 1e-12)) + penalty * np.trace(sol[:, 1:])
            if score < best:
                best = score
                out[:] = ctrl
                u_best[:] = u_try
        if best == np.inf:
            return False
        u[:] = u_best
    return True


def noise_variance(trajs_xy: list[np.ndarray], min_rows: int = 20) -> float:
    """Variance per coordinate of the positions' noise [m^2], read from all trajectories:
    the second differences ``x_{i+1} - 2 x_i + x_{i-1}`` of white noise of variance ``s2`` have
    variance ``6 s2`` per coordinate, a vehicle's own motion adds centimetres at 10 Hz; so
    their squared lengths are exponential with mean ``12 s2`` and ``s2 = median / (12 ln 2)``
    (robust to the few rows of a manoeuvre or a jump). Noise a tracker smoothed reads
    smaller, and the connectors then follow their traffic more closely. 0 when fewer than
    ``min_rows`` second differences exist. Rows that repeat the previous position (a message
    published twice, two sensors' copies of one object) are dropped first: their zero
    differences would read as no noise."""
    d2 = [xy[2:] - 2.0 * xy[1:-1] + xy[:-2] for xy in map(_moved_rows, trajs_xy) if len(xy) >= 3]
    if not d2 or sum(len(d) for d in d2) < min_rows:
        return 0.0
    q = np.sum(np.concatenate(d2) ** 2, axis=1)
    return float(np.median(q)) / (12.0 * math.log(2.0))


def _moved_rows(xy: np.ndarray) -> np.ndarray:
    """The rows of ``xy`` that differ from the row before them (the first always)."""
    xy = np.asarray(xy, float).reshape(-1, 2)
    return xy[np.r_[True, np.any(np.diff(xy, axis=0) != 0.0, axis=1)]] if len(xy) else xy


def smooth_grid(cfg) -> np.ndarray:
    """Candidate penalties of :func:`fit_connector`: ``traffic_smooth_steps`` values
    spaced evenly in log from ``traffic_smooth_min`` to ``traffic_smooth``; empty (the fixed
    ``traffic_smooth``) when ``traffic_smooth_steps`` < 2."""
    return _grid(cfg.traffic_smooth_min, cfg.traffic_smooth, int(cfg.traffic_smooth_steps))


@functools.lru_cache(maxsize=16)
def _grid(lo: float, hi: float, steps: int) -> np.ndarray:
    if steps < 2 or lo <= 0 or hi <= 0:
        return np.zeros(0)
    out = np.geomspace(lo, hi, steps)
    out.flags.writeable = False
    return out


def sample_curve(ctrl: np.ndarray, knots: np.ndarray, spacing: float, min_st: int):
    """Points and unit tangents at equal arc length along the B-spline."""
    ctrl = np.ascontiguousarray(ctrl, dtype=float)
    fine = np.linspace(0.0, 1.0, 256)
    P = _evaluate(ctrl, knots, fine)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    m = max(min_st, int(round(arc[-1] / spacing)) + 1)
    u = np.interp(np.linspace(0.0, arc[-1], m), arc, fine)
    h = 1e-5                 # tangent by central differences of the parameter (one-sided at the ends)
    T = _evaluate(ctrl, knots, np.minimum(u + h, 1.0)) - _evaluate(ctrl, knots, np.maximum(u - h, 0.0))
    T /= np.maximum(np.linalg.norm(T, axis=1, keepdims=True), 1e-12)
    return _evaluate(ctrl, knots, u), T


def _evaluate(ctrl, knots, us):
    """Points of the clamped cubic B-spline with control points ``ctrl`` at ``us``."""
    out = np.empty((len(us), 2))
    _combine(ctrl, *_basis_table(knots, np.asarray(us, float)), out)
    return out


@njit(cache=True)
def _rss(Q: np.ndarray, line: np.ndarray, clip: float) -> float:
    """Sum of squared distances of ``Q`` to a polyline, each clipped at ``clip``."""
    total = 0.0
    for i in range(len(Q)):
        total += min(window_d2(line, 0, len(line) - 1, Q[i, 0], Q[i, 1]), clip * clip)
    return total


def prefer_fit(pieces, fitted: np.ndarray, start: np.ndarray, n_params: int,
               penalty: float, clip: float = 3.0) -> bool:
    """Does the fitted curve explain the pieces better than the caller's start shape by
    more than ``penalty`` per free parameter (``penalty = 2``: Akaike's criterion,
    ``m log(RSS_start / RSS_fit) > penalty * n_params``)? ``penalty = 0``: always."""
    if penalty <= 0:
        return True
    Q = np.ascontiguousarray(np.concatenate(pieces), dtype=float)
    start, fitted = (np.ascontiguousarray(x, dtype=float) for x in (start, fitted))
    return aic_prefers(len(Q), _rss(Q, start, clip), _rss(Q, fitted, clip), n_params, penalty)


def traffic_connector(E, O, trajs_xy: list[np.ndarray], cfg, start=None, noise_var: float = 0.0):
    """Left/right borders of the connector from lanelet spec ``E`` to ``O`` shaped by
    ``trajs_xy`` (the trajectories that drove it), or None (too little traffic, or --
    given the caller's ``start`` borders -- the fit does not beat them by
    ``traffic_select`` per parameter, :func:`prefer_fit`). Half widths are blended from
    the two end cross sections; end points are the lanes'."""
    if len(E.left) < 2 or len(O.left) < 2:
        return None
    c0, c1 = 0.5 * (E.left[-1] + E.right[-1]), 0.5 * (O.left[0] + O.right[0])
    t0 = c0 - 0.5 * (E.left[-2] + E.right[-2])
    t1 = 0.5 * (O.left[1] + O.right[1]) - c1
    pieces = connector_pieces(trajs_xy, c0, c1, cfg.traffic_presmooth)
    fit = fit_connector(pieces, c0, t0, c1, t1, ctrl_spacing=cfg.traffic_ctrl_spacing,
                        smooth=cfg.traffic_smooth, min_points=cfg.traffic_min_points,
                        smooth_grid=smooth_grid(cfg), corr_length=cfg.follow_corr_length,
                        noise_var=noise_var)
    if fit is None:
        return None
    C, T = sample_curve(*fit, cfg.connector_spacing, cfg.connector_min_stations)
    if start is not None and not prefer_fit(pieces, C, 0.5 * (start[0] + start[1]),
                                            2 * (len(fit[0]) - 4) + 2, cfg.traffic_select):
        return None
    N = np.stack([-T[:, 1], T[:, 0]], axis=1)
    f = np.linspace(0.0, 1.0, len(C))[:, None]
    wl = (1 - f) * np.linalg.norm(E.left[-1] - c0) + f * np.linalg.norm(O.left[0] - c1)
    wr = (1 - f) * np.linalg.norm(E.right[-1] - c0) + f * np.linalg.norm(O.right[0] - c1)
    left, right = C + wl * N, C - wr * N
    left[0], right[0], left[-1], right[-1] = E.left[-1], E.right[-1], O.left[0], O.right[0]
    return left, right
