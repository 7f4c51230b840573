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
   / ``lane_out``, ``init.assign_parts``) give points ``(s, lat)`` between
   ``follow_stop_margin`` beyond the stop line and the far end of the lanelet; their
   residuals ``r = lat - lat_k`` measure how far the traffic is beside the straight
   lane. Each point weighs the metres its vehicle drove around it (capped), so a queue
   standing at the stop line does not outweigh the vehicles that drove the lane;
2. one common lateral shift ``g(s)`` of all lanes of the direction is fitted to the
   residuals of all its lanes: a clamped cubic B-spline in ``s`` (about one control
   point per ``follow_ctrl_spacing`` metres) by penalised weighted linear least squares
   (second-difference penalty ``follow_smooth``, scaled as in the connector fit of
   ``lanes/spline.py``); residuals beyond ``follow_gate`` of a first fit are dropped
   (lane changes, wrong assignments) and the fit repeated. A lane ``lat`` beside a bent
   axis is not ``lat`` beside it in the straight frame, so ``follow_iters`` times the
   residuals are re-measured along the normal of the shifted axis and the fit corrected;
3. model selection: the shift is kept only when it explains the points better than the
   straight lane by more than ``follow_select`` per effective degree of freedom (the
   trace of the smoother's hat matrix; ``spline.aic_prefers``, 2 = Akaike), with
   ``follow_corr_length`` metres of one vehicle's path counted as one observation (its
   points are not independent: counted per point, the rule accepted the vehicles' own
   wobble on straight roads) -- a straight road stays straight;
4. the shifted axis ``R(s) = origin + s u + g(s) n`` is the reference curve of the
   direction; its stations are placed at equal arc length and the lane borders are
   offset along its unit normal ``N`` by their lateral positions, so the lanes keep their
   widths across the bend and stay parallel: a lane without traffic moves with its
   traffic-carrying neighbours;
5. (``follow_per_lane``; default 3) each entering lane with traffic also gets its own
   deviation ``e_k`` from the reference curve (same fit and selection, on its points'
   signed offsets from ``R``; not selected: none), each leaving lane a constant one
   (:func:`select_constant`); a lane without traffic copies the deviation of its nearest
   traffic-carrying neighbour; a border between two lanes takes the mean of theirs.
   Leaving lanes get no shape of their own: their traffic is still settling out of its
   turn, and on the real AV2 clips such deviations (one lane's few vehicles over part of
   the arm, continued along its end slope) cost 26 -> 31 cm;
6. (``follow_reassign``, on) before 4-5, where the direction bends, its trajectory parts
   are re-assigned to its lanes by their offset from ``R`` (:func:`nearest_lanes`):
   §III-A's assignment by the offset from straight rays mixes neighbouring lanes' parts
   on a bend. The new assignment is the trajectories' own
   (``Trajectory.lane_in`` / ``lane_out``), so connectors and the MCMC use it too.

Only the entering/leaving geometry changes (station count, sharing keys and neighbour
pairs stay those of the straight lanes); connectors are built afterwards from the moved
lane ends (``init.lane_specs``), so they still start and end exactly there. Nothing here
knows how the simulators draw their roads: the curve is a generic smoothing spline.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.interpolate import BSpline

from .spline import _data, aic_prefers, moving_average, second_differences

#: Gauss-Newton steps of the foot point on the shifted axis (:func:`_signed_offsets`)
FOOT_STEPS = 2

__all__ = ['OffsetFit', 'fit_offset', 'select_offset', 'select_constant', 'nearest_lanes',
           'driven_lanes', 'with_points', 'arm_shift', 'follow_borders']


