"""Cost model (issue 18): the kernel's work counters and its audit against a brute-force
count, move by move; the summary arithmetic. No timing is asserted."""

import numpy as np
from numba import njit

from intersection_estimator.topology import TopologyConfig, TopologyEstimator
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.cost_model import format_cost, plain_prices, summarise
from intersection_estimator.topology.likelihood import full_loglik
from intersection_estimator.topology.mcmc import (W_ENTRIES, W_LOGS, W_MOVES, W_MUST_ENTRIES,
                                                  W_MUST_LOGS, W_VISITS, new_work, run_chain)
from intersection_estimator.topology.moves import MOVE_NAMES, REMOVE_ARM, SHIFT, propose
from intersection_estimator.topology.state import MAXA, pack_state

from .scenes import easy_intersection, scene

CFG = TopologyConfig()
TAB = Tables(CFG)


@njit
def _proposal(S, P, logqn, cumqn, seed):
    """The first proposal of ``run_chain(..., seed=seed)`` from ``S``."""
    np.random.seed(seed)
    S2 = np.empty_like(S)
    ok, _, kind, k = propose(S, S2, P, logqn, cumqn)
    return ok, kind, k, S2


def _columns(S, obs):
    C = np.zeros((MAXA, len(obs)))
    full_loglik(S, TAB.P, *obs.kernel_args(), C)
    return C[:int(S[2])]


def _brute_force(S, S2, kind, k, obs):
    """(entries computed, entries that can change, log terms that change) of one move."""
    C, C2 = _columns(S, obs), _columns(S2, obs)
    nobs = len(obs)
    M = C.max(axis=0)
    M2 = C2.max(axis=0) if len(C2) else np.zeros(nobs)
    logs = int((M != M2).sum())
    if kind == SHIFT:
        return len(C2) * nobs, int(((C > 0) | (C2 > 0)).sum()), logs
    if kind == REMOVE_ARM:
        return 0, 0, logs
    old = C[k] if k < len(C) else np.zeros(nobs)
    return nobs, int(((old > 0) | (C2[k] > 0)).sum()), logs


def test_work_counters_and_audit_match_a_brute_force_count_move_by_move():
    gt = easy_intersection(4, lanes=((1, 1), (2, 1), (1, 2), (1, 1)))
    est = TopologyEstimator(CFG, seed=0)
    est.set_observations(scene(gt, 'raw', seed=3, clutter=30))
    obs = est.observations
    S = pack_state(gt)
    S[0] += 1.0
    kinds = set()
    for seed in range(300):
        C = np.zeros((MAXA, len(obs)))
        ll = float(full_loglik(S, TAB.P, *obs.kernel_args(), C))
        ok, kind, k, S2 = _proposal(S, TAB.P, TAB.logqn, TAB.cumqn, seed)
        work = new_work()
        Sc = S.copy()
        run_chain(Sc, C, ll, 0.0, S.copy(), -np.inf, TAB.P, TAB.logPA, TAB.logPn,
                  TAB.arm_const, TAB.logqn, TAB.cumqn, *obs.kernel_args(), 1, np.ones(1),
                  seed, np.zeros(2 * len(MOVE_NAMES), np.int64), work, True)
        if not ok:
            assert work.sum() == 0
            continue
        kinds.add(int(kind))
        entries, must_entries, must_logs = _brute_force(S, S2, kind, k, obs)
        assert work[W_MOVES] == 1 and work[W_VISITS] == len(obs)
        assert work[W_ENTRIES] == entries
        assert work[W_MUST_ENTRIES] == must_entries
        assert work[W_MUST_LOGS] == must_logs
        assert must_logs <= work[W_LOGS] <= len(obs)
        if np.array_equal(Sc, S2):
            S = Sc                      # accepted: walk on
    assert len(kinds) >= 5


def test_audit_does_not_change_the_samples():
    gt = easy_intersection(3, lanes=((1, 1), (2, 1), (1, 2)))
    dets = scene(gt, 'raw', seed=1, clutter=20)
    runs = []
    for audit in (False, True):
        est = TopologyEstimator(CFG, seed=4, audit=audit)
        est.set_observations(dets)
        est.run(n_samples=1500)
        runs.append(est)
    a, b = runs
    assert np.array_equal(a._best_chain().best_S, b._best_chain().best_S)
    for ph in ('chain', 'descent'):
        assert np.array_equal(a.work[ph][:W_MUST_ENTRIES], b.work[ph][:W_MUST_ENTRIES])
        assert a.work[ph][W_MUST_ENTRIES] == 0 and a.work[ph][W_MUST_LOGS] == 0
    w = b.work['chain']
    assert 0 < w[W_MUST_ENTRIES] <= w[W_ENTRIES] and 0 < w[W_MUST_LOGS] <= w[W_LOGS]
    prices = plain_prices(b._post, b._best_chain().best_S)
    assert prices['ns_per_entry'] > 0 and prices['ns_per_log'] > 0


def _case(ms, entries, logs, must_entries, must_logs):
    work = {'moves': 10, 'entries': entries, 'visits': 100, 'logs': logs,
            'must_entries': must_entries, 'must_logs': must_logs, 'ms': ms}
    return {'observations': 50, 'arms': 3, 'samples': {'chain': 10, 'descent': 10},
            'chain': work, 'descent': work, 'plain': {'ns_per_entry': 2.0, 'ns_per_log': 4.0}}


def test_summary_prices_the_work_with_the_plain_loop():
    s = summarise([_case(0.01, 1000, 500, 250, 125), _case(0.01, 1000, 500, 250, 125), None])
    c = s['chain']
    assert s['cases'] == 2 and c['samples_per_case'] == 10
    assert c['entries_per_sample'] == 100 and c['must_logs_per_sample'] == 12.5
    assert c['ns_per_entry'] == 1e4 / 1000 and c['ns_per_visit'] == 1e4 / 100
    assert abs(c['x_plain'] - 1e4 / (2 * 1000 + 4 * 500)) < 1e-12
    assert abs(c['x_limit'] - 4 * c['x_plain']) < 1e-12
    assert 'x limit' in format_cost(s) and summarise([None]) == {'cases': 0}
