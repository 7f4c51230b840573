"""Arm refit (beyond the paper): one arm's (gap, width, lane counts) jump to the best grid point.

With the arm-axis offset on (:mod:`.arm_offset`, tracked windows) the grid spans the offset
too: each driving direction's lanes start at their own distance from the axis, gap and
offset are the sum and difference of the two (:func:`_search_gap_offset_width`). On the
SUMO family about half of the wrong lane counts had a better-scoring right count that only
fitted with the axis moved sideways, out of reach of one random-walk move.

Single moves (:mod:`.moves`) rarely reach a joint change of lane count and width, so every
``refit_every`` samples, after the polish phase of a new chain, and for every lane
candidate of the descent (:mod:`.descent`) each arm is refitted with center and angles
fixed. :func:`refit_arm` scores each (gap, width) grid point and lane count from a table of
F(x) = log(exp(-x) + floor) (:func:`log_floor_table`, cubic Hermite pieces, 32 per unit,
|error| < 1e-9), where x = energy + ``lane_norm`` log(lanes) is the observation's -log
density under this arm: no exp or log in its inner loop. Observations whose best density
under this arm cannot beat the other arms' (exp(-energy) <= other) are skipped up front.
The table only steers the search: the chosen point is scored exactly and kept only if it
is no worse (monotone in the posterior).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from .arm_offset import offset_arm_log_prior, offset_on
from .likelihood import arm_column, arm_frame, combine
from .mcmc import Posterior
from .state import (ANG, BEND, BENDAT, GAP, HDR, NARMS, NIN, NOUT, OFF, P_BEND_MAX, P_BEND_SCALE,
                    P_D2_CUT, P_FLOOR, P_GAP_MAX, P_OFF_MAX,
                    P_LANE_NORM, P_LANE_SUM, P_MAX_LANES, P_MIN_LANES, P_TRAFFIC, P_W_MAX,
                    STRIDE, WID, Chain, arm_origin)

__all__ = ['LOG_FLOOR_INV_STEP', 'log_floor_table', 'refit_arm', 'refit_bend', 'refit_chain',
           'refit_gap_width', 'refit_lane_steps', 'refit_lane_candidates']


def refit_chain(post: Posterior, c: Chain, sweeps: int) -> None:
    """``sweeps`` rounds of :func:`refit_arm` over every arm of chain ``c``'s current
    state (coordinate ascent, monotone), then ``c`` re-scored in full. No-op without
    observations or with ``sweeps == 0``."""
    if len(post.obs) == 0 or sweeps == 0:
        return
    t = post.t
    for _ in range(sweeps):
        for k in range(int(c.S[NARMS])):
            refit_arm(c.S, k, t.P, t.logPn, *post.obs.kernel_args(), c.C, t.gaps, t.widths,
                      t.log_floor)
        if t.P[P_BEND_MAX] > 0.0:
            for k in range(int(c.S[NARMS])):
                refit_bend(c.S, k, t.P, *post.obs.kernel_args(), c.C, t.bend_grid)
    post.rescore(c)


@njit(cache=True, nogil=True)
def refit_bend(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, wts, C, grid):
    """Arm ``k``'s bend (:mod:`.arm_bend`) jumps to the best ``(bend, place)`` row of
    ``grid`` (:class:`.config.Tables`), the rest of ``S`` fixed: every point scored exactly
    (its column against the other arms' ``C``, plus the bend's Laplace prior), the current
    bend kept unless a point beats it. ``S`` and ``C[k]`` are changed in place. A random
    walk of the angle takes hundreds of accepted steps to reach a 30 deg bend; the grid
    finds it in one pass (like :func:`refit_arm` for the lane counts)."""
    n = int(S[2])
    floor = P[P_FLOOR]
    ib = 1.0 / P[P_BEND_SCALE]
    i0 = HDR + k * STRIDE
    col = np.empty(ox.shape[0])
    best = combine(C, n, -1, C[0], False, wts, floor) - ib * abs(S[i0 + BEND])
    bb, ba = S[i0 + BEND], S[i0 + BENDAT]
    for r in range(grid.shape[0]):
        S[i0 + BEND], S[i0 + BENDAT] = grid[r, 0], grid[r, 1]
        arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, col)
        v = combine(C, n, k, col, True, wts, floor) - ib * abs(grid[r, 0])
        if v > best:
            best, bb, ba = v, grid[r, 0], grid[r, 1]
    S[i0 + BEND] = bb
    S[i0 + BENDAT] = ba
    arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, C[k])


def refit_gap_width(post: Posterior, S: np.ndarray, k: int):
    """Arm ``k`` of ``S`` (changed in place) with gap and width at the best grid point for
    its lane counts; returns ``(S, log posterior)``."""
    t = post.t
    C = post.columns()
    post.loglik(S, C)
    args = post.obs.kernel_args()
    refit_arm(S, k, t.P, t.logPn, *args, C, t.gaps, t.widths, t.log_floor, True)
    # refit_arm left C the columns of the refitted S
    return S, post.from_columns(S, C)


def refit_lane_candidates(post: Posterior, S: np.ndarray, k: int, counts, C=None):
    """:func:`refit_gap_width` of ``S`` with arm ``k``'s lane counts set to each row of
    ``counts`` (entering, leaving), in one grid pass (:func:`refit_lane_steps`); the same
    states and log posteriors. ``C``: the columns of ``S`` if at hand. Returns a list of
    ``(S2, log posterior)``."""
    t = post.t
    counts = np.asarray(counts, np.int64).reshape(-1, 2)
    if C is None:
        _, C = post.loglik(S)
    args = post.obs.kernel_args()
    out_S = np.empty((len(counts), len(S)))
    out_col = np.empty((len(counts), len(post.obs)))
    refit_lane_steps(S, k, counts, t.P, t.logPn, *args, C, t.gaps, t.widths, t.log_floor,
                     out_S, out_col)
    Ck = C.copy()
    out = []
    for c in range(len(counts)):
        Ck[k] = out_col[c]      # scored as refit_gap_width scores it (the same bits)
        out.append((out_S[c].copy(), post.from_columns(out_S[c], Ck)))
    return out


#: Knots per unit of the table of F(x) = log(exp(-x) + floor) that :func:`refit_arm`
#: interpolates (cubic Hermite: |error| < 1e-9, no exp / log in its inner loop).
LOG_FLOOR_INV_STEP = 32.0


@functools.lru_cache(maxsize=16)
def log_floor_table(floor: float, xmax: float) -> np.ndarray:
    """Cubic pieces (rows: knot j, columns: coefficients of u^0..u^3, u in [0, 1)) of
    F(x) = log(exp(-x) + floor) on [0, xmax]: the log-density of an observation at
    energy x plus the clutter floor."""
    h = 1.0 / LOG_FLOOR_INV_STEP
    x = np.arange(int(math.ceil(xmax / h)) + 3) * h
    ex = np.exp(-x)
    f = np.log(ex + floor)
    d = -ex / (ex + floor) * h
    f0, f1, d0, d1 = f[:-1], f[1:], d[:-1], d[1:]
    T = np.stack([f0, d0, 3.0 * (f1 - f0) - 2.0 * d0 - d1, 2.0 * (f0 - f1) + d0 + d1], axis=1)
    T.setflags(write=False)
    return T


#: fastmath without 'nnan' / 'ninf': refit_arm compares with infinite sentinels.
FAST_FINITE = {'nsz', 'arcp', 'contract', 'afn', 'reassoc'}


@njit(cache=True, nogil=True, fastmath=FAST_FINITE, inline='always')
def _relevant(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, wts, C, extra=0.0):
    """The observations arm ``k`` of ``S`` can explain at all (the other arms add a constant
    to every candidate), packed per driving direction (side 0 entering) in
    ``R[side, :, :nrel[side]]``: lateral offset, base energy, 1/(2 sigma^2), weight, the
    other arms' best density o, log(o + floor), the energy cut (beyond it this arm cannot
    beat o: the closest lane's density exp(-e) / n**beta <= exp(-e)) and -log(o).
    ``extra`` widens the lateral reach (the offset search moves the lanes sideways).
    Returns ``(R, nrel)``."""
    n = int(S[2])
    nobs = ox.shape[0]
    i0 = HDR + k * STRIDE
    a = S[i0 + ANG]
    ux = math.cos(a)
    uy = math.sin(a)
    cut = P[P_D2_CUT]
    ts = P[P_TRAFFIC]
    lane_sum = P[P_LANE_SUM] > 0.0
    floor = P[P_FLOOR]
    tl = np.empty(nobs)
    base = np.empty(nobs)
    dd = np.empty(nobs)
    other = np.zeros(nobs)
    ax, ay = arm_origin(S, k, ux, uy)
    at, cb, sb = S[i0 + BENDAT], math.cos(S[i0 + BEND]), math.sin(S[i0 + BEND])
    for i in range(nobs):
        s, t, d, e = arm_frame(i, ax, ay, ux, uy, ts, ox, oy, hx, hy, has_o, dcls, isa,
                               at, cb, sb)
        dd[i] = d
        tl[i] = d * ts * t
        base[i] = e + (isp[i] * s * s if s < 0.0 else 0.0)
        m = 0.0
        for j in range(n):
            if j != k and C[j, i] > m:
                m = C[j, i]
        other[i] = m
    reach = 0.5 * P[P_GAP_MAX] + P[P_MAX_LANES] * P[P_W_MAX] + extra
    R = np.empty((2, 8, nobs))
    nrel = np.zeros(2, np.int64)
    for i in range(nobs):
        ci = cut
        if other[i] > 0.0 and not lane_sum:
            ci = min(cut, -math.log(other[i]))
        if base[i] < ci and abs(tl[i]) < reach + math.sqrt(ci / isp[i]):
            side = 0 if dd[i] > 0.0 else 1
            r = nrel[side]
            R[side, 0, r] = tl[i]
            R[side, 1, r] = base[i]
            R[side, 2, r] = isp[i]
            R[side, 3, r] = wts[i]
            R[side, 4, r] = other[i]
            R[side, 5, r] = math.log(other[i] + floor)
            R[side, 6, r] = ci
            R[side, 7, r] = -math.log(other[i]) if other[i] > 0.0 else np.inf
            nrel[side] += 1
    return R, nrel


@njit(cache=True, nogil=True, fastmath=FAST_FINITE, inline='always')
def _side_scores(R, nrel, side, g, w, n_lo, n_hi, P, logPn, blog, invn, FT, acc):
    """``acc[nl]`` for ``nl`` in ``[n_lo, n_hi]``: log lane prior + the log-likelihood gain
    of one driving direction's observations (``R``, :func:`_relevant`) under arm lanes of
    gap ``g``, width ``w`` and ``nl`` lanes, relative to "no lane of this arm explains it"
    (the same for every candidate, so left out): 0 unless this arm beats the others.
    Each ``acc[nl]`` is the same sum whatever the range around it."""
    cut = P[P_D2_CUT]
    floor = P[P_FLOOR]
    lane_sum = P[P_LANE_SUM] > 0.0
    for nl in range(n_lo, n_hi + 1):
        acc[nl] = logPn[nl]
    Rt = R[side, 0]
    Rb = R[side, 1]
    Ri = R[side, 2]
    Rw = R[side, 3]
    Ro = R[side, 4]
    Rl = R[side, 5]
    Rc = R[side, 6]
    Rx = R[side, 7]
    for r in range(nrel[side]):
        q = Rt[r] - 0.5 * g
        kf = math.floor(q / w)
        if kf < 0.0:
            kf = 0.0
        if not lane_sum:
            # closest lane: kf while it exists, else the outermost one, whose distance
            # grows as lanes are taken away -- count down and stop at the first lane count
            # that leaves it beyond the cut
            last = -1.0
            for nl in range(n_hi, n_lo - 1, -1):
                kk = kf if kf < nl - 1.0 else nl - 1.0
                if kk != last:
                    last = kk
                    dl = q - (kk + 0.5) * w
                    e = Rb[r] + Ri[r] * dl * dl
                    if e >= Rc[r]:
                        break
                # density exp(-x), x = e + beta log(nl): beats o iff x < -log(o); its
                # log-density log(exp(-x) + floor) from the table
                x = e + blog[nl]
                if x < Rx[r]:
                    tj = x * LOG_FLOOR_INV_STEP
                    j = int(tj)
                    u = tj - j
                    f = FT[j, 0] + u * (FT[j, 1] + u * (FT[j, 2] + u * FT[j, 3]))
                    acc[nl] += Rw[r] * (f - Rl[r])
            continue
        # sum over lanes 0..nl-1 (the closest must be within the cut)
        cs = 0.0
        for nl in range(n_lo, n_hi + 1):
            for jl in range(0 if nl == n_lo else nl - 1, nl):   # the new lanes
                dj = q - (jl + 0.5) * w
                ej = Rb[r] + Ri[r] * dj * dj
                if ej < cut:
                    cs += math.exp(-ej)
            kk = kf if kf < nl - 1.0 else nl - 1.0
            dl = q - (kk + 0.5) * w
            if Rb[r] + Ri[r] * dl * dl >= cut:
                continue
            v = cs * invn[nl]
            if v > Ro[r]:
                acc[nl] += Rw[r] * (math.log(v + floor) - Rl[r])


@njit(cache=True, nogil=True, inline='always')
def _count_tables(P, FT):
    """(1/n**beta, beta log n) for lane counts n = 1..max_lanes (index n); checks that the
    log-floor table ``FT`` covers the energies of the search."""
    cut = P[P_D2_CUT]
    beta = P[P_LANE_NORM]
    hi = int(P[P_MAX_LANES])
    if FT.shape[0] < (cut + beta * math.log(hi)) * LOG_FLOOR_INV_STEP + 1.0:
        raise ValueError('refit_arm: log_floor_table too short for P_D2_CUT / lanes')
    invn = np.empty(hi + 1)
    blog = np.empty(hi + 1)
    for nl in range(1, hi + 1):
        invn[nl] = float(nl) ** -beta
        blog[nl] = beta * math.log(float(nl))
    return invn, blog


@njit(cache=True, nogil=True, fastmath=FAST_FINITE, inline='always')
def _keep_if_better(S, k, P, logPn, ox, oy, hx, hy, has_o, dcls, isp, isa, wts, C, col,
                    bg, bw, bi, bo, boff):
    """Arm ``k`` of ``S`` set to (gap ``bg``, width ``bw``, counts ``bi``, ``bo``, axis
    offset ``boff``) if that scores no worse exactly (else left as it was); ``col`` its
    column after. Returns (posterior after, posterior before, log-likelihood after) up to
    the other arms' prior."""
    n = int(S[2])
    floor = P[P_FLOOR]
    i0 = HDR + k * STRIDE
    old = np.empty(STRIDE)
    for q in range(STRIDE):
        old[q] = S[i0 + q]
    arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, col)
    ll_cur = combine(C, n, k, col, True, wts, floor)
    cur = (ll_cur + logPn[int(old[NIN])] + logPn[int(old[NOUT])]
           + offset_arm_log_prior(old[OFF], P))
    S[i0 + GAP] = bg
    S[i0 + WID] = bw
    S[i0 + NIN] = bi
    S[i0 + NOUT] = bo
    S[i0 + OFF] = boff
    arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, col)
    ll_new = combine(C, n, k, col, True, wts, floor)
    new = ll_new + logPn[int(bi)] + logPn[int(bo)] + offset_arm_log_prior(boff, P)
    if new < cur:
        for q in range(STRIDE):
            S[i0 + q] = old[q]
        arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, col)
        return cur, cur, ll_cur
    return new, cur, ll_new


