"""Entering and leaving lanelets shaped by the traffic that drove them (beyond the paper).

The paper initialises every entering/leaving lanelet as a straight lane along its arm
(§III-A) and lets the MCMC (§III-C) bend it only station by station with small border
moves. Real approaches curve (tens of degrees over the observed stretch), arm axes do
not meet in one point and lanes are added before the stop line; a straight start then
sits metres beside the traffic where the road bends, and the sampler, whose smoothness
prior pulls towards the start's own angles, does not recover that. This step extends
§III-A: the start shape of the approach lanes comes from the traffic instead.

Per arm and driving direction (the straight frame ``origin + s u + lat n`` of
``init.ArmFrame``, lanes at lateral positions ``lat_k``):

1. the trajectory parts the lane estimator assigned to lane ``k`` (``Trajectory.lane_in``
   / ``lane_out``) give points ``(s, lat)`` between the stop line and the far end of the
   lanelet; their residuals ``r = lat - lat_k`` measure how far the traffic is beside the
   straight lane;
2. one common lateral shift ``g(s)`` of all lanes of the direction is fitted to the
   residuals of all its lanes: a clamped cubic B-spline in ``s`` (about one control
   point per ``follow_ctrl_spacing`` metres) by penalised linear least squares
   (second-difference penalty ``follow_smooth`` as in the connector fit of
   ``lanes/spline.py``), residuals beyond ``follow_gate`` of a first fit are dropped
   (lane changes, wrong assignments) and the fit repeated;
3. model selection: the shift is kept only when it explains the points better than the
   straight lane by more than ``follow_select`` per effective degree of freedom (the
   trace of the smoother's hat matrix; ``spline.aic_prefers``, 2 = Akaike) -- a straight
   road stays straight;
4. the shifted axis ``R(s) = origin + s u + g(s) n`` is the reference curve of the
   direction; its stations are placed at equal arc length and the lane borders are
   offset along its unit normal ``N`` by their lateral positions, so the lanes keep their
   widths across the bend and stay parallel: a lane without traffic moves with its
   traffic-carrying neighbours;
5. optionally (``follow_per_lane``) each lane with traffic also gets its own deviation
   ``e_k`` from the reference curve (same fit and selection, on its points' signed
   offsets from ``R``); a lane without traffic copies the deviation of its nearest
   traffic-carrying neighbour; a border between two lanes takes the mean of theirs.

Only the entering/leaving geometry changes (station count, sharing keys and neighbour
pairs stay those of the straight lanes); connectors are built afterwards from the moved
lane ends (``init.lane_specs``), so they still start and end exactly there. Nothing here
knows how the simulators draw their roads: the curve is a generic smoothing spline.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import BSpline
from scipy.spatial import cKDTree

from .spline import aic_prefers, second_differences

__all__ = ['OffsetFit', 'fit_offset', 'select_offset', 'follow_borders']


class OffsetFit:
    """A smoothing B-spline ``g(s)`` [m] of lateral offset vs axis distance ``s`` [m]."""

    def __init__(self, spline: BSpline, edf: float, lo: float, hi: float):
        self.spline, self.edf, self.lo, self.hi = spline, edf, lo, hi

    def __call__(self, s) -> np.ndarray:
        return self.spline(np.clip(s, self.lo, self.hi)) + self._extrapolate(s)

    def plus(self, other: 'OffsetFit') -> 'OffsetFit':
        """``g + other`` (same knots): a correction fitted in the frame of ``g``."""
        return OffsetFit(BSpline(self.spline.t, self.spline.c + other.spline.c, 3),
                         self.edf, self.lo, self.hi)

    def slope(self, s) -> np.ndarray:
        """dg/ds (dimensionless); constant beyond the fitted range."""
        return self.spline.derivative()(np.clip(s, self.lo, self.hi))

    def _extrapolate(self, s) -> np.ndarray:
        """Linear continuation beyond ``[lo, hi]`` with the end slopes."""
        s = np.asarray(s, float)
        d = self.spline.derivative()
        below = np.minimum(s - self.lo, 0.0) * d(self.lo)
        above = np.maximum(s - self.hi, 0.0) * d(self.hi)
        return below + above


def fit_offset(s: np.ndarray, r: np.ndarray, lo: float, hi: float, ctrl_spacing: float,
               smooth: float) -> OffsetFit | None:
    """Penalised least-squares cubic B-spline of residuals ``r`` [m] over ``s`` in
    ``[lo, hi]`` [m] (module docstring, step 2), or None for too few points. The
    penalty is scaled like the connector fit's: ``smooth * m / n`` on the squared second
    differences of the ``n`` coefficients (``m`` points)."""
    if len(s) < 4 or hi - lo < 1e-6:
        return None
    n = int(np.clip(round((hi - lo) / ctrl_spacing) + 3, 4, 60))
    knots = np.r_[[lo] * 3, np.linspace(lo, hi, n - 2), [hi] * 3]
    B = BSpline.design_matrix(np.clip(s, lo, hi), knots, 3).toarray()
    W = math.sqrt(smooth * len(s) / n) * second_differences(n)
    H = B.T @ B + W.T @ W + 1e-9 * np.eye(n)
    coef = np.linalg.solve(H, B.T @ r)
    if not np.all(np.isfinite(coef)):
        return None
    edf = float(np.trace(np.linalg.solve(H, B.T @ B)))
    return OffsetFit(BSpline(knots, coef, 3), edf, lo, hi)


def _gated_fit(s, r, lo, hi, cfg):
    """:func:`fit_offset` with one gated re-fit (``follow_gate`` [m]): (fit, kept mask) or
    None for fewer than ``follow_min_points`` points."""
    if len(s) < cfg.follow_min_points:
        return None
    fit = fit_offset(s, r, lo, hi, cfg.follow_ctrl_spacing, cfg.follow_smooth)
    if fit is None:
        return None
    keep = np.abs(r - fit(s)) <= cfg.follow_gate
    if keep.sum() < cfg.follow_min_points:
        return None
    fit = fit_offset(s[keep], r[keep], lo, hi, cfg.follow_ctrl_spacing, cfg.follow_smooth)
    return None if fit is None else (fit, keep)


def _selected(r0: np.ndarray, r1: np.ndarray, edf: float, cfg) -> bool:
    """Residuals ``r1`` [m] of the fit beat ``r0`` of the straight lane by ``follow_select``
    per effective degree of freedom (clipped at ``follow_gate``; ``spline.aic_prefers``)."""
    c = cfg.follow_gate
    rss0 = float(np.sum(np.minimum(np.abs(r0), c) ** 2))
    rss1 = float(np.sum(np.minimum(np.abs(r1), c) ** 2))
    return aic_prefers(len(r0), rss0, rss1, edf, cfg.follow_select)


def select_offset(s: np.ndarray, r: np.ndarray, lo: float, hi: float, cfg) -> OffsetFit | None:
    """Gated :func:`fit_offset` of residuals ``r`` [m] over ``s`` [m], kept only when it
    beats ``g = 0`` (module docstring, step 3); None otherwise or for too few points."""
    got = _gated_fit(s, r, lo, hi, cfg)
    if got is None:
        return None
    fit, keep = got
    return fit if _selected(r[keep], r[keep] - fit(s[keep]), fit.edf, cfg) else None


def _common_shift(frame, lats, per_lane, lo, hi, cfg) -> OffsetFit | None:
    """The shift ``g`` of all lanes of a direction (module docstring, steps 1-3): fitted
    to the lateral residuals in the straight frame, then ``follow_iters`` times
    corrected by a fit to the residuals measured along the normal of the shifted axis
    (a lane ``lat`` beside a bent axis is not ``lat`` beside it in the straight frame)."""
    g, keep, r0 = None, None, None
    for it in range(1 + cfg.follow_iters):
        s_all, r_all = [], []
        for k, P in enumerate(per_lane):
            sk, ok = _signed_offsets(P, frame, g, lo, hi)
            s_all.append(sk)
            r_all.append(ok - lats[k])
        s_all, r_all = np.concatenate(s_all), np.concatenate(r_all)
        if it == 0:
            r0 = r_all
        got = _gated_fit(s_all, r_all, lo, hi, cfg)
        if got is None:
            return None
        delta, keep = got
        g = delta if g is None else g.plus(delta)
    res = _signed_offsets(np.concatenate(per_lane), frame, g, lo, hi)[1] - \
        np.concatenate([np.full(len(P), lats[k]) for k, P in enumerate(per_lane)])
    return g if _selected(r0[keep], res[keep], g.edf, cfg) else None


def _reference(frame, g: OffsetFit | None, lo: float, hi: float, n_st: int):
    """Stations (n_st, 2) at equal arc length along ``R(s) = origin + s u + g(s) n`` from
    ``s = lo`` to ``hi`` [m], their unit left normals and axis distances ``s``."""
    fine = np.linspace(lo, hi, max(64, int((hi - lo) / 0.25) + 1))
    gf = g(fine) if g is not None else np.zeros_like(fine)
    P = frame.origin + np.multiply.outer(fine, frame.u) + np.multiply.outer(gf, frame.n)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    s = np.interp(np.linspace(0.0, arc[-1], n_st), arc, fine)
    gs = g(s) if g is not None else np.zeros_like(s)
    ds = g.slope(s) if g is not None else np.zeros_like(s)
    C = frame.origin + np.multiply.outer(s, frame.u) + np.multiply.outer(gs, frame.n)
    T = frame.u[None, :] + ds[:, None] * frame.n[None, :]
    T /= np.linalg.norm(T, axis=1, keepdims=True)
    return C, np.stack([-T[:, 1], T[:, 0]], axis=1), s


def _signed_offsets(P: np.ndarray, frame, g: OffsetFit | None, lo: float, hi: float):
    """(axis distance of the foot point, signed offset along ``N``) of points ``P`` from
    the reference curve (dense, 0.25 m, extended 20 m beyond both ends); with ``g``
    None the straight frame's ``(s, lat)``."""
    if g is None:
        rel = P - frame.origin
        return rel @ frame.u, rel @ frame.n
    C, N, s = _reference(frame, g, lo - 20.0, hi + 20.0,
                         max(64, int((hi - lo + 40.0) / 0.25) + 1))
    _, i = cKDTree(C).query(P)
    return s[i], np.einsum('ij,ij->i', P - C[i], N[i])