class OffsetFit:
    """A smoothing B-spline ``g(s)`` [m] of lateral offset vs axis distance ``s`` [m],
    continued linearly (with its end slopes) beyond ``[lo, hi]``."""

    def __init__(self, spline: BSpline, edf: float, lo: float, hi: float):
        self.spline, self.edf, self.lo, self.hi = spline, edf, lo, hi
        self._d = None            # the derivative and its end slopes, built on first use
        self._ends = None         # (most fits are evaluated inside their range only)

    def _deriv(self) -> BSpline:
        if self._d is None:
            self._d = self.spline.derivative()
            self._ends = (float(self._d(self.lo)), float(self._d(self.hi)))
        return self._d

    def __call__(self, s) -> np.ndarray:
        s = np.asarray(s, float)
        out = self.spline(np.clip(s, self.lo, self.hi))
        if (s < self.lo).any() or (s > self.hi).any():
            self._deriv()
            d_lo, d_hi = self._ends
            out = (out + np.minimum(s - self.lo, 0.0) * d_lo
                   + np.maximum(s - self.hi, 0.0) * d_hi)
        return out

    def plus(self, other: 'OffsetFit') -> 'OffsetFit':
        """``g + other`` (same knots): a correction fitted in the frame of ``g``."""
        return OffsetFit(BSpline(self.spline.t, self.spline.c + other.spline.c, 3),
                         self.edf, self.lo, self.hi)

    def slope(self, s) -> np.ndarray:
        """dg/ds (dimensionless); constant beyond the fitted range."""
        return self._deriv()(np.clip(s, self.lo, self.hi))


@lru_cache(maxsize=64)
def _penalty(n: int) -> np.ndarray:
    """``D'D`` of the second differences of ``n`` coefficients (read-only)."""
    D = second_differences(n)
    out = D.T @ D
    out.flags.writeable = False
    return out


def fit_offset(s: np.ndarray, r: np.ndarray, lo: float, hi: float, ctrl_spacing: float,
               smooth: float, w: np.ndarray | None = None) -> OffsetFit | None:
    """Penalised weighted least-squares cubic B-spline of residuals ``r`` [m] over ``s``
    in ``[lo, hi]`` [m] (module docstring, step 2), or None for too few points. Weights
    ``w`` (default 1) are metres driven per point; the penalty is scaled like the
    connector fit's: ``smooth * sum(w) / n`` on the squared second differences of the
    ``n`` coefficients."""
    if len(s) < 4 or hi - lo < 1e-6:
        return None
    w = np.ones(len(s)) if w is None else np.asarray(w, float)
    n = int(np.clip(round((hi - lo) / ctrl_spacing) + 3, 4, 60))
    knots = np.r_[[lo] * 3, np.linspace(lo, hi, n - 2), [hi] * 3]
    BtB, Btr = _data(np.asarray(r, float).reshape(-1, 1), np.asarray(s, float), knots, w)
    Btr = Btr[:, 0]
    H = BtB + (smooth * w.sum() / n) * _penalty(n) + 1e-9 * np.eye(n)
    coef = np.linalg.solve(H, Btr)
    if not np.all(np.isfinite(coef)):
        return None
    edf = float(np.trace(np.linalg.solve(H, BtB)))
    return OffsetFit(BSpline(knots, coef, 3), edf, lo, hi)


def _gated_fit(s, r, w, lo, hi, cfg):
    """:func:`fit_offset` with one gated re-fit (``follow_gate`` [m]): (fit, kept mask) or
    None for fewer than ``follow_min_points`` points."""
    if len(s) < cfg.follow_min_points:
        return None
    fit = fit_offset(s, r, lo, hi, cfg.follow_ctrl_spacing, cfg.follow_smooth, w)
    if fit is None:
        return None
    keep = np.abs(r - fit(s)) <= cfg.follow_gate
    if keep.sum() < cfg.follow_min_points:
        return None
    fit = fit_offset(s[keep], r[keep], lo, hi, cfg.follow_ctrl_spacing, cfg.follow_smooth,
                     w[keep])
    return None if fit is None else (fit, keep)


