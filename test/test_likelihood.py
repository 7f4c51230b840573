"""Likelihood (paper §II-C2): compiled + incremental == plain numpy reference; GT wins."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from intersection_estimator import _kernels as K
from intersection_estimator.anneal import Chain, advance, temperatures
from intersection_estimator.likelihood import (ObservationSet, log_likelihood,
                                               log_likelihood_reference)
from intersection_estimator.model import Arm, Intersection
from intersection_estimator.moves import pack_state
from intersection_estimator.topology import TopologyConfig, TopologyEstimator, _Tables

from test_moves import states
from topology_scenes import easy_intersection, scene

CFG = TopologyConfig()
TAB = _Tables(CFG)


def random_obs(rng, n, center=(0.0, 0.0), spread=60.0):
    xy = np.asarray(center) + rng.uniform(-spread, spread, (n, 2))
    h = rng.uniform(-math.pi, math.pi, n)
    has_o = rng.uniform(size=n) < 0.5
    return ObservationSet(xy[:, 0].copy(), xy[:, 1].copy(), np.where(has_o, np.cos(h), 0.0),
                          np.where(has_o, np.sin(h), 0.0), has_o,
                          rng.choice([1.0, -1.0, 0.0], n),
                          rng.uniform(0.5, 5.0, n), rng.uniform(0.3, 2.0, n),
                          rng.uniform(0.05, 0.5, n))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(states(), st.integers(0, 10 ** 6), st.sampled_from([0.0, 0.5, 1.0]),
       st.sampled_from([1, -1]))
def test_compiled_likelihood_equals_reference(S, seed, lane_norm, side):
    rng = np.random.default_rng(seed)
    obs = random_obs(rng, 200, center=S[:2], spread=40.0)
    P = TopologyConfig(lane_norm=lane_norm, traffic_side=side, cut_sigma2=700.0).kernel_params()
    assert abs(log_likelihood(S, obs, P) - log_likelihood_reference(S, obs, P)) < 1e-9


def test_incremental_likelihood_equals_reference_along_a_chain():
    """After thousands of accepted moves the cached columns give the reference value."""
    rng = np.random.default_rng(1)
    inter = easy_intersection(4, lanes=((2, 1), (1, 2), (2, 2), (1, 1)))
    obs = random_obs(rng, 150, center=inter.center, spread=50.0)
    S = pack_state(inter)
    C = np.zeros((K.MAXA, len(obs)))
    ll = float(K.full_loglik(S, TAB.P, *obs.kernel_args(), C))
    lp = float(K.log_prior(S, TAB.logPA, TAB.logPn, TAB.arm_const))
    ch = Chain(S=S, C=C, ll=ll, lp=lp, best_S=S.copy(), best_lpost=ll + lp, step=0,
               stats=np.zeros(14, np.int64))
    for i in range(10):
        temps = temperatures(0, 500, 1e4, 1e4, 1)     # hot: many accepted moves of every kind
        advance(ch, 500, temps, 100 + i, TAB.P, TAB.logPA, TAB.logPn, TAB.arm_const,
                TAB.logqn, TAB.cumqn, obs)
        assert abs(ch.ll - log_likelihood_reference(ch.S, obs, TAB.P)) < 1e-9
        n = int(ch.S[2])
        C2 = np.zeros_like(ch.C)
        K.all_columns(ch.S, TAB.P, *obs.kernel_args()[:8], C2)
        assert np.allclose(ch.C[:n], C2[:n], rtol=0, atol=1e-12)
        assert abs(ch.lp - K.log_prior(ch.S, TAB.logPA, TAB.logPn, TAB.arm_const)) < 1e-9
    acc = ch.stats[1::2]
    assert (acc[:6] > 0).all(), acc     # every move kind was accepted at least once


def _one_obs(x, y, heading=None, d=1.0):
    has = heading is not None
    h = heading or 0.0
    return ObservationSet(np.array([x]), np.array([y]), np.array([math.cos(h) if has else 0.0]),
                          np.array([math.sin(h) if has else 0.0]), np.array([has]),
                          np.array([d]), np.array([1.0]), np.array([1.0]), np.array([0.1]))


def test_lane_geometry_and_direction():
    """On the entering lane center: peak density; wrong direction or behind the start: low."""
    arm = Arm(angle=0.0, gap=1.0, lanes_in=2, lanes_out=1, lane_width=3.0)
    S = pack_state(Intersection(center=np.zeros(2), arms=[arm, Arm(angle=math.pi)]))
    P = TopologyConfig(lane_norm=0.0).kernel_params()
    floor = math.log(1.0 + CFG.clutter_floor)
    y_in = 0.5 + 1.5 + 3.0                # entering lane k=1 on the +n side
    assert math.isclose(log_likelihood(S, _one_obs(30.0, y_in, math.pi), P), floor)
    assert math.isclose(log_likelihood(S, _one_obs(30.0, y_in, None, 1.0), P), floor)
    assert log_likelihood(S, _one_obs(30.0, y_in, None, -1.0), P) < floor - 1.0
    # leaving on the -n side, orientation outward
    assert math.isclose(log_likelihood(S, _one_obs(30.0, -2.0, 0.0), P), floor)
    # behind the ray start of arm 0 and far from arm 1's lanes
    assert log_likelihood(S, _one_obs(-30.0, 20.0, math.pi), P) < floor - 3.0


def test_lane_normalisation_penalises_empty_lanes():
    S1 = pack_state(Intersection(np.zeros(2), [Arm(0.0, lanes_in=1), Arm(math.pi)]))
    S3 = pack_state(Intersection(np.zeros(2), [Arm(0.0, lanes_in=3), Arm(math.pi)]))
    obs = _one_obs(30.0, 1.75, math.pi)
    P = TopologyConfig(lane_norm=1.0).kernel_params()
    assert log_likelihood(S1, obs, P) > log_likelihood(S3, obs, P)
    P0 = TopologyConfig(lane_norm=0.0).kernel_params()
    assert math.isclose(log_likelihood(S1, obs, P0), log_likelihood(S3, obs, P0))


def _perturbed(gt: Intersection):
    def clone(**kw):
        arms = [Arm(a.angle, a.gap, a.lanes_in, a.lanes_out, a.lane_width) for a in gt.arms]
        c = gt.center.copy()
        return arms, c
    out = []
    arms, c = clone()
    out.append(Intersection(c + np.array([3.0, 0.0]), arms))
    arms, c = clone()
    arms[0].angle += math.radians(6)
    out.append(Intersection(c, arms))
    arms, c = clone()
    arms[1].lanes_in += 1
    out.append(Intersection(c, arms))
    arms, c = clone()
    arms[2].lanes_out = max(1, arms[2].lanes_out - 1) if arms[2].lanes_out > 1 else 3
    out.append(Intersection(c, arms))
    arms, c = clone()
    out.append(Intersection(c, arms[:-1]))
    arms, c = clone()
    arms[3].gap += 3.0
    out.append(Intersection(c, arms))
    return out


def test_ground_truth_scores_higher_than_perturbations():
    for mode in ('tracked', 'raw', 'heading'):
        gt = easy_intersection(4, lanes=((2, 1), (1, 2), (2, 2), (1, 1)))
        est = TopologyEstimator(CFG, seed=0)
        est.set_observations(scene(gt, mode, seed=2, clutter=30))
        est._preprocess(gt.center)
        lp_gt = est.log_posterior(gt)
        for k, bad in enumerate(_perturbed(gt)):
            assert est.log_posterior(bad) < lp_gt, (mode, k)


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(states(), st.integers(0, 10 ** 6), st.sampled_from([0.0, 0.5]), st.booleans(),
       st.booleans())
def test_refit_arm_finds_the_best_grid_point_of_the_reference_posterior(S, seed, lane_norm,
                                                                        lane_sum, fixed):
    """refit_arm (compiled, relative log-densities) picks the (gap, width, lane counts) of
    arm k that maximise the plain reference posterior over its grid (with ``fixed``: the
    best gap and width for the counts already there)."""
    import itertools
    rng = np.random.default_rng(seed)
    obs = random_obs(rng, 80, center=S[:2], spread=30.0)
    cfg = TopologyConfig(lane_norm=lane_norm, lane_sum=lane_sum, cut_sigma2=700.0)
    tab = _Tables(cfg)
    k = int(rng.integers(0, int(S[2])))
    i0 = K.HDR + k * K.STRIDE

    def lpost(T):
        return (log_likelihood_reference(T, obs, tab.P)
                + float(K.log_prior(T, tab.logPA, tab.logPn, tab.arm_const)))

    best = -math.inf
    counts = ([(S[i0 + K.NIN], S[i0 + K.NOUT])] if fixed else
              itertools.product(range(cfg.min_lanes, cfg.max_lanes + 1), repeat=2))
    for (ni, no), g, w in itertools.product(list(counts), np.r_[tab.gaps, S[i0 + K.GAP]],
                                            np.r_[tab.widths, S[i0 + K.WID]]):
        T = S.copy()
        T[i0 + K.GAP], T[i0 + K.WID], T[i0 + K.NIN], T[i0 + K.NOUT] = g, w, ni, no
        best = max(best, lpost(T))
    R = S.copy()
    C = np.zeros((K.MAXA, len(obs)))
    K.full_loglik(R, tab.P, *obs.kernel_args(), C)
    K.refit_arm(R, k, tab.P, tab.logPn, *obs.kernel_args(), C, tab.gaps, tab.widths,
                tab.log_floor, fixed)
    assert lpost(R) == pytest.approx(best, abs=1e-6)
    if fixed:
        assert (R[i0 + K.NIN], R[i0 + K.NOUT]) == (S[i0 + K.NIN], S[i0 + K.NOUT])


@pytest.mark.parametrize('floor', [0.01, 0.2])
def test_log_floor_table_interpolates_log_density_to_1e9(floor):
    """refit_arm's table of log(exp(-x) + floor): cubic pieces within 1e-9 everywhere."""
    T = K.log_floor_table(floor, 40.0)
    x = np.r_[np.random.default_rng(0).uniform(0.0, 40.0, 200_000), 0.0, 40.0]
    j = (x * K.LOG_FLOOR_INV_STEP).astype(int)
    u = x * K.LOG_FLOOR_INV_STEP - j
    f = T[j, 0] + u * (T[j, 1] + u * (T[j, 2] + u * T[j, 3]))
    np.testing.assert_allclose(f, np.log(np.exp(-x) + floor), rtol=0, atol=1e-9)


def test_refit_arm_refuses_a_table_too_short_for_the_cut():
    tab = _Tables(TopologyConfig())
    S = pack_state(easy_intersection(3))
    obs = random_obs(np.random.default_rng(0), 20, center=S[:2], spread=30.0)
    C = np.zeros((K.MAXA, len(obs)))
    with pytest.raises(ValueError, match='too short'):
        K.refit_arm(S, 0, tab.P, tab.logPn, *obs.kernel_args(), C, tab.gaps, tab.widths,
                    K.log_floor_table(0.01, 5.0))
