"""Metropolis-Hastings with simulated annealing (paper §II, Algorithm 1; Kirkpatrick 1983).

A proposal ``I'`` from a move (:mod:`.moves`) is accepted with probability
``min(1, [P(I'|Z) / P(I|Z)]^(1/T) * q(I|I') / q(I'|I))``; the temperature follows a
geometric schedule from ``t_start`` to ``t_end`` over ``anneal_samples`` steps and then
stays at ``t_end``. The best (MAP) state seen is kept. The chain loop is compiled
(:func:`run_chain`, incremental likelihood); :class:`Posterior` scores a packed state in
full on one observation set.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .likelihood import (ObservationSet, all_columns_into, arm_column_into, combine,
                         full_loglik)
from .moves import MOVE_NAMES, REMOVE_ARM, SHIFT, propose
from .arm_bend import bend_log_prior
from .arm_offset import offset_log_prior
from .prior import log_prior
from .state import MAXA, NARMS, P_FLOOR, Chain

__all__ = ['temperatures', 'advance', 'acceptance_rates', 'state_log_prior', 'Posterior',
           'run_chain', 'observation_maxima', 'rescore_arm', 'WORK_FIELDS', 'W_MOVES', 'W_ENTRIES',
           'W_VISITS', 'W_LOGS', 'W_MUST_ENTRIES', 'W_MUST_LOGS', 'new_work']

#: Work counters of :func:`run_chain` (int64 vector ``work``, summed over calls; the cost
#: model of :mod:`.cost_model` reads them): likelihood evaluations (valid proposals),
#: per-arm density entries computed, observations visited by the re-scoring, log terms
#: recomputed; with ``audit`` also the lower bounds -- density entries that can be nonzero
#: under the old or the new state (the rest are 0 in both: beyond the cut) and log terms
#: whose value changes (the best density of the observation changed).
WORK_FIELDS = ('moves', 'entries', 'visits', 'logs', 'must_entries', 'must_logs')
W_MOVES, W_ENTRIES, W_VISITS, W_LOGS, W_MUST_ENTRIES, W_MUST_LOGS = range(6)


def new_work() -> np.ndarray:
    """Zeroed work counters (:data:`WORK_FIELDS`)."""
    return np.zeros(len(WORK_FIELDS), np.int64)


def temperatures(k0: int, n: int, t_start: float, t_end: float, anneal_samples: int) -> np.ndarray:
    """Temperatures of steps ``k0 .. k0+n-1`` (geometric, then constant ``t_end``)."""
    k = np.minimum(np.arange(k0, k0 + n, dtype=np.float64), anneal_samples)
    frac = k / max(anneal_samples, 1)
    return t_start * (t_end / t_start) ** frac


def advance(chain: Chain, n: int, temps: np.ndarray, seed: int, P, logPA, logPn, arm_const,
            logqn, cumqn, obs: ObservationSet, work: np.ndarray | None = None,
            audit: bool = False) -> None:
    """Draw ``n`` samples of ``chain`` in place (one compiled call, numba RNG seeded with
    ``seed``); ``work``: counters (:data:`WORK_FIELDS`) to add to, ``audit``: count the lower
    bounds too (no effect on the samples)."""
    work = new_work() if work is None else work
    ll, lp, best = run_chain(chain.S, chain.C, chain.ll, chain.lp, chain.best_S,
                             chain.best_lpost, P, logPA, logPn, arm_const, logqn, cumqn,
                             *obs.kernel_args(), n, temps, seed, chain.stats, work, audit)
    chain.ll, chain.lp, chain.best_lpost = float(ll), float(lp), float(best)
    chain.step += n


def acceptance_rates(stats: np.ndarray) -> dict:
    """Per move: (proposed, accepted)."""
    return {name: (int(stats[2 * i]), int(stats[2 * i + 1]))
            for i, name in enumerate(MOVE_NAMES)}


@njit(cache=True)
def state_log_prior(S, P, logPA, logPn, arm_const):
    """log P(I) of state ``S``: the paper's count and uniform priors (§II-C1,
    :func:`.prior.log_prior`) plus the arm-axis offsets' (:mod:`.arm_offset`; 0 when off)."""
    return log_prior(S, logPA, logPn, arm_const) + offset_log_prior(S, P) + bend_log_prior(S, P)