def _selected(r0: np.ndarray, r1: np.ndarray, w: np.ndarray, edf: float, cfg) -> bool:
    """Residuals ``r1`` [m] of the fit beat ``r0`` of the straight lane by ``follow_select``
    per effective degree of freedom (``spline.aic_prefers``). Residuals are clipped at
    ``follow_gate`` and weighted by metres driven; the points of one vehicle are not
    independent, so ``follow_corr_length`` metres of driving count as one observation."""
    c = cfg.follow_gate
    rss0 = float(np.sum(w * np.minimum(np.abs(r0), c) ** 2))
    rss1 = float(np.sum(w * np.minimum(np.abs(r1), c) ** 2))
    m = float(w.sum()) / cfg.follow_corr_length
    return aic_prefers(m, rss0, rss1, edf, cfg.follow_select)


def select_offset(s: np.ndarray, r: np.ndarray, lo: float, hi: float, cfg,
                  w: np.ndarray | None = None) -> OffsetFit | None:
    """Gated :func:`fit_offset` of residuals ``r`` [m] over ``s`` [m] (weights ``w``
    [m], default 1), kept only when it beats ``g = 0`` (module docstring, step 3); None
    otherwise or for too few points."""
    w = np.ones(len(s)) if w is None else np.asarray(w, float)
    got = _gated_fit(s, r, w, lo, hi, cfg)
    if got is None:
        return None
    fit, keep = got
    return fit if _selected(r[keep], r[keep] - fit(s[keep]), w[keep], fit.edf, cfg) else None


def _common_shift(frame, lats, lanes, lo, hi, cfg) -> OffsetFit | None:
    """The shift ``g`` of all lanes of a direction (module docstring, steps 1-3): fitted
    to the lateral residuals in the straight frame, then ``follow_iters`` times
    corrected by a fit to the residuals measured along the normal of the shifted axis
    (a lane ``lat`` beside a bent axis is not ``lat`` beside it in the straight frame).
    ``lanes``: per lane (points (m, 2), weights (m,) [m])."""
    lanes = [(P, w, k) for k, (P, w) in enumerate(lanes) if len(P)]
    if not lanes:
        return None
    P_all = np.concatenate([P for P, _, _ in lanes])
    w = np.concatenate([w for _, w, _ in lanes])
    lat = np.concatenate([np.full(len(P), lats[k]) for P, _, k in lanes])
    g, keep, r0 = None, None, None
    for it in range(1 + cfg.follow_iters):
        s_all, off = _signed_offsets(P_all, frame, g, lo, hi)
        r = off - lat
        r0 = r if it == 0 else r0
        got = _gated_fit(s_all, r, w, lo, hi, cfg)
        if got is None:
            return None
        delta, keep = got
        if it == 0 and not _selected(r[keep], r[keep] - delta(s_all[keep]), w[keep],
                                     delta.edf, cfg):
            return None            # the straight lane explains it: no corrections needed
        g = delta if g is None else g.plus(delta)
    res = _signed_offsets(P_all, frame, g, lo, hi)[1] - lat
    return g if _selected(r0[keep], res[keep], w[keep], g.edf, cfg) else None


