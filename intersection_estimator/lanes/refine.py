"""Penalised least-squares refinement of the lane course (beyond the paper).

Meyer, Walter, Lauer 2020 (arXiv 2007.06904) refine the MCMC lane course with 1-D
cubic B-splines fitted by non-linear least squares. We solve the same kind of
problem directly on the lanelet graph: the unknowns are the lateral offsets ``x_p``
of all border points along their axes (shared points are one unknown, so shared
borders stay shared); the objective is

    sum_q  w_q (d_perp(q) / sigma)^2                        trajectory points
  + refine_smooth * sum_h |c_prev(h) - 2 c_h + c_next(h) - D0_h|^2  second differences
  + refine_width  * sum_g (width_g - width0_g)^2              lane width

with Huber weights ``w_q`` (iteratively reweighted) and Gauss-Newton iterations that
re-linearise ``d_perp`` at the current center line. The second-difference penalty on
equidistant stations is a discrete cubic smoothing spline.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

__all__ = ['effective_share', 'lanelet_dof', 'nearest_in_window', 'refine_offsets', 'signed_offsets']


def _inner(graph, lane):
    """Border point slots of a lanelet's stations but its first and last (its ends)."""
    st = np.arange(graph.st_off[lane] + 1, graph.st_off[lane] + graph.st_n[lane] - 1)
    return np.concatenate([2 * st, 2 * st + 1])


def nearest_in_window(C, Q, lo, hi):
    """Segment start ``g``, parameter ``t`` and unit normal of each point's nearest segment."""
    best = np.full(len(Q), np.inf)
    bg = lo.copy()
    bt = np.zeros(len(Q))
    for k in range(int((hi - lo).max(initial=0))):
        g = lo + k
        ok = g < hi
        gg = np.where(ok, g, lo)
        a, b = C[gg], C[np.minimum(gg + 1, len(C) - 1)]
        d = b - a
        L2 = np.maximum((d * d).sum(1), 1e-18)
        t = np.clip(((Q - a) * d).sum(1) / L2, 0.0, 1.0)
        e = Q - (a + t[:, None] * d)
        D = (e * e).sum(1)
        better = ok & (D < best)
        best[better], bg[better], bt[better] = D[better], gg[better], t[better]
    d = C[np.minimum(bg + 1, len(C) - 1)] - C[bg]
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    nrm = np.stack([-d[:, 1], d[:, 0]], axis=1)
    return bg, bt, nrm


def signed_offsets(C, Q, lo, hi):
    """Each point's nearest segment ``g`` of the center line ``C`` (within its window), the
    foot's parameter ``t``, the segment's unit normal and the point's signed distance along it."""
    g, t, nrm = nearest_in_window(C, Q, lo, hi)
    proj = (1 - t)[:, None] * C[g] + t[:, None] * C[g + 1]
    return g, t, nrm, ((Q - proj) * nrm).sum(1)


def _rows(n_rows, slots_per_row, coefs, ref, axis, vec, var):
    """COO triplets: row i gets coef * (axis[p] . vec[i]) for each point p of its slots."""
    r, c, v = [], [], []
    for slots, coef in zip(slots_per_row, coefs):
        p = ref[slots]
        val = coef * (axis[p] * vec).sum(1)
        r.append(np.arange(n_rows))
        c.append(var[p])
        v.append(val)
    return np.concatenate(r), np.concatenate(c), np.concatenate(v)


def _difference_rows(blocks, rhs, stations, half_coefs, s, D, ref, axis, var, n_var):
    """Rows s * (finite difference of the centers), both coordinates, linearised."""
    n = len(stations[0])
    for dim in range(2):
        e = np.zeros((n, 2))
        e[:, dim] = 1.0
        slots = [x for st in stations for x in (2 * st, 2 * st + 1)]
        coefs = [c * s for c in half_coefs for _ in range(2)]
        rr, cc, vv = _rows(n, slots, coefs, ref, axis, e, var)
        blocks.append(sp.csr_matrix((vv, (rr, cc)), shape=(n, n_var)))
        rhs.append(-s * D[:, dim])


def lanelet_dof(JQ, A, lanelet_of_row, cols_of: dict) -> dict:
    """Effective degrees of freedom of the fit on each lanelet ``l`` of ``cols_of``, given the
    rest of the course: the trace of the hat matrix over the rows of the lanelet's own points
    when only its variables ``cols_of[l]`` move, ``tr(A_ll^-1 J_l^T J_l)`` (the df of a
    linear smoother, Hastie & Tibshirani 1990 §3.5), at the last linearisation. ``JQ`` the
    point rows of the Jacobian (weights and ``1 / sigma`` in them), ``A`` the normal matrix,
    ``lanelet_of_row`` each point row's lanelet. A connector's inner points given its ends
    are what ``LaneConfig.refine_select`` weighs against the start's shape carried to those ends."""
    out = {}
    order = np.argsort(lanelet_of_row, kind='stable')
    bounds = np.searchsorted(lanelet_of_row[order], [(l, l + 1) for l in cols_of])
    A = A.tocsr()
    for (l, c), (lo, hi) in zip(cols_of.items(), bounds):
        c = np.asarray(c, np.int64)
        if hi <= lo or len(c) == 0:
            out[l] = 0.0
            continue
        J = JQ[order[lo:hi]][:, c].toarray()
        out[l] = float(np.trace(np.linalg.solve(A[c][:, c].toarray(), J.T @ J)))
    return out


