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
   ``alpha``, ``beta`` and the inner control points are the unknowns);
3. the curve is sampled at equal arc length (``spacing``) -- the connector's stations;
4. it replaces the start shape only where it explains the traffic better by more than
   ``traffic_select`` per free parameter (:func:`prefer_fit`; 2 = Akaike's criterion).

Too little traffic (fewer than ``min_points`` points in the pieces) or a degenerate fit
returns None and the caller keeps its own start shape.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import BSpline
from scipy.spatial import cKDTree

__all__ = ['connector_pieces', 'fit_connector', 'sample_curve', 'prefer_fit', 'traffic_connector',
           'moving_average', 'second_differences', 'aic_prefers']


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


def aic_prefers(m: int, rss_start: float, rss_fit: float, n_params: float,
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
                  smooth: float = 1.0, min_points: int = 10, iters: int = 3):
    """(control points (n, 2), knots) of the clamped cubic B-spline (module docstring),
    or None. The points' parameters start as their pieces' normalised arc length and
    are then ``iters`` times re-set to their foot points on the fitted curve (the spline
    parameter is not arc length: without this the fit is pulled towards the chord)."""
    pieces = [p for p in pieces if len(p) >= 3]
    if sum(len(p) for p in pieces) < min_points:
        return None
    c0, c1 = np.asarray(c0, float), np.asarray(c1, float)
    t0 = np.asarray(t0, float) / max(np.linalg.norm(t0), 1e-12)
    t1 = np.asarray(t1, float) / max(np.linalg.norm(t1), 1e-12)
    chord = float(np.linalg.norm(c1 - c0))
    n = int(np.clip(round(chord / ctrl_spacing) + 4, 5, 40))
    knots = np.r_[[0.0] * 3, np.linspace(0.0, 1.0, n - 2), [1.0] * 3]
    u = np.concatenate([_params(p) for p in pieces])
    Q = np.concatenate(pieces)
    fit = None
    for _ in range(iters + 1):
        fit = _solve(Q, u, knots, c0, t0, c1, t1, smooth)
        if fit is None:
            return None
        fine = np.linspace(0.0, 1.0, 512)
        P = BSpline(knots, fit, 3)(fine)
        u = fine[cKDTree(P).query(Q)[1]]
    return fit, knots


def _solve(Q, u, knots, c0, t0, c1, t1, smooth):
    """One linear least-squares fit of the control points for fixed parameters ``u``."""
    n = len(knots) - 4
    B = BSpline.design_matrix(np.clip(u, 0.0, 1.0), knots, 3).toarray()   # (m, n)
    # unknowns z = [alpha, beta, P_2x, P_2y, ..., P_{n-3}x, P_{n-3}y]
    inner = n - 4
    nz = 2 + 2 * inner

    # control points = A z + b (A: (n, 2, nz))
    A = np.zeros((n, 2, nz))
    b = np.zeros((n, 2))
    b[0], b[1], b[n - 2], b[n - 1] = c0, c0, c1, c1
    A[1, :, 0] = t0
    A[n - 2, :, 1] = -t1
    for j in range(inner):
        A[2 + j, 0, 2 + 2 * j] = 1.0
        A[2 + j, 1, 3 + 2 * j] = 1.0
    # data rows: B @ P = Q, both coordinates
    Md = np.einsum('mj,jdz->mdz', B, A).reshape(-1, nz)
    rd = (Q - B @ b).reshape(-1)
    # smoothness rows: second differences of the control points
    D = second_differences(n)
    Ms = math.sqrt(smooth * len(Q) / max(n, 1)) * np.einsum('kj,jdz->kdz', D, A).reshape(-1, nz)
    rs = -math.sqrt(smooth * len(Q) / max(n, 1)) * (D @ b).reshape(-1)
    z, *_ = np.linalg.lstsq(np.vstack([Md, Ms]), np.concatenate([rd, rs]), rcond=None)
    if not np.all(np.isfinite(z)) or z[0] <= 0 or z[1] <= 0:
        return None
    return np.einsum('jdz,z->jd', A, z) + b


def sample_curve(ctrl: np.ndarray, knots: np.ndarray, spacing: float, min_st: int):
    """Points and unit tangents at equal arc length along the B-spline."""
    spl = BSpline(knots, ctrl, 3)
    fine = np.linspace(0.0, 1.0, 256)
    P = spl(fine)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    m = max(min_st, int(round(arc[-1] / spacing)) + 1)
    u = np.interp(np.linspace(0.0, arc[-1], m), arc, fine)
    T = spl.derivative()(u)
    T /= np.maximum(np.linalg.norm(T, axis=1, keepdims=True), 1e-12)
    return spl(u), T


def _rss(Q: np.ndarray, line: np.ndarray, clip: float) -> float:
    """Sum of clipped squared distances of ``Q`` to a polyline (resampled every 0.1 m)."""
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    q = np.linspace(0.0, s[-1], max(2, int(s[-1] / 0.1) + 1))
    dense = np.stack([np.interp(q, s, line[:, 0]), np.interp(q, s, line[:, 1])], axis=1)
    d = cKDTree(dense).query(Q)[0]
    return float(np.sum(np.minimum(d, clip) ** 2))


def prefer_fit(pieces, fitted: np.ndarray, start: np.ndarray, n_params: int,
               penalty: float, clip: float = 3.0) -> bool:
    """Does the fitted curve explain the pieces better than the caller's start shape by
    more than ``penalty`` per free parameter (``penalty = 2``: Akaike's criterion,
    ``m log(RSS_start / RSS_fit) > penalty * n_params``)? ``penalty = 0``: always."""
    if penalty <= 0:
        return True
    Q = np.concatenate(pieces)
    return aic_prefers(len(Q), _rss(Q, start, clip), _rss(Q, fitted, clip), n_params, penalty)


def traffic_connector(E, O, trajs_xy: list[np.ndarray], cfg, start=None):
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
                        smooth=cfg.traffic_smooth, min_points=cfg.traffic_min_points)
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
