"""Traffic-shaped connectors (lanes/spline.py): cubic B-spline least squares."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from intersection_estimator.lanes import LaneConfig
from intersection_estimator.lanes.init import arc_bezier, lane_specs, trajectories, assign_parts
from intersection_estimator.lanes.spline import (connector_pieces, fit_connector, noise_variance,
                                                 prefer_fit, sample_curve, traffic_connector)
from intersection_estimator.evaluate import lane_distance
from intersection_estimator.pipeline import estimate
from intersection_estimator.sim import simulate_scenario


def _ellipse_turn(a=18.0, b=7.0, n=200):
    """A left turn along a quarter ellipse: not a circular arc, not a Bezier."""
    phi = np.linspace(-np.pi / 2, 0.0, n)
    return np.stack([a * np.cos(phi), b * np.sin(phi) + b], axis=1)


def _noisy_runs(curve, rng, runs=4, noise=0.5, step=1.0):
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
    out = []
    for _ in range(runs):
        q = np.arange(rng.uniform(0, step), s[-1], step)
        p = np.stack([np.interp(q, s, curve[:, 0]), np.interp(q, s, curve[:, 1])], axis=1)
        out.append(p + rng.normal(0, noise, p.shape))
    return out


def test_fit_follows_a_curve_that_the_arc_start_does_not():
    truth = _ellipse_turn()
    c0, c1 = truth[0], truth[-1]
    t0, t1 = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    rng = np.random.default_rng(0)
    pieces = [np.concatenate([[c0 + [-3, 0], c0 + [-1, 0]], p, [c1 + [0, 1], c1 + [0, 3]]])
              for p in _noisy_runs(truth, rng)]
    pieces = connector_pieces(pieces, c0, c1, presmooth=5)
    ctrl, knots = fit_connector(pieces, c0, t0, c1, t1, smooth=10.0)
    fitted, tang = sample_curve(ctrl, knots, 1.0, 6)
    arc = arc_bezier(c0, t0, c1, t1, np.linspace(0, 1, 100))
    err_fit, err_arc = lane_distance(fitted, truth), lane_distance(arc, truth)
    assert err_fit < 0.06 and err_fit < 0.2 * err_arc, (err_fit, err_arc)   # 3.4 vs 57 cm
    # re-setting the parameters to the foot points removes the pull towards the chord
    once = sample_curve(*fit_connector(pieces, c0, t0, c1, t1, smooth=10.0, iters=0), 1.0, 6)[0]
    assert lane_distance(once, truth) > 2 * err_fit
    # end points and tangents are those of the lanes it joins
    assert np.allclose(fitted[0], c0) and np.allclose(fitted[-1], c1)
    assert tang[0] @ t0 > 0.999 and tang[-1] @ t1 > 0.999
    # equidistant stations
    d = np.linalg.norm(np.diff(fitted, axis=0), axis=1)
    assert np.ptp(d) < 0.05


def test_the_fit_replaces_the_start_only_where_the_traffic_says_so():
    truth = _ellipse_turn()
    c0, c1 = truth[0], truth[-1]
    t0, t1 = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    arc = arc_bezier(c0, t0, c1, t1, np.linspace(0, 1, 100))
    rng = np.random.default_rng(1)
    for curve, wanted in ((truth, True), (arc, False)):
        pieces = connector_pieces(_noisy_runs(curve, rng, noise=1.0), c0, c1)
        ctrl, knots = fit_connector(pieces, c0, t0, c1, t1, smooth=10.0)
        fitted = sample_curve(ctrl, knots, 1.0, 6)[0]
        n_par = 2 * (len(ctrl) - 4) + 2
        assert prefer_fit(pieces, fitted, arc, n_par, 2.0) is wanted
        assert prefer_fit(pieces, fitted, arc, n_par, 0.0) is True


def test_too_little_traffic_gives_none():
    c0, c1 = np.zeros(2), np.array([10.0, 10.0])
    assert fit_connector([np.array([[1.0, 0.0], [5.0, 5.0], [9.0, 9.0]])], c0, [1, 0], c1,
                         [0, 1], min_points=10) is None
    assert connector_pieces([np.array([[0.0, 0.0], [1.0, 1.0]])], c0, c1) == []


def test_switch_reshapes_the_connectors_and_keeps_the_lanes():
    sc = simulate_scenario(2)
    dets = sc.detections('tracked')
    topo = sc.gt
    out = {}
    for flag in (0, 1):
        cfg = replace(LaneConfig(), connector_traffic=flag, traffic_select=0.0)
        trajs = trajectories(dets)
        assign_parts(trajs, topo, cfg)
        specs, _, _ = lane_specs(topo, trajs, cfg)
        out[flag] = {s.id: s for s in specs}
    assert out[0].keys() == out[1].keys()
    moved = 0
    for sid, s in out[0].items():
        t = out[1][sid]
        if s.kind != 'connector':
            assert np.array_equal(s.left, t.left) and np.array_equal(s.right, t.right)
        else:
            assert np.allclose(s.left[[0, -1]], t.left[[0, -1]])     # shared end points
            moved += not (len(s.left) == len(t.left) and np.allclose(s.left, t.left))
    assert moved > 0


def test_pipeline_with_traffic_connectors_scores_close_to_the_truth():
    sc = simulate_scenario(4)
    from intersection_estimator.evaluate import evaluate
    r = estimate(sc.detections('tracked'), mode='tracked', seed=0, lane_samples=5000,
                 lane_config=replace(LaneConfig(), connector_traffic=1, traffic_select=0.0))
    m = evaluate((r.intersection, r.lanelets), sc)
    assert m['topology_correct'] and m['by_kind']['connector']['matched'] > 0
    k = m['by_kind']['connector']
    assert k['error_cm_sum'] / k['matched'] < 30.0


def test_traffic_connector_needs_two_stations_per_lane():
    e = type('S', (), {'left': np.zeros((1, 2)), 'right': np.zeros((1, 2))})()
    assert traffic_connector(e, e, [], LaneConfig()) is None


def test_bad_switch_value_is_named():
    with pytest.raises(ValueError, match='connector_traffic'):
        replace(LaneConfig(), connector_traffic=2).validate()


# ---------------------------------------------------------------- the compiled fit
def _knots(n):
    return np.r_[[0.0] * 3, np.linspace(0.0, 1.0, n - 2), [1.0] * 3]


def test_compiled_curve_is_scipys_bspline():
    from scipy.interpolate import BSpline
    from intersection_estimator.lanes.spline import _evaluate
    rng = np.random.default_rng(3)
    for n in (5, 9, 23):
        ctrl, knots = rng.normal(0, 10, (n, 2)), _knots(n)
        us = np.r_[0.0, rng.uniform(0, 1, 50), 1.0]
        assert np.allclose(_evaluate(ctrl, knots, us), BSpline(knots, ctrl, 3)(us), atol=1e-10)


def test_compiled_fit_equals_the_least_squares_it_replaced():
    """One penalty, parameters fixed (no foot-point rounds): the compiled normal equations
    give the control points of the scipy design matrix + lstsq reference."""
    from reference.spline import solve_reference
    rng = np.random.default_rng(4)
    truth = _ellipse_turn()
    c0, c1 = truth[0], truth[-1]
    t0, t1 = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    pieces = connector_pieces(_noisy_runs(truth, rng, noise=0.7), c0, c1)
    for smooth in (0.1, 1.0, 10.0):
        ctrl, knots = fit_connector(pieces, c0, t0, c1, t1, smooth=smooth, iters=0)
        Q = np.concatenate(pieces)
        u = np.concatenate([p_ / p_[-1] for p_ in
                            (np.r_[0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
                             for p in pieces)])
        ref = solve_reference(Q, u, knots, c0, t0, c1, t1, smooth)
        assert np.allclose(ctrl, ref, atol=1e-6), (smooth, np.abs(ctrl - ref).max())


def _hairpin(r=4.0, n=120):
    """A tight 150 deg turn (radius 4 m) between two straight 8 m runs."""
    phi = np.linspace(0.0, np.radians(150), n)
    arc = np.stack([r * np.sin(phi), r - r * np.cos(phi)], axis=1)
    d_out = np.array([np.cos(np.radians(150)), np.sin(np.radians(150))])
    lead = np.stack([np.linspace(-8, 0, 30, endpoint=False), np.zeros(30)], axis=1)
    tail = arc[-1] + np.linspace(0, 8, 30)[1:, None] * d_out
    return np.concatenate([lead, arc, tail]), d_out


def test_the_traffic_picks_the_penalty():
    """A tight turn seen with little noise gets a weak penalty (the strongest alone cuts the
    corner); a gentle arc seen through 1 m of noise a strong one (the weakest alone follows
    the noise). The choice is the traffic's, the candidates are the same."""
    grid = np.geomspace(0.1, 10.0, 3)
    rng = np.random.default_rng(5)
    hp, d_out = _hairpin()
    c0, c1 = hp[0], hp[-1]
    pieces = connector_pieces(_noisy_runs(hp, rng, runs=3, noise=0.15, step=0.5), c0, c1)
    err = {}
    for name, kw in (('strong', dict(smooth=10.0)), ('chosen', dict(smooth_grid=grid))):
        ctrl, knots = fit_connector(pieces, c0, [1, 0], c1, d_out, **kw)
        err[name] = lane_distance(sample_curve(ctrl, knots, 0.5, 6)[0], hp)
    assert err['chosen'] < 0.5 * err['strong'], err
    truth = _ellipse_turn(a=30.0, b=20.0)
    c0, c1 = truth[0], truth[-1]
    pieces = connector_pieces(_noisy_runs(truth, rng, runs=2, noise=1.0), c0, c1)
    err = {}
    for name, kw in (('weak', dict(smooth=0.1)), ('chosen', dict(smooth_grid=grid))):
        ctrl, knots = fit_connector(pieces, c0, [1, 0], c1, [0, 1], **kw)
        err[name] = lane_distance(sample_curve(ctrl, knots, 0.5, 6)[0], truth)
    assert err['chosen'] < err['weak'], err


