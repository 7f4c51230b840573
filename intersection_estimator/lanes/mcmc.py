"""Metropolis-Hastings with simulated annealing over the lanelet graph (paper §III).

One compiled loop draws ``n`` samples: pick a move (center point, border point or
split/merge of a neighbour pair, ``lanes/moves.py``), re-evaluate only what it
touched -- the center points of the stations that use a changed border point, the
angles of the stations around them (prior, ``lanes/prior.py``) and the trajectory
points whose window contains them (likelihood, ``lanes/likelihood.py``) -- and accept
with ``min(1, exp(dlogP / T))``. The temperature falls geometrically from
``temp_start`` to ``temp_end`` over ``anneal_samples`` (counted over all runs, so
a warm-started chain continues cold). The best state seen (checked every 256
samples) is copied to ``best_*``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .likelihood import point_term, window_d2
from .moves import merge, move_border, move_center, split, undo
from .prior import station_angle

__all__ = ['run_chain', 'NPRM', 'PRM_INV2S2', 'PRM_EPS', 'PRM_INV2SD2', 'PRM_TAU',
           'PRM_WIDTH_MIN', 'PRM_WIDTH_MAX', 'PRM_STEP_CENTER', 'PRM_STEP_BORDER',
           'PRM_SPLIT_MAX', 'PRM_P_CENTER', 'PRM_P_BORDER', 'PRM_P_SWITCH', 'PRM_TEMP_START',
           'PRM_TEMP_END', 'PRM_ANNEAL_SAMPLES']

# Slots of the float parameter vector ``prm`` handed to the compiled loop: one named
# index per value, the convention of the topology's ``P_*`` (topology/state.py).
(PRM_INV2S2, PRM_EPS, PRM_INV2SD2, PRM_TAU, PRM_WIDTH_MIN, PRM_WIDTH_MAX, PRM_STEP_CENTER,
 PRM_STEP_BORDER, PRM_SPLIT_MAX, PRM_P_CENTER, PRM_P_BORDER, PRM_P_SWITCH, PRM_TEMP_START,
 PRM_TEMP_END, PRM_ANNEAL_SAMPLES) = range(15)
NPRM = 15


@njit(cache=True)
def _copy_best(P, ref, merged, bP, bref, bmerged):
    bP[:] = P
    bref[:] = ref
    bmerged[:] = merged


@njit(cache=True, nogil=True)   # inputs are served meanwhile (node.py)
def run_chain(n, k0, seed, prm, P, axis, ref, home, users, nusers, st_normal, st_ll,
              pair_a, pair_b, pair_merged, prev_st, next_st, adep_ptr, adep_idx, ang, delta,
              mu, C, Q, win_lo, win_hi, pdep_ptr, pdep_idx, term, best_P, best_ref, best_merged):
    """Draw ``n`` samples starting at global sample index ``k0``.

    Returns (accepted, log-posterior change of the final state, of the best state)."""
    np.random.seed(seed)
    inv2s2, eps, inv2sd2, tau = prm[PRM_INV2S2], prm[PRM_EPS], prm[PRM_INV2SD2], prm[PRM_TAU]
    wmin, wmax = prm[PRM_WIDTH_MIN], prm[PRM_WIDTH_MAX]
    step_c, step_b, split_max = prm[PRM_STEP_CENTER], prm[PRM_STEP_BORDER], prm[PRM_SPLIT_MAX]
    p_c, p_b, p_sw = prm[PRM_P_CENTER], prm[PRM_P_BORDER], prm[PRM_P_SWITCH]
    T0, T1, n_anneal = prm[PRM_TEMP_START], prm[PRM_TEMP_END], prm[PRM_ANNEAL_SAMPLES]
    n_st, n_slots, n_pairs, n_ll, n_q = len(st_ll), len(ref), len(pair_a), len(delta), len(Q)
    p_tot = p_c + p_b + (p_sw if n_pairs > 0 else 0.0)
    n_shared = 0
    for k in range(n_pairs):
        if pair_merged[k]:
            n_shared += 1
    up_p = np.empty(8, np.int64)
    up_xy = np.empty((8, 2))
    rc_slot = np.empty(4, np.int64)
    rc_old = np.empty(4, np.int64)
    st_list = np.empty(n_st, np.int64)
    st_mark = np.zeros(n_st, np.int64)
    C_old = np.empty((n_st, 2))
    ang_list = np.empty(n_st, np.int64)
    ang_mark = np.zeros(n_st, np.int64)
    ang_old = np.empty(n_st)
    ll_list = np.empty(n_ll, np.int64)
    ll_mark = np.zeros(n_ll, np.int64)
    ll_dd = np.zeros(n_ll)
    q_list = np.empty(n_q, np.int64)
    q_mark = np.zeros(n_q, np.int64)
    q_old = np.empty(n_q)
    cur, best, accepted = 0.0, 0.0, 0
    if n_st == 0 or p_tot <= 0.0:
        return 0, 0.0, 0.0
    for it in range(n):
        frac = min(k0 + it, n_anneal) / n_anneal
        T = T0 * (T1 / T0) ** frac
        u = np.random.random() * p_tot
        n_up, n_rc, pair_k, ds = 0, 0, -1, 0
        if u < p_c:
            n_up = move_center(P, ref, st_normal, np.random.randint(n_st), step_c, up_p, up_xy)
        elif u < p_c + p_b:
            n_up = move_border(P, ref, axis, np.random.randint(n_slots), step_b, up_p, up_xy)
        else:
            pair_k = np.random.randint(n_pairs)
            if pair_merged[pair_k]:
                n_up, n_rc = split(P, ref, home, axis, users, nusers, pair_a[pair_k],
                                   pair_b[pair_k], split_max, up_p, up_xy, rc_slot, rc_old)
                ds = -1
            else:
                n_rc = merge(ref, users, nusers, pair_a[pair_k], pair_b[pair_k], rc_slot, rc_old)
                ds = 1
        stamp = it + 1
        # stations whose center changed
        ns = 0
        for i in range(n_up):
            p = up_p[i]
            for j in range(nusers[p]):
                g = users[p, j] // 2
                if st_mark[g] != stamp:
                    st_mark[g] = stamp
                    st_list[ns] = g
                    ns += 1
        for i in range(n_rc):
            g = rc_slot[i] // 2
            if st_mark[g] != stamp:
                st_mark[g] = stamp
                st_list[ns] = g
                ns += 1
        valid = True
        for i in range(ns):
            g = st_list[i]
            l, r = ref[2 * g], ref[2 * g + 1]
            C_old[i, 0], C_old[i, 1] = C[g, 0], C[g, 1]
            C[g, 0] = 0.5 * (P[l, 0] + P[r, 0])
            C[g, 1] = 0.5 * (P[l, 1] + P[r, 1])
            w = (P[l, 0] - P[r, 0]) * st_normal[g, 0] + (P[l, 1] - P[r, 1]) * st_normal[g, 1]
            if w < wmin or w > wmax:
                valid = False
        if not valid:
            for i in range(ns):
                C[st_list[i], 0], C[st_list[i], 1] = C_old[i, 0], C_old[i, 1]
            undo(P, ref, users, nusers, up_p, up_xy, n_up, rc_slot, rc_old, n_rc)
            continue
        # prior: angles around the changed centers, delta_l per lanelet
        na, nl = 0, 0
        for i in range(ns):
            g = st_list[i]
            for j in range(adep_ptr[g], adep_ptr[g + 1]):
                h = adep_idx[j]
                if ang_mark[h] == stamp:
                    continue
                ang_mark[h] = stamp
                ang_list[na] = h
                ang_old[na] = ang[h]
                a = station_angle(C, prev_st, next_st, h)
                ang[h] = a
                l = st_ll[h]
                if ll_mark[l] != stamp:
                    ll_mark[l] = stamp
                    ll_list[nl] = l
                    ll_dd[l] = 0.0
                    nl += 1
                ll_dd[l] += a - ang_old[na]
                na += 1
        dlp = 0.0
        for i in range(nl):
            l = ll_list[i]
            d0 = delta[l] - mu[l]
            d1 = d0 + ll_dd[l]
            dlp -= (d1 * d1 - d0 * d0) * inv2sd2
        if ds != 0:
            dlp += tau * (math.log(1.0 + n_shared + ds) - math.log(1.0 + n_shared))
        # likelihood: points whose window contains a changed center
        nq = 0
        for i in range(ns):
            g = st_list[i]
            for j in range(pdep_ptr[g], pdep_ptr[g + 1]):
                q = pdep_idx[j]
                if q_mark[q] == stamp:
                    continue
                q_mark[q] = stamp
                q_list[nq] = q
                q_old[nq] = term[q]
                t = point_term(window_d2(C, win_lo[q], win_hi[q], Q[q, 0], Q[q, 1]), inv2s2, eps)
                term[q] = t
                dlp += t - q_old[nq]
                nq += 1
        if dlp >= 0.0 or math.log(np.random.random() + 1e-300) < dlp / T:
            for i in range(nl):
                delta[ll_list[i]] += ll_dd[ll_list[i]]
            if pair_k >= 0:
                pair_merged[pair_k] = not pair_merged[pair_k]
                n_shared += ds
            cur += dlp
            accepted += 1
        else:
            for i in range(ns):
                C[st_list[i], 0], C[st_list[i], 1] = C_old[i, 0], C_old[i, 1]
            for i in range(na):
                ang[ang_list[i]] = ang_old[i]
            for i in range(nq):
                term[q_list[i]] = q_old[i]
            undo(P, ref, users, nusers, up_p, up_xy, n_up, rc_slot, rc_old, n_rc)
        if (it & 255) == 255 and cur > best:
            best = cur
            _copy_best(P, ref, pair_merged, best_P, best_ref, best_merged)
    if cur > best:
        best = cur
        _copy_best(P, ref, pair_merged, best_P, best_ref, best_merged)
    return accepted, cur, best
