"""Least-squares refinement of the lane course (beyond the paper, lanes/refine.py)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.ndimage import uniform_filter1d

from test_lanes_synth import synth_case

from intersection_estimator.lanes import LaneConfig, LaneCourseEstimator
from intersection_estimator.lanes.refine import effective_share, lanelet_dof

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
    plain, est = _estimator(refine_init=0), _estimator(refine_init=1, refine_select=0)
    assert np.isfinite(est.log_posterior())
    moved = max(float(np.abs(a.center - b.center).max())
                for a, b in zip(plain.lanelets, est.lanelets))
    assert moved > 1e-3                       # the refinement changed the start
    est.run(n_samples=500)
    assert all(np.isfinite(l.center).all() for l in est.lanelets)


def test_lanelet_dof_is_the_trace_of_the_hat_matrix_over_its_rows():
    """``tr(A_ll^-1 J_l^T J_l)`` equals the dense hat matrix of the fit that moves only the
    lanelet's variables, its diagonal summed over the lanelet's rows."""
    rng = np.random.default_rng(3)
    JQ = sp.random(40, 12, density=0.3, random_state=rng, format='csr')
    P = sp.random(15, 12, density=0.4, random_state=rng, format='csr')       # penalty rows
    A = (JQ.T @ JQ + P.T @ P + 1e-3 * sp.identity(12)).tocsc()
    rows = rng.integers(0, 3, 40)
    cols = {0: [0, 1, 2, 3, 4], 2: [5, 6, 7, 11]}
    dof = lanelet_dof(JQ, A, rows, cols)
    for l, c in cols.items():
        J = JQ.toarray()[rows == l][:, c]
        H = J @ np.linalg.solve(A.toarray()[np.ix_(c, c)], J.T)
        assert dof[l] == pytest.approx(np.trace(H), rel=1e-9)
    assert set(dof) == {0, 2}
    # without a penalty every parameter a lanelet's rows alone touch is one degree of freedom
    J1 = sp.csr_matrix(np.kron(np.eye(2), np.ones((5, 1))))                 # two 5-row blocks
    assert lanelet_dof(J1, (J1.T @ J1).tocsc(), np.repeat([1, 0], 5), {0: [1], 1: [0]}) == \
        pytest.approx({0: 1.0, 1: 1.0})


def test_effective_share_counts_a_smooth_path_as_one_piece_of_evidence():
    rng = np.random.default_rng(5)
    white = rng.normal(0, 1, 4000)
    smooth = np.zeros(4000)
    for i in range(1, 4000):                                   # AR(1), rho 0.95
        smooth[i] = 0.95 * smooth[i - 1] + rng.normal(0, 0.3)
    one = np.zeros(4000, np.int64)
    assert effective_share(white, one) == pytest.approx(1.0, abs=0.1)    # rho ~ 0 +- 0.016
    assert effective_share(smooth, one) == pytest.approx(0.05 / 1.95, abs=0.02)
    # consecutive points of different lanelets are no pair
    alternating = np.where(np.arange(4000) % 2 == 0, 1.0, -1.0)
    assert effective_share(alternating, np.arange(4000)) == 1.0
    assert effective_share(alternating, one) == 1.0             # negative rho is clipped


def test_refine_select_keeps_only_connectors_the_traffic_supports():
    """With a penalty no drop can beat every connector keeps its start shape, carried to the
    refined ends; without one the refinement's shape stays, as with ``refine_select`` 0."""
    plain = _estimator(refine_init=1, refine_select=0)
    free = _estimator(refine_init=1, refine_select=1e-9)
    stiff = _estimator(refine_init=1, refine_select=1000.0)
    start = _estimator(refine_init=0)
    conns = [i for i, l in enumerate(plain.lanelets) if l.kind == 'connector']
    for i in conns:
        np.testing.assert_allclose(free.lanelets[i].center, plain.lanelets[i].center, atol=1e-9)
    # the stiff connectors differ from the refined ones and keep the start's bend
    assert max(float(np.abs(stiff.lanelets[i].center - plain.lanelets[i].center).max())
               for i in conns) > 1e-3
    for i in conns:
        s, a = stiff.lanelets[i].center, start.lanelets[i].center
        bend = lambda c: np.diff(np.unwrap(np.arctan2(*np.diff(c, axis=0).T[::-1])))
        assert np.abs(bend(s).sum() - bend(a).sum()) < 0.1


def test_refine_min_share_leaves_a_start_whose_residuals_follow_each_track():
    """``refine_min_share``: white detection noise (share ~1) is refined as without the
    option; the same tracks smoothed along their rows (a tracker's output: the residuals of
    neighbouring rows alike, share ~0) keep the start."""
    topo, _, _, dets = CASE
    gated = _estimator(refine_init=1, refine_select=0, refine_min_share=0.33)
    for a, b in zip(gated.lanelets, _estimator(refine_init=1, refine_select=0, refine_min_share=0).lanelets):
        np.testing.assert_array_equal(a.center, b.center)
    smooth = dets.subset(np.ones(len(dets), bool))
    for i in np.unique(dets.track_id):
        rows = np.flatnonzero(dets.track_id == i)
        rows = rows[np.argsort(dets.t[rows])]
        smooth.xy[rows] = uniform_filter1d(dets.xy[rows], 21, axis=0, mode='nearest')

    def lanes(**kw):
        est = LaneCourseEstimator(LaneConfig(**kw), 0)
        est.initialise(topo, smooth)
        return est.lanelets
    start = lanes(refine_init=0)
    kept = lanes(refine_init=1, refine_select=0, refine_min_share=0.33)
    refined = lanes(refine_init=1, refine_select=0, refine_min_share=0)
    for a, b in zip(kept, start):
        np.testing.assert_array_equal(a.center, b.center)
    assert max(float(np.abs(a.center - b.center).max()) for a, b in zip(refined, start)) > 1e-3