def _quarter_turn(r=8.0):
    """A 90 deg right-angle turn of radius ``r`` between two straight 10 m runs."""
    phi = np.linspace(0.0, np.pi / 2, 150)
    arc = np.stack([r * np.sin(phi), r - r * np.cos(phi)], axis=1)
    lead = np.stack([np.linspace(-10.0, 0.0, 40, endpoint=False), np.zeros(40)], axis=1)
    tail = arc[-1] + np.linspace(0.0, 10.0, 40)[1:, None] * np.array([0.0, 1.0])
    return np.concatenate([lead, arc, tail])


@pytest.mark.parametrize('sigma', [0.3, 1.0])
def test_noise_variance_reads_the_sensors_noise_off_curved_paths(sigma):
    """White noise of ``sigma`` on vehicles turning at 10 Hz (0.7 m per cycle) reads back
    within 15 %; too few rows read 0 (unknown)."""
    rng = np.random.default_rng(3)
    runs = _noisy_runs(_quarter_turn(), rng, runs=6, noise=sigma, step=0.7)
    assert noise_variance(runs) == pytest.approx(sigma ** 2, rel=0.15)
    assert noise_variance([runs[0][:5]]) == 0.0
    # every row published twice: the repeats are not read as noise-free motion
    twice = [np.repeat(r, 2, axis=0) for r in runs]
    assert noise_variance(twice) == pytest.approx(noise_variance(runs))


def test_known_noise_lets_one_vehicle_shape_a_tight_turn():
    """One vehicle through a tight turn, 1 m noise: Akaike's criterion on that one path's
    few metres smooths the corner away; with the noise known (Mallows) the corner is kept.
    Mean error over 30 draws."""
    truth = _quarter_turn()
    grid = np.geomspace(0.01, 10.0, 4)
    err = {0.0: [], 1.0: []}
    for seed in range(30):
        rng = np.random.default_rng(seed)
        pieces = connector_pieces(_noisy_runs(truth, rng, runs=1, noise=1.0, step=0.7),
                                  truth[0], truth[-1])
        for nv in err:
            fit = fit_connector(pieces, truth[0], [1, 0], truth[-1], [0, 1], smooth_grid=grid,
                                noise_var=nv)
            err[nv].append(lane_distance(sample_curve(*fit, 0.5, 6)[0], truth))
    assert np.mean(err[1.0]) < 0.92 * np.mean(err[0.0]), {k: np.mean(v) for k, v in err.items()}