class Posterior:
    """log P(I|Z) + const of packed states on one observation set (paper §II-C):
    ``tables`` is a :class:`.config.Tables`, ``obs`` an :class:`ObservationSet`."""

    def __init__(self, tables, obs: ObservationSet, work: np.ndarray | None = None,
                 audit: bool = False):
        self.t = tables
        self.obs = obs
        #: work counters of every :meth:`advance` on this posterior (:data:`WORK_FIELDS`)
        self.work = new_work() if work is None else work
        self.audit = audit

    def columns(self) -> np.ndarray:
        """Fresh (zero) per-arm likelihood columns for this observation set."""
        return np.zeros((MAXA, len(self.obs)))

    def loglik(self, S, C=None):
        """(log P(Z|I), columns): ``S`` scored in full, its columns written to ``C``."""
        if C is None:
            C = self.columns()
        ll = float(full_loglik(S, self.t.P, *self.obs.kernel_args(), C))
        return ll, C

    def log_prior(self, S) -> float:
        t = self.t
        return float(state_log_prior(S, t.P, t.logPA, t.logPn, t.arm_const))

    def from_columns(self, S, C) -> float:
        """log P(I|Z) + const of ``S`` whose columns ``C`` are at hand (a refit leaves
        them): no second scoring."""
        ll = float(combine(C, int(S[NARMS]), -1, C[0], False, self.obs.kernel_args()[-1],
                           self.t.P[P_FLOOR]))
        return ll + self.log_prior(S)

    def __call__(self, S) -> float:
        """log P(I|Z) + const of ``S`` (scored in full)."""
        return self.loglik(S)[0] + self.log_prior(S)

    def rescore(self, c: Chain) -> None:
        """Chain ``c``'s current state scored in full (columns remade); its best state
        takes the current one if that scores higher."""
        if c.C.shape[1] != len(self.obs):
            c.C = self.columns()
        c.ll, _ = self.loglik(c.S, c.C)
        c.lp = self.log_prior(c.S)
        if c.ll + c.lp > c.best_lpost:
            c.best_S[:] = c.S
            c.best_lpost = c.ll + c.lp

    def advance(self, c: Chain, n: int, temps: np.ndarray, seed: int, P=None) -> None:
        """:func:`advance` of chain ``c`` on this posterior (``P``: the tables' by default)."""
        t = self.t
        advance(c, n, temps, seed, t.P if P is None else P, t.logPA, t.logPn, t.arm_const,
                t.logqn, t.cumqn, self.obs, self.work, self.audit)


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


@njit(cache=True, fastmath=True)
def nonzero_entries(C, rows, col, has_col):
    """Audit (:data:`W_MUST_ENTRIES`): observations with a nonzero density in any of the
    first ``rows`` rows of ``C`` or in ``col`` (``has_col``) -- the only density entries a
    move can change; the others are 0 before and after (beyond the cut)."""
    cnt = 0
    for i in range(C.shape[1]):
        nz = has_col and col[i] > 0.0
        for j in range(rows):
            nz = nz or C[j, i] > 0.0
        cnt += 1 if nz else 0
    return cnt


@njit(cache=True)
def changed_maxima(M, M2, idx, cnt):
    """Audit (:data:`W_MUST_LOGS`): of the rows ``idx[:cnt]`` (all rows if ``cnt < 0``),
    those whose best density ``M2`` differs from ``M`` -- the log terms that must change."""
    n = 0
    if cnt < 0:
        for i in range(M.shape[0]):
            n += 1 if M2[i] != M[i] else 0
        return n
    for q in range(cnt):
        n += 1 if M2[q] != M[idx[q]] else 0
    return n


@njit(cache=True)
def _audit_move(work, kind, k, n, C, C2, col, M, M2, nM, idx, cnt):
    """Audit counts of one evaluated move (see :data:`WORK_FIELDS`)."""
    if kind == SHIFT:
        for j in range(n):
            work[W_MUST_ENTRIES] += nonzero_entries(C[j:j + 1], 1, C2[j], True)
        work[W_MUST_LOGS] += changed_maxima(M, M2, idx, -1)
        return
    if kind != REMOVE_ARM:
        work[W_MUST_ENTRIES] += nonzero_entries(C[k:k + 1], 1 if k < n else 0, col, True)
    work[W_MUST_LOGS] += changed_maxima(M, nM, idx, cnt)


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
        if audit:
            _audit_move(work, kind, k, n, C, C2, col, M, M2, nM, idx, cnt)
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
