"""Frozen copy of the topology chain kernel before the support cull (issue 18, branch
``speed5``): :func:`run_chain` with the unculled :func:`arm_column_into` (every observation
per arm move, arms x observations per center shift) and :func:`rescore_arm` (every
observation). The culled kernel of :mod:`intersection_estimator.topology.mcmc` must give
the same numbers bit for bit (``test/topology/test_cull.py``). Work counters are kept so
the call signature is the same; the audit is left out (``audit`` is ignored)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from intersection_estimator.topology.mcmc import (W_ENTRIES, W_LOGS, W_MOVES, W_VISITS,
                                                  state_log_prior)
from intersection_estimator.topology.moves import REMOVE_ARM, SHIFT, propose
from intersection_estimator.topology.state import (ANG, GAP, HDR, NIN, NOUT, P_D2_CUT, P_FLOOR,
                                                   P_LANE_NORM, P_LANE_SUM, P_TRAFFIC, STRIDE,
                                                   WID, arm_origin)


@njit(cache=True, fastmath=True, inline='always')
def arm_frame(i, cx, cy, ux, uy, ts, ox, oy, hx, hy, has_o, dcls, isa):
    """Observation ``i`` relative to an arm through (cx, cy) with direction (ux, uy):
    along-arm ``s``, lateral ``t``, direction ``d`` (+1 entering) and angle energy ``e``.
    With an orientation the direction is arm-local (entering iff <o, u_a> < 0) and
    ``e = 2(1 - |cos|) / sigma^2`` (von Mises ~ angle^2); without, the Doppler class, and
    for an unknown class (0) the side of the median decides."""
    px = ox[i] - cx
    py = oy[i] - cy
    s = px * ux + py * uy
    t = py * ux - px * uy
    e = 0.0
    if has_o[i]:
        c = hx[i] * ux + hy[i] * uy
        d = 1.0 if c < 0.0 else -1.0
        e = isa[i] * 2.0 * (1.0 - abs(c))
    else:
        d = dcls[i]
        if d == 0.0:
            d = 1.0 if t * ts > 0.0 else -1.0
    return s, t, d, e


@njit(cache=True, fastmath=True, inline='always')
def _arm_geometry(S, k, P):
    """Arm ``k`` of state ``S`` for the likelihood: axis start (the center, moved by the
    arm's axis offset), unit direction, half gap, lane counts and width, traffic side,
    lane-count normalisations (entering, leaving)."""
    i0 = HDR + k * STRIDE
    a = S[i0 + ANG]
    nin = S[i0 + NIN]
    nout = S[i0 + NOUT]
    ux = math.cos(a)
    uy = math.sin(a)
    cx, cy = arm_origin(S, k, ux, uy)
    return (cx, cy, ux, uy, 0.5 * S[i0 + GAP], nin, nout, S[i0 + WID],
            P[P_TRAFFIC], nin ** -P[P_LANE_NORM], nout ** -P[P_LANE_NORM])


@njit(cache=True, fastmath=True)
def _arm_column_sum(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, out):
    """:func:`arm_column` with the sum over the lanes of that direction (``P_LANE_SUM``)."""
    cx, cy, ux, uy, hg, nin, nout, w, ts, inv_n_in, inv_n_out = _arm_geometry(S, k, P)
    cut = P[P_D2_CUT]
    for i in range(ox.shape[0]):
        s, t, d, e = arm_frame(i, cx, cy, ux, uy, ts, ox, oy, hx, hy, has_o, dcls, isa)
        if e >= cut:
            out[i] = 0.0
            continue
        nl = nin if d > 0.0 else nout
        q = d * ts * t - hg
        kk = math.floor(q / w)
        if kk < 0.0:
            kk = 0.0
        elif kk > nl - 1.0:
            kk = nl - 1.0
        dl = q - (kk + 0.5) * w
        e0 = e + (isp[i] * s * s if s < 0.0 else 0.0)
        e = e0 + isp[i] * dl * dl
        if e >= cut:
            out[i] = 0.0
            continue
        v = 0.0
        for j in range(int(nl)):
            dj = q - (j + 0.5) * w
            ej = e0 + isp[i] * dj * dj
            if ej < cut:
                v += math.exp(-ej)
        out[i] = v * (inv_n_in if d > 0.0 else inv_n_out)


@njit(cache=True, fastmath=True)
def arm_column_into(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, out, energy):
    """:func:`arm_column` with the caller's scratch ``energy`` (one per observation): no
    allocation, for the sampler's loop. Two passes: the energy of the closest lane and the
    lane-count normalisation (branch-free, vectorises); the exponential only below the cut."""
    if P[P_LANE_SUM] > 0.0:
        _arm_column_sum(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, out)
        return
    cx, cy, ux, uy, hg, nin, nout, w, ts, inv_n_in, inv_n_out = _arm_geometry(S, k, P)
    n = ox.shape[0]
    for i in range(n):
        px = ox[i] - cx
        py = oy[i] - cy
        s = px * ux + py * uy
        t = py * ux - px * uy
        c = hx[i] * ux + hy[i] * uy
        side = 1.0 if t * ts > 0.0 else -1.0
        dd = dcls[i] if dcls[i] != 0.0 else side
        d = (1.0 if c < 0.0 else -1.0) if has_o[i] else dd
        e = isa[i] * 2.0 * (1.0 - abs(c)) if has_o[i] else 0.0
        nl = nin if d > 0.0 else nout
        q = d * ts * t - hg
        dl = q - (min(max(math.floor(q / w), 0.0), nl - 1.0) + 0.5) * w
        sb = min(s, 0.0)
        energy[i] = e + isp[i] * (sb * sb + dl * dl)
        out[i] = inv_n_in if d > 0.0 else inv_n_out
    cut = P[P_D2_CUT]
    for i in range(n):
        out[i] = out[i] * math.exp(-energy[i]) if energy[i] < cut else 0.0


@njit(cache=True, fastmath=True)
def all_columns_into(S, P, ox, oy, hx, hy, has_o, dcls, isp, isa, C, energy):
    """:func:`all_columns` with the caller's scratch (:func:`arm_column_into`)."""
    for k in range(int(S[2])):
        arm_column_into(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, C[k], energy)


@njit(cache=True, fastmath=True)
def observation_maxima(C, n, wts, floor, M, AM, Lg):
    """Per observation: best density over arms ``M``, its arm ``AM`` (-1: none) and the
    log-likelihood term ``Lg = w log(M + floor)``; returns their sum."""
    ll = 0.0
    for i in range(wts.shape[0]):
        m = 0.0
        am = -1
        for j in range(n):
            if C[j, i] > m:
                m = C[j, i]
                am = j
        M[i] = m
        AM[i] = am
        Lg[i] = wts[i] * math.log(m + floor)
        ll += Lg[i]
    return ll


@njit(cache=True, fastmath=True)
def rescore_arm(C, n, k, col, has_col, wts, floor, M, AM, Lg, idx, nM, nAM, nLg):
    """Log-likelihood change when arm slot ``k`` gets column ``col`` (``has_col``) or is
    removed (not ``has_col``). Only observations whose best arm could change are
    re-scored: those whose best arm is ``k``, or that ``col`` explains better than their
    current best. Changed rows go to ``idx[:count]`` with new values in ``nM, nAM, nLg``.
    Returns (delta, count).
    """
    delta = 0.0
    cnt = 0
    for i in range(wts.shape[0]):
        c = col[i] if has_col else 0.0
        if AM[i] == k:
            m = c
            am = k if has_col and c > 0.0 else -1
            for j in range(n):
                if j != k and C[j, i] > m:
                    m = C[j, i]
                    am = j
        elif c > M[i]:
            m = c
            am = k
        else:
            continue
        if m == M[i] and am == AM[i]:
            continue
        lg = wts[i] * math.log(m + floor)
        idx[cnt] = i
        nM[cnt] = m
        nAM[cnt] = am
        nLg[cnt] = lg
        delta += lg - Lg[i]
        cnt += 1
    return delta, cnt


@njit(cache=True, nogil=True)   # inputs are served meanwhile (node.py)
def run_chain(S, C, ll, lp, best_S, best_lpost, P, logPA, logPn, arm_const, logqn, cumqn,
              ox, oy, hx, hy, has_o, dcls, isp, isa, wts, n_steps, temps, seed, stats,
              work, audit):
    """Metropolis-Hastings with simulated annealing (paper §II, Algorithm 1).

    Mutates ``S`` (chain state), ``C`` (per-arm density columns of ``S``) and
    ``best_S``; ``temps[t]`` is the temperature of step ``t``. The likelihood is
    incremental: a move of one arm recomputes only that arm's column and re-scores only
    the observations whose best arm could change (see :func:`rescore_arm`); a center
    shift recomputes everything. ``stats[kind*2]`` counts proposals, ``stats[kind*2+1]``
    acceptances; ``work`` (:data:`WORK_FIELDS`) counts the likelihood work, with ``audit``
    also its lower bounds (:func:`_audit_move`). Returns (ll, lp, best_lpost); ``ll`` is
    re-summed exactly at the end.

    Length (over 80 lines): the Metropolis-Hastings loop with its incremental bookkeeping;
    the accept branch updates six per-observation arrays in place, which a helper call per
    accepted move would have to pass back.
    """
    np.random.seed(seed)
    S2 = np.empty_like(S)
    nobs = ox.shape[0]
    floor = P[P_FLOOR]
    col = np.empty(nobs)
    C2 = np.empty_like(C)
    M = np.empty(nobs)
    AM = np.empty(nobs, np.int64)
    Lg = np.empty(nobs)
    M2 = np.empty(nobs)
    AM2 = np.empty(nobs, np.int64)
    Lg2 = np.empty(nobs)
    idx = np.empty(nobs, np.int64)
    nM = np.empty(nobs)
    nAM = np.empty(nobs, np.int64)
    nLg = np.empty(nobs)
    energy = np.empty(nobs)       # arm_column_into scratch: no allocation in the loop
    ll = observation_maxima(C, int(S[2]), wts, floor, M, AM, Lg)
    for step in range(n_steps):
        ok, lq, kind, k = propose(S, S2, P, logqn, cumqn)
        stats[2 * kind] += 1
        if not ok:
            continue
        n2 = int(S2[2])
        n = int(S[2])
        cnt = 0
        work[W_MOVES] += 1
        work[W_VISITS] += nobs
        if kind == SHIFT:
            all_columns_into(S2, P, ox, oy, hx, hy, has_o, dcls, isp, isa, C2, energy)
            ll2 = observation_maxima(C2, n2, wts, floor, M2, AM2, Lg2)
            work[W_ENTRIES] += n2 * nobs
            work[W_LOGS] += nobs
        elif kind == REMOVE_ARM:
            d, cnt = rescore_arm(C, n, k, col, False, wts, floor, M, AM, Lg, idx, nM, nAM, nLg)
            ll2 = ll + d
            work[W_LOGS] += cnt
        else:
            arm_column_into(S2, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, col, energy)
            d, cnt = rescore_arm(C, n2, k, col, True, wts, floor, M, AM, Lg, idx, nM, nAM, nLg)
            ll2 = ll + d
            work[W_ENTRIES] += nobs
            work[W_LOGS] += cnt
        lp2 = state_log_prior(S2, P, logPA, logPn, arm_const)
        a = (ll2 + lp2 - ll - lp) / temps[step] + lq
        if a < 0.0 and math.log(np.random.random()) >= a:
            continue
        stats[2 * kind + 1] += 1
        if kind == SHIFT:
            for j in range(n2):
                C[j, :] = C2[j, :]
            M[:] = M2
            AM[:] = AM2
            Lg[:] = Lg2
        else:
            for q in range(cnt):
                i = idx[q]
                M[i] = nM[q]
                AM[i] = nAM[q]
                Lg[i] = nLg[q]
            if kind == REMOVE_ARM:
                if k != n - 1:
                    C[k, :] = C[n - 1, :]
                    for i in range(nobs):
                        if AM[i] == n - 1:
                            AM[i] = k
            else:
                C[k, :] = col
        S[:] = S2
        ll = ll2
        lp = lp2
        if ll + lp > best_lpost:
            best_lpost = ll + lp
            best_S[:] = S
    ll = 0.0
    for i in range(nobs):
        ll += Lg[i]
    return ll, lp, best_lpost

