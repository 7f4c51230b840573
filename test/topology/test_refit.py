"""Arm refit (beyond the paper): the grid search equals the reference posterior's best."""

import itertools
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from intersection_estimator.topology import TopologyConfig, TopologyEstimator
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.likelihood import full_loglik
from intersection_estimator.topology.mcmc import Posterior, state_log_prior
from intersection_estimator.topology.refit import (LOG_FLOOR_INV_STEP, log_floor_table,
                                                   refit_arm, refit_chain, refit_gap_width,
                                                   refit_lane_candidates)
from intersection_estimator.topology.state import (GAP, HDR, MAXA, NIN, NOUT, OFF, STRIDE, WID,
                                                   Chain, pack_state)
from reference.likelihood import log_likelihood_reference

from .scenes import EASY, easy_intersection, scene
from .strategies import random_obs, states


def _refit_candidates(S, i0, tab, cfg, fixed, known):
    """Every (gap, width, n_in, n_out, offset) refit_arm may choose: with the offset off the
    gap x width grids plus the current values; with it on, every pair of lane starts
    ``(h_in, h_out)`` of its grid (gap ``h_in + h_out``, offset ``o + ts (h_in - h_out) / 2``
    within the bounds) -- when every observation's direction is ``known``."""
    counts = ([(S[i0 + NIN], S[i0 + NOUT])] if fixed else
              list(itertools.product(range(cfg.min_lanes, cfg.max_lanes + 1), repeat=2)))
    widths = np.r_[tab.widths, S[i0 + WID]]
    oc = S[i0 + OFF]
    if cfg.arm_offset_max <= 0 or not known:
        pairs = [(g, oc) for g in np.r_[tab.gaps, S[i0 + GAP]]]
    else:
        span = cfg.arm_offset_max + abs(oc)
        n = int(math.ceil((0.5 * cfg.gap_max + 2 * span) / 0.5)) + 1
        H = np.r_[-span + 0.5 * np.arange(n), 0.5 * S[i0 + GAP]]
        pairs = [(a + b, oc + 0.5 * (a - b)) for a in H for b in H     # ts = +1 (right-hand)
                 if -1e-9 <= a + b <= cfg.gap_max + 1e-9
                 and abs(oc + 0.5 * (a - b)) <= cfg.arm_offset_max + 1e-9]
    for (ni, no), (g, o), w in itertools.product(counts, pairs, widths):
        yield max(g, 0.0), w, ni, no, o


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(states(max_offset=3.0), st.integers(0, 10 ** 6), st.sampled_from([0.0, 0.5]),
       st.booleans(), st.booleans(), st.sampled_from([0.0, 6.0]), st.booleans())
def test_refit_arm_finds_the_best_grid_point_of_the_reference_posterior(S, seed, lane_norm,
                                                                        lane_sum, fixed, omax,
                                                                        known):
    """refit_arm (compiled, relative log-densities) picks the (gap, width, lane counts) of
    arm k -- with the axis offset on, the offset too -- that maximise the plain reference
    posterior over its grid (with ``fixed``: the best for the counts already there). The
    offset is searched only when every observation's direction is ``known``."""
    rng = np.random.default_rng(seed)
    obs = random_obs(rng, 80, center=S[:2], spread=30.0, known_direction=known)
    cfg = TopologyConfig(lane_norm=lane_norm, lane_sum=lane_sum, cut_sigma2=700.0,
                         arm_offset_max=omax)
    if omax == 0.0:
        S = S.copy()
        S[HDR + OFF::STRIDE][:int(S[2])] = 0.0
    tab = Tables(cfg)
    k = int(rng.integers(0, int(S[2])))
    i0 = HDR + k * STRIDE

    def lpost(T):
        return (log_likelihood_reference(T, obs, tab.P)
                + float(state_log_prior(T, tab.P, tab.logPA, tab.logPn, tab.arm_const)))

    best = -math.inf
    for g, w, ni, no, o in _refit_candidates(S, i0, tab, cfg, fixed, known):
        T = S.copy()
        T[i0 + GAP], T[i0 + WID], T[i0 + NIN], T[i0 + NOUT], T[i0 + OFF] = g, w, ni, no, o
        best = max(best, lpost(T))
    R = S.copy()
    C = np.zeros((MAXA, len(obs)))
    full_loglik(R, tab.P, *obs.kernel_args(), C)
    refit_arm(R, k, tab.P, tab.logPn, *obs.kernel_args(), C, tab.gaps, tab.widths,
                tab.log_floor, fixed)
    assert lpost(R) == pytest.approx(best, abs=1e-6)
    if fixed:
        assert (R[i0 + NIN], R[i0 + NOUT]) == (S[i0 + NIN], S[i0 + NOUT])


def test_refit_arm_moves_the_axis_of_an_arm_beside_the_center():
    """An arm whose lanes run 3 m beside the center (an offset arm): with the axis offset
    on, one refit from the straight-through state finds its offset and lane counts; the
    gap-width grid alone (offset off) cannot reach them."""
    import copy
    gt = copy.deepcopy(EASY[1])
    gt.arms[1].offset, gt.arms[1].lanes_in, gt.arms[1].gap = 3.0, 2, 0.5
    start = copy.deepcopy(gt)
    start.arms[1].offset, start.arms[1].lanes_in, start.arms[1].gap = 0.0, 3, 0.5
    for omax, found in ((6.0, True), (0.0, False)):
        cfg = TopologyConfig(arm_offset_max=omax)
        post, c = _chain_on_scene(cfg, gt, start)
        i0 = HDR + STRIDE
        refit_arm(c.S, 1, post.t.P, post.t.logPn, *post.obs.kernel_args(), c.C, post.t.gaps,
                  post.t.widths, post.t.log_floor)
        got = (int(c.S[i0 + NIN]), round(float(c.S[i0 + OFF]) * 2) / 2)
        assert (got == (2, 3.0)) is found, (omax, got)


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