@njit(cache=True, nogil=True, fastmath=FAST_FINITE, inline='always')
def _count_range(S, i0, side, lo, hi, fixed_counts):
    if fixed_counts:
        n = int(S[i0 + NIN]) if side == 0 else int(S[i0 + NOUT])
        return n, n
    return lo, hi


@njit(cache=True, nogil=True, fastmath=FAST_FINITE, inline='always')
def _best_count(acc, n_lo, n_hi, lo):
    """(best score, its lane count) of ``acc[n_lo..n_hi]`` (ties: the fewest lanes; all
    ``-inf``: ``lo``, the smallest count allowed)."""
    sbest = -np.inf
    sn = lo
    for nl in range(n_lo, n_hi + 1):
        if acc[nl] > sbest:
            sbest = acc[nl]
            sn = nl
    return sbest, sn


@njit(cache=True, nogil=True, fastmath=FAST_FINITE)
def _search_gap_width(S, i0, R, nrel, P, logPn, blog, invn, FT, gaps, widths, lo, hi,
                      fixed_counts, acc):
    """Best (gap, width, n_in, n_out) over the grids, the axis offset fixed."""
    ng = gaps.shape[0] + 1
    nw = widths.shape[0] + 1
    best = -np.inf
    bg, bw, bi, bo = S[i0 + GAP], S[i0 + WID], S[i0 + NIN], S[i0 + NOUT]
    for gi in range(ng):
        g = gaps[gi] if gi < ng - 1 else S[i0 + GAP]
        for wi in range(nw):
            w = widths[wi] if wi < nw - 1 else S[i0 + WID]
            tot = 0.0
            ni = no = lo
            for side in range(2):
                n_lo, n_hi = _count_range(S, i0, side, lo, hi, fixed_counts)
                _side_scores(R, nrel, side, g, w, n_lo, n_hi, P, logPn, blog, invn, FT, acc)
                sbest, sn = _best_count(acc, n_lo, n_hi, lo)
                tot += sbest
                if side == 0:
                    ni = sn
                else:
                    no = sn
            if tot > best:
                best, bg, bw, bi, bo = tot, g, w, ni, no
    return bg, bw, bi, bo


