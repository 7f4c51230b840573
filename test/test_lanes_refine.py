"""Least-squares refinement of the lane course (beyond the paper, lanes/refine.py)."""

from __future__ import annotations

import numpy as np

from test_lanes_synth import synth_case

from intersection_estimator.lanes import LaneConfig, LaneCourseEstimator

CASE = synth_case(4, n_arms=3, lanes=(1, 1), per_lane=6, length=40.0)


def _estimator(**kw):
    topo, _, _, dets = CASE
    est = LaneCourseEstimator(LaneConfig(**kw), 0)
    est.initialise(topo, dets)
    return est


def _offset(est, lane_id):
    """Mean signed lateral offset of a lanelet's center from the GT lane (m)."""
    topo, gt, _, _ = CASE
    l = next(x for x in est.lanelets if x.id == lane_id)
    a = topo.arms[l.arm]
    truth = gt[(l.arm, 1, l.lane_index)]
    return float(np.mean((l.center - truth[0]) @ a.normal))


def test_refine_pulls_a_displaced_lane_back_to_the_traffic():
    est = _estimator()
    g = est.graph
    i = next(k for k, s in enumerate(g.specs) if s.id == 'a0_in0')
    pts = np.unique(g.ref[2 * np.arange(g.st_off[i], g.st_off[i] + g.st_n[i])[:, None]
                         + np.array([0, 1])])
    g.P[pts] += 0.8 * g.axis[pts]                     # 0.8 m off its traffic
    est._recompute()
    assert abs(_offset(est, 'a0_in0')) > 0.5
    est._refine()
    assert abs(_offset(est, 'a0_in0')) < 0.25
    # the shared end points stayed shared: connectors still start where the lane ends
    for l in est.lanelets:
        for s in l.successors:
            nxt = next(x for x in est.lanelets if x.id == s)
            np.testing.assert_array_equal(l.left[-1], nxt.left[0])


def test_refine_option_runs_after_the_chain():
    est = _estimator(refine=1)
    est.run(n_samples=500)
    assert 'refine' in est.timings
    assert all(np.isfinite(l.center).all() for l in est.lanelets)


def test_refine_init_option_refines_the_start_and_samples_from_it():
    """``refine_init`` evaluates the posterior before the prior's mean angles were read
    from the start; they are read before and again after the refinement."""
    plain, est = _estimator(), _estimator(refine_init=1)
    assert np.isfinite(est.log_posterior())
    moved = max(float(np.abs(a.center - b.center).max())
                for a, b in zip(plain.lanelets, est.lanelets))
    assert moved > 1e-3                       # the refinement changed the start
    est.run(n_samples=500)
    assert all(np.isfinite(l.center).all() for l in est.lanelets)
