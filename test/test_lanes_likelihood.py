"""Incremental likelihood/prior of the compiled chain vs a reference recomputation (§III-C)."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from test_lanes_synth import synth_case

from intersection_estimator.lanes import LaneConfig, LaneCourseEstimator
from intersection_estimator.lanes.likelihood import all_terms, seg_dist2
from intersection_estimator.lanes.prior import all_angles, log_prior

_CASE = synth_case(5, n_arms=4, lanes=(1, 2), per_lane=3, length=30.0)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(chain_seed=st.integers(0, 2**31 - 1), n=st.integers(1, 4000),
       temp=st.sampled_from([0.01, 1.0, 30.0]), eps=st.sampled_from([0.0, 0.05]))
def test_incremental_update_equals_reference(chain_seed, n, temp, eps):
    topo, _, _, dets = _CASE
    cfg = LaneConfig(temp_start=temp, temp_end=temp, outlier_weight=eps, keep_best=0,
                     p_split=0.1, p_merge=0.1)
    est = LaneCourseEstimator(cfg, chain_seed)
    est.initialise(topo, dets)
    lp0 = est.log_posterior()
    est.run(n_samples=n)
    # cached per-point terms, centers, angles and delta_l as the chain left them ...
    C, term, ang, delta = est._C.copy(), est._term.copy(), est._ang.copy(), est._delta.copy()
    lp1 = est.log_posterior()          # ... against a recomputation from scratch
    np.testing.assert_allclose(C, est._C, atol=1e-9)
    np.testing.assert_allclose(term, est._term, atol=1e-7)
    np.testing.assert_allclose(ang, est._ang, atol=1e-9)
    np.testing.assert_allclose(delta, est._delta, atol=1e-6)
    # the chain's accumulated log-posterior change matches too
    np.testing.assert_allclose(lp1 - lp0, est.last_chain[1], rtol=1e-6, atol=1e-5)


def test_likelihood_prefers_the_true_course():
    """Shifting all center lines sideways by 1 m lowers the trajectory likelihood."""
    topo, _, _, dets = _CASE
    est = LaneCourseEstimator(LaneConfig(), 0)
    est.initialise(topo, dets)
    C = est.graph.centers()
    out = np.zeros(len(est._Q))
    good = all_terms(C, est._Q, est._lo, est._hi, 0.5, 0.0, out)
    shifted = C + np.array([0.7, 0.7])
    bad = all_terms(shifted, est._Q, est._lo, est._hi, 0.5, 0.0, out)
    assert good > bad


def test_seg_dist2_clamps_to_the_segment():
    assert seg_dist2(0.5, 1.0, 0.0, 0.0, 1.0, 0.0) == 1.0
    assert seg_dist2(2.0, 0.0, 0.0, 0.0, 1.0, 0.0) == 1.0
    assert seg_dist2(-1.0, 1.0, 0.0, 0.0, 0.0, 0.0) == 2.0


def test_smoothness_prior_prefers_gt_over_zigzag():
    """delta_l (sum of |angle changes|) and the prior favour the GT course over a zig-zag."""
    topo, _, _, dets = _CASE
    est = LaneCourseEstimator(LaneConfig(), 0)
    est.initialise(topo, dets)          # GT topology: straight lanes, arc connectors
    g = est.graph
    C = g.centers()
    zig = C.copy()
    for li in range(len(g.specs)):
        o, n = g.st_off[li], g.st_n[li]
        sign = np.where(np.arange(1, n - 1) % 2, 1.0, -1.0)[:, None]
        zig[o + 1:o + n - 1] += 0.3 * g.st_normal[o + 1:o + n - 1] * sign
    ang, d_gt, d_zig = np.zeros(len(C)), np.zeros(len(g.specs)), np.zeros(len(g.specs))
    all_angles(C, g.prev_st, g.next_st, g.st_ll, ang, d_gt)
    all_angles(zig, g.prev_st, g.next_st, g.st_ll, ang, d_zig)
    assert np.all(d_zig >= d_gt - 1e-9) and d_zig.sum() > d_gt.sum() + 1.0
    assert _prior_of(est, zig) < _prior_of(est, C)


def _prior_of(est, C):
    g, cfg = est.graph, est.config
    ang, delta = np.zeros(len(C)), np.zeros(len(g.specs))
    all_angles(C, g.prev_st, g.next_st, g.st_ll, ang, delta)
    return log_prior(delta, est._mu, 0.5 / cfg.sigma_delta ** 2, cfg.tau, g.n_shared())