def _driven(parts, frame, lo: float, hi: float, cfg):
    """(points (m, 2), weights (m,) [m]) of one lane's trajectory parts between
    ``lo + follow_stop_margin`` and ``hi`` along the axis: each point weighs the metres
    its vehicle drove around it (positions smoothed over ``traffic_presmooth`` points,
    at most ``follow_max_weight`` [m]), so a queue standing at the stop line does not
    outweigh the vehicles that drove the lane."""
    P_out, w_out = [], []
    for xy in parts:
        xy = np.asarray(xy, float).reshape(-1, 2)
        if len(xy) < 2:
            continue
        sm = moving_average(xy, cfg.traffic_presmooth)
        step = np.linalg.norm(np.diff(sm, axis=0), axis=1)
        w = 0.5 * (np.r_[step, 0.0] + np.r_[0.0, step])
        s = (xy - frame.origin) @ frame.u
        ok = (s >= lo + cfg.follow_stop_margin) & (s <= hi)
        P_out.append(xy[ok])
        w_out.append(np.minimum(w[ok], cfg.follow_max_weight))
    if not P_out:
        return np.zeros((0, 2)), np.zeros(0)
    return np.concatenate(P_out), np.concatenate(w_out)


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
    the reference curve ``R(s) = origin + s u + g(s) n``, its foot point searched within 20 m
    beyond both ends; with ``g`` None the straight frame's ``(s, lat)``.

    In the straight frame a point is ``(s0, l0)``; its foot point on ``R`` solves
    ``(s0 - s) + (l0 - g(s)) g'(s) = 0``, found by Gauss-Newton steps from ``s0``
    (``FOOT_STEPS``: the offset is flat in the foot point to first order; two steps put it
    within 0.1 mm of the exact one at slopes up to 2), and
    its offset along the unit normal ``N = (n - g' u) / sqrt(1 + g'^2)`` is
    ``((l0 - g) - g' (s0 - s)) / sqrt(1 + g'^2)``."""
    rel = P - frame.origin
    s0, l0 = rel @ frame.u, rel @ frame.n
    if g is None:
        return s0, l0
    s = np.clip(s0, lo - 20.0, hi + 20.0)
    for _ in range(FOOT_STEPS):
        d = g.slope(s)
        s = np.clip(s + ((s0 - s) + (l0 - g(s)) * d) / (1.0 + d * d), lo - 20.0, hi + 20.0)
    d = g.slope(s)
    return s, ((l0 - g(s)) - d * (s0 - s)) / np.sqrt(1.0 + d * d)


def _straight(s) -> np.ndarray:
    """No deviation: the lane's own traffic follows the reference curve."""
    return np.zeros(len(np.atleast_1d(s)))


def select_constant(r: np.ndarray, w: np.ndarray, cfg):
    """A constant offset [m] of a lane from the reference curve: the weighted (metres
    driven) mean of its gated residuals ``r``, kept when it beats none by the selection of
    :func:`_selected` with one degree of freedom; None otherwise."""
    keep = np.abs(r) <= cfg.follow_gate
    if keep.sum() < cfg.follow_min_points or w[keep].sum() <= 0:
        return None
    c = float(np.sum(w[keep] * r[keep]) / w[keep].sum())
    if not _selected(r[keep], r[keep] - c, w[keep], 1.0, cfg):
        return None
    return lambda s: np.full(len(np.atleast_1d(s)), c)


def _lane_deviations(frame, g, lats, lanes, lo, hi, cfg, constant: bool = False):
    """(K, n) deviations ``e_k(s)`` [m] of each lane from the reference curve at axis
    distances ``s``: with ``follow_min_points`` points its own selected fit (``constant``:
    a constant, :func:`select_constant`), or none when the fit is not selected (its
    traffic follows ``R``); with fewer its nearest such neighbour's, else 0 (module
    docstring, step 5). Returns a function of ``s``."""
    fits: list = [None] * len(lats)
    own = [k for k, (P, _) in enumerate(lanes) if len(P) >= cfg.follow_min_points]
    if own:                          # one foot-point search for all lanes' points
        s_all, off_all = _signed_offsets(np.concatenate([lanes[k][0] for k in own]), frame,
                                         g, lo, hi)
        cuts = np.cumsum([len(lanes[k][0]) for k in own])[:-1]
        for k, sk, ok in zip(own, np.split(s_all, cuts), np.split(off_all, cuts)):
            fit = select_constant(ok - lats[k], lanes[k][1], cfg) if constant else \
                select_offset(sk, ok - lats[k], lo, hi, cfg, lanes[k][1])
            fits[k] = _straight if fit is None else fit
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