@njit(cache=True, nogil=True, fastmath=FAST_FINITE)
def _search_gap_offset_width(S, i0, R, nrel, P, logPn, blog, invn, FT, widths, lo, hi,
                             fixed_counts, acc):
    """Best (gap, width, n_in, n_out, axis offset) over a grid (beyond the paper).

    Given the width, a driving direction's lanes start at ``h = gap / 2 + ts (o - o_c)``
    (entering) or ``gap / 2 - ts (o - o_c)`` (leaving) from the current axis (offset
    ``o_c``): its score depends on its own ``h`` only (:func:`_side_scores` with gap
    ``2 h``). So each side is scored once per ``h`` of a grid, and every pair ``(h_in,
    h_out)`` -- gap ``h_in + h_out`` in ``[0, gap_max]``, offset ``o_c + ts (h_in - h_out) / 2``
    within the bound -- is a sum of two table entries plus the offset's prior. A lane count
    that only fits once the axis moves sideways (an arm beside the center) is found in one
    pass, where the random walk must move offset, gap and count together."""
    ts = P[P_TRAFFIC]
    oc = S[i0 + OFF]
    omax = P[P_OFF_MAX]
    gmax = P[P_GAP_MAX]
    span = omax + abs(oc)
    nh0 = int(math.ceil((0.5 * gmax + 2.0 * span) / _H_STEP)) + 1
    H = np.empty(nh0 + 1)
    for q in range(nh0):
        H[q] = -span + q * _H_STEP
    H[nh0] = 0.5 * S[i0 + GAP]           # the current state is a candidate
    nh = nh0 + 1
    nw = widths.shape[0] + 1
    sc = np.empty((2, nh))
    sn = np.empty((2, nh), np.int64)
    best = -np.inf
    bg, bw, bi, bo, boff = S[i0 + GAP], S[i0 + WID], S[i0 + NIN], S[i0 + NOUT], oc
    for wi in range(nw):
        w = widths[wi] if wi < nw - 1 else S[i0 + WID]
        for side in range(2):
            n_lo, n_hi = _count_range(S, i0, side, lo, hi, fixed_counts)
            for q in range(nh):
                _side_scores(R, nrel, side, 2.0 * H[q], w, n_lo, n_hi, P, logPn, blog, invn,
                             FT, acc)
                sc[side, q], sn[side, q] = _best_count(acc, n_lo, n_hi, lo)
        for a in range(nh):
            for b in range(nh):
                g = H[a] + H[b]
                o = oc + ts * 0.5 * (H[a] - H[b])
                if g < -1e-9 or g > gmax + 1e-9 or abs(o) > omax + 1e-9:
                    continue
                tot = sc[0, a] + sc[1, b] + offset_arm_log_prior(o, P)
                if tot > best:
                    best, bg, bw, bi, bo, boff = tot, max(g, 0.0), w, sn[0, a], sn[1, b], o
    return bg, bw, bi, bo, boff


