"""Likelihood (paper §II-C2): compiled + incremental == plain numpy reference; GT wins."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from intersection_estimator.model import Arm, Intersection
from intersection_estimator.topology import TopologyConfig, TopologyEstimator
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.likelihood import (ObservationSet, all_columns, full_loglik,
                                                        log_likelihood)
from intersection_estimator.topology.mcmc import advance, state_log_prior, temperatures
from intersection_estimator.topology.arm_offset import offset_log_prior
from intersection_estimator.topology.arm_bend import bend_log_prior
from intersection_estimator.topology.moves import BEND_MOVE, MOVE_NAMES, OFFSET
from intersection_estimator.topology.prior import log_prior
from intersection_estimator.topology.state import MAXA, Chain, pack_state
from reference.likelihood import log_likelihood_reference

from .scenes import easy_intersection, scene
from .strategies import random_obs, states

CFG = TopologyConfig()
TAB = Tables(CFG)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(states(4.0, 40.0), st.integers(0, 10 ** 6), st.sampled_from([0.0, 0.5, 1.0]),
       st.sampled_from([1, -1]))
def test_compiled_likelihood_equals_reference(S, seed, lane_norm, side):
    rng = np.random.default_rng(seed)
    obs = random_obs(rng, 200, center=S[:2], spread=40.0)
    P = TopologyConfig(lane_norm=lane_norm, traffic_side=side, cut_sigma2=700.0).kernel_params()
    assert abs(log_likelihood(S, obs, P) - log_likelihood_reference(S, obs, P)) < 1e-9


@pytest.mark.parametrize('offset_max,bend_max', [(0.0, 0.0), (6.0, 0.0), (6.0, 30.0)])
def test_incremental_likelihood_equals_reference_along_a_chain(offset_max, bend_max):
    """After thousands of accepted moves the cached columns give the reference value (with
    the arm-axis offset and the bend off and on)."""
    TAB = Tables(TopologyConfig(arm_offset_max=offset_max, arm_bend_max_deg=bend_max))
    rng = np.random.default_rng(1)
    inter = easy_intersection(4, lanes=((2, 1), (1, 2), (2, 2), (1, 1)))
    obs = random_obs(rng, 150, center=inter.center, spread=50.0)
    S = pack_state(inter)
    C = np.zeros((MAXA, len(obs)))
    ll = float(full_loglik(S, TAB.P, *obs.kernel_args(), C))
    lp = float(state_log_prior(S, TAB.P, TAB.logPA, TAB.logPn, TAB.arm_const))
    ch = Chain(S=S, C=C, ll=ll, lp=lp, best_S=S.copy(), best_lpost=ll + lp, step=0,
               stats=np.zeros(2 * len(MOVE_NAMES), np.int64))
    for i in range(10):
        temps = temperatures(0, 500, 1e4, 1e4, 1)     # hot: many accepted moves of every kind
        advance(ch, 500, temps, 100 + i, TAB.P, TAB.logPA, TAB.logPn, TAB.arm_const,
                TAB.logqn, TAB.cumqn, obs)
        assert abs(ch.ll - log_likelihood_reference(ch.S, obs, TAB.P)) < 1e-9
        n = int(ch.S[2])
        C2 = np.zeros_like(ch.C)
        all_columns(ch.S, TAB.P, *obs.kernel_args()[:8], C2)
        assert np.allclose(ch.C[:n], C2[:n], rtol=0, atol=1e-12)
        assert abs(ch.lp - log_prior(ch.S, TAB.logPA, TAB.logPn, TAB.arm_const)
                   - offset_log_prior(ch.S, TAB.P) - bend_log_prior(ch.S, TAB.P)) < 1e-9
    acc = ch.stats[1::2]
    # every move kind was accepted at least once (a removal from six arms is rarely valid:
    # with the bend on, its draws leave none in this chain; the add-arm was accepted)
    assert (acc[:6 if bend_max == 0 else 4] > 0).all() and acc[5] > 0, acc
    assert (acc[OFFSET] > 0) == (offset_max > 0), acc
    assert (acc[BEND_MOVE] > 0) == (bend_max > 0), acc


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