def nearest_lanes(frame, g: OffsetFit, lats, parts, lo: float, hi: float, cfg) -> np.ndarray:
    """Lane index of each trajectory part by its offset from the shifted axis ``R(s)``
    (-1: no points between ``lo`` and ``hi``). §III-A assigns a part by its mean offset
    from the *straight* lane rays; on a bent approach that mean depends on where along
    the bend the part was seen, and parts of neighbouring lanes mix. Measured along the
    normal of ``R``, the offset of one lane's traffic is the same at every station: each
    part goes to the lane nearest its weighted (metres driven) mean offset."""
    lats = np.asarray(lats, float)
    out = np.full(len(parts), -1, np.int64)
    pts = [_driven([p], frame, lo, hi, cfg) for p in parts]
    n = np.array([len(P) for P, _ in pts])
    if n.sum() == 0:
        return out
    _, off = _signed_offsets(np.concatenate([P for P, _ in pts]), frame, g, lo, hi)
    w = np.concatenate([w for _, w in pts])
    starts = np.r_[0, np.cumsum(n)[:-1]]
    for i in np.flatnonzero(n):
        sl = slice(starts[i], starts[i] + n[i])
        ww = w[sl]
        m = float(np.sum(ww * off[sl]) / ww.sum()) if ww.sum() > 0 else float(off[sl].mean())
        out[i] = int(np.argmin(np.abs(lats - m)))
    return out


def driven_lanes(parts, frame, lo: float, hi: float, cfg) -> list:
    """Per lane ``(points (m, 2), weights (m,) [m])`` of its trajectory parts between ``lo``
    and ``hi`` (:func:`_driven`); ``parts``: per lane a list of parts ((m, 2), time order)."""
    return [_driven(p, frame, lo, hi, cfg) for p in parts]


def with_points(frame, g: OffsetFit | None, lats, lanes, P: np.ndarray, weight: float,
                lo: float, hi: float) -> list:
    """``lanes`` (:func:`driven_lanes`) with the points ``P`` (m, 2) added, each of
    ``weight`` [m], to the lane nearest its offset from the axis shifted by ``g``
    (the straight frame when None): observations of a lane that carry no metres driven,
    such as halted vehicles (``lanes/halts.py``)."""
    lanes = [(np.asarray(Q, float).reshape(-1, 2), np.asarray(w, float)) for Q, w in lanes]
    if not len(P):
        return lanes
    _, off = _signed_offsets(P, frame, g, lo, hi)
    k = np.argmin(np.abs(np.asarray(lats, float)[None, :] - off[:, None]), axis=1)
    for j in np.unique(k):
        Q, w = lanes[j]
        lanes[j] = (np.concatenate([Q, P[k == j]]), np.concatenate([w, np.full((k == j).sum(), weight)]))
    return lanes


def arm_shift(frame, lats, lanes, lo: float, hi: float, cfg) -> OffsetFit | None:
    """The selected common shift ``g(s)`` [m] of the given lanes (module docstring, steps
    1-3), or None (straight). ``lats``: their lateral positions [m] (the lanes of one
    arm direction); ``lanes``: per lane its traffic (:func:`driven_lanes`)."""
    return _common_shift(frame, np.asarray(lats, float), lanes, lo, hi, cfg)


def follow_borders(frame, lats, borders, lo: float, hi: float, n_st: int, lanes, cfg,
                   g: OffsetFit | None, deviation: str | None = 'shape'):
    """Border polylines ``(K + 1, n_st, 2)`` of the ``K`` lanes of one arm direction,
    ordered from ``s = lo`` (stop line) to ``hi`` [m], offset from the axis shifted by
    ``g`` (:func:`arm_shift`) plus each lane's ``deviation``: 'shape' its own deviation,
    'constant' its constant offset, None none; None when that leaves them straight (module
    docstring, steps 4-5).

    ``lats``: (K,) lateral positions of the lane center lines [m]; ``borders``: (K + 1,)
    lateral positions of their borders [m] (``init._border_positions``); ``lanes``: per
    lane its traffic (:func:`driven_lanes`; may be empty)."""
    lats = np.asarray(lats, float)
    dev = None
    if deviation is not None:
        dev = _lane_deviations(frame, g, lats, lanes, lo, hi, cfg,
                               constant=deviation == 'constant')
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