@njit(cache=True, nogil=True)
def _directions_known(has_o, dcls):
    """Does every observation carry its driving direction (an orientation or a Doppler
    class)? One without takes its side of the median from the axis (:func:`.likelihood.arm_frame`),
    which the offset moves: then the two directions no longer separate."""
    for i in range(has_o.shape[0]):
        if not has_o[i] and dcls[i] == 0.0:
            return False
    return True


#: grid step of a side's lane start in :func:`_search_gap_offset_width` [m]
_H_STEP = 0.5


@njit(cache=True, nogil=True, fastmath=FAST_FINITE)
def refit_arm(S, k, P, logPn, ox, oy, hx, hy, has_o, dcls, isp, isa, wts, C, gaps, widths, FT,
              fixed_counts=False):
    """Best (gap, width, lanes_in, lanes_out) of arm ``k`` with center and angles fixed
    (with ``fixed_counts``: best gap and width for the lane counts in ``S``); with the arm
    axis offset on (:mod:`.arm_offset`) and every observation's direction known (tracked
    windows, where the offset is on by default), the offset too
    (:func:`_search_gap_offset_width`).

    Deterministic coordinate ascent on the posterior (initialisation aid, beyond the
    paper): candidates are the grids ``gaps`` x ``widths`` plus the current values; for
    each, the lane counts per direction are chosen independently (the likelihood of
    entering and leaving observations separates given the other arms' columns,
    :func:`_side_scores`). Writes the best into ``S`` and arm ``k``'s column into ``C``;
    returns the posterior gain, never negative: the choice is scored exactly and kept only
    if it is no worse. The search reads log-densities from ``FT`` (:func:`log_floor_table`),
    the closest lane only; the sum over lanes (``P_LANE_SUM``) takes exact logarithms.
    """
    i0 = HDR + k * STRIDE
    lo = int(P[P_MIN_LANES])
    hi = int(P[P_MAX_LANES])
    invn, blog = _count_tables(P, FT)
    acc = np.empty(hi + 1)
    if offset_on(P) and _directions_known(has_o, dcls):
        R, nrel = _relevant(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, wts, C,
                            P[P_OFF_MAX] + abs(S[i0 + OFF]))
        bg, bw, bi, bo, boff = _search_gap_offset_width(S, i0, R, nrel, P, logPn, blog, invn,
                                                        FT, widths, lo, hi, fixed_counts, acc)
    else:
        R, nrel = _relevant(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, wts, C)
        bg, bw, bi, bo = _search_gap_width(S, i0, R, nrel, P, logPn, blog, invn, FT, gaps,
                                           widths, lo, hi, fixed_counts, acc)
        boff = S[i0 + OFF]
    col = np.empty(ox.shape[0])
    new, cur, _ = _keep_if_better(S, k, P, logPn, ox, oy, hx, hy, has_o, dcls, isp, isa, wts,
                                  C, col, bg, bw, bi, bo, boff)
    C[k, :] = col
    return new - cur


