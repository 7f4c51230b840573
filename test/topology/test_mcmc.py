"""Annealed Metropolis-Hastings: schedule, determinism, monotone best."""

import math

import numpy as np

from intersection_estimator.topology import TopologyConfig, TopologyEstimator
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.likelihood import full_loglik
from intersection_estimator.topology.mcmc import advance, temperatures
from intersection_estimator.topology.moves import MOVE_NAMES
from intersection_estimator.topology.prior import log_prior
from intersection_estimator.topology.state import MAXA, Chain, pack_state
from reference.likelihood import log_likelihood_reference

from .scenes import easy_intersection, scene

# the paper's chain (straight rays): the arm-axis offset has its own tests (test_arm_offset)
CFG = TopologyConfig(arm_offset_max=0.0, arm_bend_max_deg=0.0)   # the paper's moves
TAB = Tables(CFG)


def test_schedule_is_geometric_then_constant():
    t = temperatures(0, 200, 8.0, 0.5, 100)
    assert math.isclose(t[0], 8.0) and math.isclose(t[100], 0.5)
    assert np.all(np.diff(t[:101]) < 0) and np.all(t[100:] == 0.5)
    assert np.allclose(temperatures(50, 10, 8.0, 0.5, 100), t[50:60])


def _chain(obs, inter):
    S = pack_state(inter)
    C = np.zeros((MAXA, len(obs)))
    ll = float(full_loglik(S, TAB.P, *obs.kernel_args(), C))
    lp = float(log_prior(S, TAB.logPA, TAB.logPn, TAB.arm_const))
    return Chain(S=S, C=C, ll=ll, lp=lp, best_S=S.copy(), best_lpost=ll + lp, step=0,
                 stats=np.zeros(2 * len(MOVE_NAMES), np.int64))


def _obs():
    gt = easy_intersection(3, lanes=((1, 1), (2, 1), (1, 2)))
    est = TopologyEstimator(CFG, seed=0)
    est.set_observations(scene(gt, 'tracked', seed=1))
    return est.observations, gt


def test_same_seed_same_chain_and_best_is_the_best_visited():
    obs, gt = _obs()
    runs = []
    for _ in range(2):
        ch = _chain(obs, gt)
        advance(ch, 3000, temperatures(0, 3000, 4.0, 0.5, 3000), 42, TAB.P, TAB.logPA,
                TAB.logPn, TAB.arm_const, TAB.logqn, TAB.cumqn, obs)
        runs.append(ch)
    a, b = runs
    assert np.array_equal(a.S, b.S) and np.array_equal(a.best_S, b.best_S)
    assert a.best_lpost == b.best_lpost
    assert a.best_lpost >= a.ll + a.lp
    best_ll = log_likelihood_reference(a.best_S, obs, TAB.P)
    best_lp = log_prior(a.best_S, TAB.logPA, TAB.logPn, TAB.arm_const)
    assert abs(a.best_lpost - (best_ll + best_lp)) < 1e-9
    assert a.stats[0::2].sum() == 3000


def test_cold_chain_only_climbs():
    """At a tiny temperature a worse proposal is (practically) never accepted."""
    obs, gt = _obs()
    ch = _chain(obs, gt)
    prev = ch.ll + ch.lp
    for i in range(20):
        advance(ch, 100, np.full(100, 1e-9), i, TAB.P, TAB.logPA, TAB.logPn, TAB.arm_const,
                TAB.logqn, TAB.cumqn, obs)
        cur = ch.ll + ch.lp
        assert cur >= prev - 1e-6   # (up to Hastings factors of births/deaths)
        prev = cur


def test_best_posterior_never_gets_worse_with_more_samples():
    gt = easy_intersection(4, lanes=((2, 1), (1, 1), (1, 2), (1, 1)))
    est = TopologyEstimator(TopologyConfig(recenter_window=0), seed=5)
    est.set_observations(scene(gt, 'raw', seed=3, clutter=50))
    hist = []
    for _ in range(12):
        est.run(n_samples=400)
        hist.append(est.best_log_posterior)
    assert all(b >= a for a, b in zip(hist, hist[1:]))
    assert est.samples_drawn == 4800


def test_hot_chain_accepts_more_than_cold():
    obs, gt = _obs()
    rates = []
    for T in (50.0, 0.2):
        ch = _chain(obs, gt)
        advance(ch, 2000, np.full(2000, T), 7, TAB.P, TAB.logPA, TAB.logPn, TAB.arm_const,
                TAB.logqn, TAB.cumqn, obs)
        rates.append(ch.stats[1::2].sum() / 2000)
    assert rates[0] > 2 * rates[1]