def _lane_deviations(frame, g, lats, points, lo, hi, cfg) -> np.ndarray:
    """(K, n) deviations ``e_k(s)`` [m] of each lane from the reference curve at axis
    distances ``s``: its own selected fit, else its nearest traffic-carrying neighbour's,
    else 0 (module docstring, step 5). Returns a function of ``s``."""
    fits: list = [None] * len(lats)
    for k, P in enumerate(points):
        if len(P):
            sk, ok = _signed_offsets(P, frame, g, lo, hi)
            fits[k] = select_offset(sk, ok - lats[k], lo, hi, cfg)
    have = [k for k, f in enumerate(fits) if f is not None]

    def dev(s):
        out = np.zeros((len(lats), len(s)))
        if not have:
            return out
        for k in range(len(lats)):
            src = min(have, key=lambda j: (abs(j - k), j))
            out[k] = fits[src](s)
        return out
    return dev


def follow_borders(frame, lats, borders, lo: float, hi: float, n_st: int, points, cfg):
    """Border polylines ``(K + 1, n_st, 2)`` of the ``K`` lanes of one arm direction,
    ordered from ``s = lo`` (stop line) to ``hi`` [m], shaped by the traffic, or None when
    the straight lanes explain it (module docstring).

    ``lats``: (K,) lateral positions of the lane center lines [m]; ``borders``: (K + 1,)
    lateral positions of their borders [m] (``init._border_positions``); ``points``: per
    lane the (m_k, 2) points of its assigned trajectory parts (may be empty)."""
    lats = np.asarray(lats, float)
    per_lane = []
    for P in points:
        P = np.asarray(P, float).reshape(-1, 2)
        s = (P - frame.origin) @ frame.u
        per_lane.append(P[(s >= lo) & (s <= hi)])
    g = _common_shift(frame, lats, per_lane, lo, hi, cfg)
    dev = _lane_deviations(frame, g, lats, per_lane, lo, hi, cfg) if cfg.follow_per_lane \
        else None
    if g is None and dev is None:
        return None
    C, N, s = _reference(frame, g, lo, hi, n_st)
    E = _border_deviations(dev(s), len(borders)) if dev is not None \
        else np.zeros((len(borders), n_st))
    if g is None and not np.any(E):
        return None
    b = np.asarray(borders, float)[:, None] + E
    return C[None, :, :] + b[:, :, None] * N[None, :, :]


def _border_deviations(E_lane: np.ndarray, n_borders: int) -> np.ndarray:
    """(K + 1, n) border deviations from lane deviations (K, n): outer borders follow
    their lane, a border between lanes ``k - 1`` and ``k`` takes the mean."""
    out = np.empty((n_borders, E_lane.shape[1]))
    out[0], out[-1] = E_lane[0], E_lane[-1]
    out[1:-1] = 0.5 * (E_lane[:-1] + E_lane[1:])
    return out