@njit(cache=True, nogil=True, fastmath=FAST_FINITE)
def refit_lane_steps(S, k, counts, P, logPn, ox, oy, hx, hy, has_o, dcls, isp, isa, wts, C,
                     gaps, widths, FT, out_S, out_col):
    """:func:`refit_arm` with fixed counts for many lane counts of arm ``k`` at once: row
    ``c`` of ``out_S`` is ``S`` with arm ``k``'s counts ``counts[c]`` (entering, leaving) and
    its best gap and width, ``out_col[c]`` that arm's column -- the same numbers as one
    ``refit_arm(..., fixed_counts=True)`` per row (each direction's score of a count does
    not depend on the other counts scored with it, :func:`_side_scores`), one grid pass for
    all. ``C``: the columns of ``S`` (arm ``k``'s is not read)."""
    i0 = HDR + k * STRIDE
    lo = int(P[P_MIN_LANES])
    hi = int(P[P_MAX_LANES])
    nc = counts.shape[0]
    invn, blog = _count_tables(P, FT)
    R, nrel = _relevant(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, wts, C)
    acc = np.empty((2, hi + 1))
    n_lo = np.empty(2, np.int64)
    n_hi = np.empty(2, np.int64)
    for side in range(2):
        n_lo[side] = counts[:, side].min()
        n_hi[side] = counts[:, side].max()
    best = np.full(nc, -np.inf)
    choice = np.empty((nc, 4))
    for c in range(nc):
        choice[c, 0] = S[i0 + GAP]
        choice[c, 1] = S[i0 + WID]
        choice[c, 2] = counts[c, 0]
        choice[c, 3] = counts[c, 1]
    ng = gaps.shape[0] + 1
    nw = widths.shape[0] + 1
    for gi in range(ng):
        g = gaps[gi] if gi < ng - 1 else S[i0 + GAP]
        for wi in range(nw):
            w = widths[wi] if wi < nw - 1 else S[i0 + WID]
            for side in range(2):
                _side_scores(R, nrel, side, g, w, n_lo[side], n_hi[side], P, logPn, blog, invn,
                             FT, acc[side])
            for c in range(nc):
                a0 = acc[0, counts[c, 0]]
                a1 = acc[1, counts[c, 1]]
                # as refit_arm: a count whose score is -inf falls back to min_lanes
                tot = (a0 if a0 > -np.inf else -np.inf) + (a1 if a1 > -np.inf else -np.inf)
                if tot > best[c]:
                    best[c] = tot
                    choice[c, 0] = g
                    choice[c, 1] = w
                    choice[c, 2] = counts[c, 0] if a0 > -np.inf else lo
                    choice[c, 3] = counts[c, 1] if a1 > -np.inf else lo
    for c in range(nc):
        out_S[c, :] = S
        out_S[c, i0 + NIN] = counts[c, 0]
        out_S[c, i0 + NOUT] = counts[c, 1]
        _keep_if_better(out_S[c], k, P, logPn, ox, oy, hx, hy, has_o, dcls, isp, isa, wts, C,
                        out_col[c], choice[c, 0], choice[c, 1], choice[c, 2], choice[c, 3],
                        S[i0 + OFF])
