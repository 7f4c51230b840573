"""Arm refit (beyond the paper): the grid search equals the reference posterior's best."""

import itertools
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from intersection_estimator.topology import TopologyConfig, TopologyEstimator
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.likelihood import full_loglik
from intersection_estimator.topology.mcmc import Posterior
from intersection_estimator.topology.prior import log_prior
from intersection_estimator.topology.refit import (LOG_FLOOR_INV_STEP, log_floor_table,
                                                   refit_arm, refit_chain, refit_gap_width,
                                                   refit_lane_candidates)
from intersection_estimator.topology.state import (GAP, HDR, MAXA, NIN, NOUT, STRIDE, WID, Chain,
                                                   pack_state)
from reference.likelihood import log_likelihood_reference

from .scenes import EASY, easy_intersection, scene
from .strategies import random_obs, states


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(states(), st.integers(0, 10 ** 6), st.sampled_from([0.0, 0.5]), st.booleans(),
       st.booleans())
def test_refit_arm_finds_the_best_grid_point_of_the_reference_posterior(S, seed, lane_norm,
                                                                        lane_sum, fixed):
    """refit_arm (compiled, relative log-densities) picks the (gap, width, lane counts) of
    arm k that maximise the plain reference posterior over its grid (with ``fixed``: the
    best gap and width for the counts already there)."""
    rng = np.random.default_rng(seed)
    obs = random_obs(rng, 80, center=S[:2], spread=30.0)
    cfg = TopologyConfig(lane_norm=lane_norm, lane_sum=lane_sum, cut_sigma2=700.0)
    tab = Tables(cfg)
    k = int(rng.integers(0, int(S[2])))
    i0 = HDR + k * STRIDE

    def lpost(T):
        return (log_likelihood_reference(T, obs, tab.P)
                + float(log_prior(T, tab.logPA, tab.logPn, tab.arm_const)))

    best = -math.inf
    counts = ([(S[i0 + NIN], S[i0 + NOUT])] if fixed else
              itertools.product(range(cfg.min_lanes, cfg.max_lanes + 1), repeat=2))
    for (ni, no), g, w in itertools.product(list(counts), np.r_[tab.gaps, S[i0 + GAP]],
                                            np.r_[tab.widths, S[i0 + WID]]):
        T = S.copy()
        T[i0 + GAP], T[i0 + WID], T[i0 + NIN], T[i0 + NOUT] = g, w, ni, no
        best = max(best, lpost(T))
    R = S.copy()
    C = np.zeros((MAXA, len(obs)))
    full_loglik(R, tab.P, *obs.kernel_args(), C)
    refit_arm(R, k, tab.P, tab.logPn, *obs.kernel_args(), C, tab.gaps, tab.widths,
                tab.log_floor, fixed)
    assert lpost(R) == pytest.approx(best, abs=1e-6)
    if fixed:
        assert (R[i0 + NIN], R[i0 + NOUT]) == (S[i0 + NIN], S[i0 + NOUT])


@pytest.mark.parametrize('floor', [0.01, 0.2])
def test_log_floor_table_interpolates_log_density_to_1e9(floor):
    """refit_arm's table of log(exp(-x) + floor): cubic pieces within 1e-9 everywhere."""
    T = log_floor_table(floor, 40.0)
    x = np.r_[np.random.default_rng(0).uniform(0.0, 40.0, 200_000), 0.0, 40.0]
    j = (x * LOG_FLOOR_INV_STEP).astype(int)
    u = x * LOG_FLOOR_INV_STEP - j
    f = T[j, 0] + u * (T[j, 1] + u * (T[j, 2] + u * T[j, 3]))
    np.testing.assert_allclose(f, np.log(np.exp(-x) + floor), rtol=0, atol=1e-9)


def test_refit_arm_refuses_a_table_too_short_for_the_cut():
    tab = Tables(TopologyConfig())
    S = pack_state(easy_intersection(3))
    obs = random_obs(np.random.default_rng(0), 20, center=S[:2], spread=30.0)
    C = np.zeros((MAXA, len(obs)))
    with pytest.raises(ValueError, match='too short'):
        refit_arm(S, 0, tab.P, tab.logPn, *obs.kernel_args(), C, tab.gaps, tab.widths,
                    log_floor_table(0.01, 5.0))


def _chain_on_scene(cfg, gt, bad):
    est = TopologyEstimator(cfg, seed=0)
    est.set_observations(scene(gt, 'tracked', seed=2, clutter=10))
    post = Posterior(Tables(cfg), est.observations)
    c = Chain.start(pack_state(bad), len(post.obs), 7)
    post.rescore(c)
    return post, c


def test_refit_chain_is_monotone_and_recovers_lane_counts():
    """A chain whose arm has the wrong lane counts and gap: one sweep puts them right
    (center and angles are the truth's) and never lowers the posterior."""
    import copy
    gt = EASY[0]
    bad = copy.deepcopy(gt)
    bad.arms[1].lanes_in, bad.arms[1].gap = bad.arms[1].lanes_in + 2, 3.0
    cfg = TopologyConfig()
    post, c = _chain_on_scene(cfg, gt, bad)
    before = c.ll + c.lp
    refit_chain(post, c, 1)
    assert c.ll + c.lp >= before and c.best_lpost >= c.ll + c.lp - 1e-9
    assert int(c.S[HDR + STRIDE + NIN]) == gt.arms[1].lanes_in
    assert c.ll == pytest.approx(post.loglik(c.S)[0], abs=1e-9)
    S0 = c.S.copy()
    refit_chain(post, c, 0)                              # sweeps = 0: no-op
    assert np.array_equal(c.S, S0)


def test_refit_gap_width_keeps_the_counts_and_scores_exactly():
    gt = EASY[1]
    cfg = TopologyConfig()
    post, _ = _chain_on_scene(cfg, gt, gt)
    S = pack_state(gt)
    S[HDR + GAP] = 3.9
    S2, lp = refit_gap_width(post, S.copy(), 0)
    assert (S2[HDR + NIN], S2[HDR + NOUT]) == (S[HDR + NIN], S[HDR + NOUT])
    assert lp == pytest.approx(post(S2), abs=1e-9) and lp >= post(S) - 1e-9


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(states(), st.integers(0, 10 ** 6), st.booleans())
def test_lane_candidates_in_one_pass_are_refit_gap_width_bit_for_bit(S, seed, lane_sum):
    """refit_lane_candidates (one grid pass for all lane counts of an arm, the descent's
    screen) gives exactly the states and log posteriors of one refit_gap_width each."""
    rng = np.random.default_rng(seed)
    obs = random_obs(rng, 80, center=S[:2], spread=30.0)
    cfg = TopologyConfig(lane_sum=lane_sum)
    post = Posterior(Tables(cfg), obs)
    k = int(rng.integers(0, int(S[2])))
    i0 = HDR + k * STRIDE
    counts = [(ni, no) for ni, no in itertools.product(range(cfg.min_lanes, cfg.max_lanes + 1),
                                                       repeat=2) if rng.random() < 0.4] or [(1, 1)]
    got = refit_lane_candidates(post, S, k, counts)
    for (ni, no), (S2, L2) in zip(counts, got):
        T = S.copy()
        T[i0 + NIN], T[i0 + NOUT] = ni, no
        T, L = refit_gap_width(post, T, k)
        assert np.array_equal(S2, T) and L2 == L