def effective_share(r, lanelet) -> float:
    """Share of the points that count as independent residuals, ``(1 - rho) / (1 + rho)``
    (the variance inflation of an AR(1) mean), ``rho`` the lag-1 correlation of the residuals
    ``r`` of consecutive points on the same lanelet (in the points' order, each trajectory's
    run in turn), clipped to [0, 0.99]. A detector's white noise gives ~1 (rho 0.1 on the
    SUMO family's tracked objects, 0 on Table I); a tracker's smoothed output ~0 (rho 0.93 on
    the AV2 tracks, 0.99 on the radar tracker's): each vehicle's path is then one piece of
    evidence, not one per row."""
    r, lanelet = np.asarray(r, float), np.asarray(lanelet)
    same = lanelet[1:] == lanelet[:-1]
    rho = float(np.sum(r[1:][same] * r[:-1][same]) / max(float(np.sum(r * r)), 1e-12))
    rho = min(max(rho, 0.0), 0.99)
    return (1.0 - rho) / (1.0 + rho)


def refine_offsets(graph, Q, lo, hi, width0, *, sigma=1.0, smooth=20.0, smooth_connector=1.0,
                   jerk=0.0, width=1.0, iters=4, huber=2.0, assign=None, d2_ref=None, dof_of=()):
    """Gauss-Newton / IRLS over the lateral point offsets; modifies ``graph.P`` in place.
    Returns :func:`lanelet_dof` of the lanelets ``dof_of`` given their ends (empty: nothing
    computed).

    ``assign``: optional callable returning fresh (Q, lo, hi) after each iteration
    (used by the initialisation, whose connectors move far from their start).
    ``d2_ref``: per-station second differences of a reference shape; the penalty is
    then on the deviation from it (the connectors' arc prior is not pulled straight).
    """
    ref, axis = graph.ref, graph.axis
    used = np.unique(ref)
    var = np.full(len(graph.P), -1, np.int64)
    var[used] = np.arange(len(used))
    n_var = len(used)
    n_st = graph.n_stations()
    if n_var == 0 or n_st == 0:
        return {l: 0.0 for l in dof_of}
    h = np.flatnonzero((graph.prev_st >= 0) & (graph.next_st >= 0))
    a_st, b_st = graph.prev_st[h], graph.next_st[h]
    is_conn = graph.kind_code[graph.st_ll[h]] == 2
    lam = np.where(is_conn, smooth_connector, smooth)
    h3 = h[graph.next_st[b_st] >= 0]                       # third differences a, h, b, bb
    a3, b3 = graph.prev_st[h3], graph.next_st[h3]
    bb3 = graph.next_st[b3]
    g_all = np.arange(n_st)
    dof = {l: 0.0 for l in dof_of}
    for it in range(iters):
        C = graph.centers()
        blocks, rhs = [], []
        if len(Q):
            g, t, nrm, r = signed_offsets(C, Q, lo, hi)
            w = np.where(np.abs(r) <= huber, 1.0, huber / np.maximum(np.abs(r), 1e-12))
            sw = np.sqrt(w) / sigma
            rr, cc, vv = _rows(len(Q), [2 * g, 2 * g + 1, 2 * g + 2, 2 * g + 3],
                               [0.5 * (1 - t) * sw, 0.5 * (1 - t) * sw, 0.5 * t * sw, 0.5 * t * sw],
                               ref, axis, nrm, var)
            blocks.append(sp.csr_matrix((vv, (rr, cc)), shape=(len(Q), n_var)))
            rhs.append(r * sw)
        if len(h) and lam.max() > 0:
            s = np.sqrt(lam)
            D = C[a_st] - 2 * C[h] + C[b_st]
            if d2_ref is not None:
                D = D - d2_ref[h]
            _difference_rows(blocks, rhs, [a_st, h, b_st], [0.5, -1.0, 0.5], s, D, ref, axis,
                             var, n_var)
        if len(h3) and jerk > 0:
            s = np.full(len(h3), np.sqrt(jerk))
            D = -C[a3] + 3 * C[h3] - 3 * C[b3] + C[bb3]
            _difference_rows(blocks, rhs, [a3, h3, b3, bb3], [-0.5, 1.5, -1.5, 0.5], s, D, ref,
                             axis, var, n_var)
        if width > 0:
            s = np.sqrt(width)
            nrm = graph.st_normal
            wd = ((graph.P[ref[2 * g_all]] - graph.P[ref[2 * g_all + 1]]) * nrm).sum(1)
            rr, cc, vv = _rows(n_st, [2 * g_all, 2 * g_all + 1], [s, -s], ref, axis, nrm, var)
            blocks.append(sp.csr_matrix((vv, (rr, cc)), shape=(n_st, n_var)))
            rhs.append(-s * (wd - width0))
        J = sp.vstack(blocks).tocsr()
        b = np.concatenate(rhs)
        A = (J.T @ J + 1e-6 * sp.identity(n_var)).tocsc()
        dx = spsolve(A, J.T @ b)
        if dof_of and it == iters - 1 and len(Q):
            dof = lanelet_dof(J[:len(Q)], A, graph.st_ll[g],
                              {l: np.unique(var[ref[_inner(graph, l)]]) for l in dof_of})
        graph.P[used] += dx[:, None] * axis[used]
        if assign is not None:
            Q, lo, hi = assign()
    return dof
