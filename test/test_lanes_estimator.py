"""LaneCourseEstimator API: initialisation (paper §III-A), anytime runs, degenerate input."""

from __future__ import annotations

import numpy as np
import pytest

from test_lanes_synth import synth_case

from intersection_estimator.lanes import LaneConfig, LaneCourseEstimator, lanelets_from_topology
from intersection_estimator.lanes.init import (Trajectory, arm_frames, assign_parts, fit_frames,
                                               split_at_center, stop_distances, trajectories)
from intersection_estimator.model import ENTERING, LEAVING, Arm, Intersection
from intersection_estimator.observations import Detections

CASE = synth_case(3, n_arms=4, lanes=(2, 1), per_lane=2, length=40.0)


def _run(seed, n=3000, case=CASE, cfg=None):
    topo, _, _, dets = case
    est = LaneCourseEstimator(cfg or LaneConfig(), seed)
    est.initialise(topo, dets)
    est.run(n_samples=n)
    return est


def test_deterministic_per_seed():
    a, b = _run(7).lanelets, _run(7).lanelets
    assert [l.id for l in a] == [l.id for l in b]
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.center, y.center)
        np.testing.assert_array_equal(x.left, y.left)
    # the chain itself depends on the seed (final states, not the best-state snapshot)
    hot = LaneConfig(keep_best=0, temp_start=1.0, temp_end=1.0)
    c, d = _run(7, cfg=hot), _run(8, cfg=hot)
    assert not np.array_equal(c.graph.P, d.graph.P)


def test_generator_seed_and_samples_drawn():
    est = _run(np.random.default_rng(3), n=1234)
    assert est.samples_drawn == 1234
    assert est.run(n_samples=100) == 100 and est.samples_drawn == 1334
    assert est.run(time_budget_s=0.02) > 0


def test_lanelets_are_a_connected_lane_graph():
    topo, _, conns, _ = CASE
    ls = _run(1).lanelets
    by = {l.id: l for l in ls}
    kinds = {k: [l for l in ls if l.kind == k] for k in ('entering', 'leaving', 'connector')}
    assert len(kinds['entering']) == sum(a.lanes_in for a in topo.arms)
    assert len(kinds['leaving']) == sum(a.lanes_out for a in topo.arms)
    # one connector per observed (entering lane, leaving lane) pair, none without evidence
    got = {(c.arm, c.lane_index, c.arm_to, int(c.id.rsplit('_', 1)[1])) for c in kinds['connector']}
    assert got == set(conns)
    for c in kinds['connector']:
        pred = [l for l in kinds['entering'] if c.id in l.successors]
        assert len(pred) == 1 and pred[0].arm == c.arm and len(c.successors) == 1
        succ = by[c.successors[0]]
        assert succ.kind == 'leaving' and succ.arm == c.arm_to
        # consecutive lanelets share end points exactly
        np.testing.assert_array_equal(c.left[0], pred[0].left[-1])
        np.testing.assert_array_equal(c.right[0], pred[0].right[-1])
        np.testing.assert_array_equal(c.left[-1], succ.left[0])
        np.testing.assert_array_equal(c.right[-1], succ.right[0])
    assert len({l.id for l in ls}) == len(ls)


def test_lane_course_close_to_truth():
    """Noise N(0, 1 m): the estimated center lines stay within decimetres of the truth."""
    from intersection_estimator.evaluate import orthogonal_distances, resample
    topo, gt, conns, _ = CASE
    errs = []
    for l in _run(2, n=20000).lanelets:
        if l.kind == 'connector':
            key = (l.arm, l.lane_index, l.arm_to, int(l.id.rsplit('_', 1)[1]))
            truth = conns[key]
        else:
            truth = gt[(l.arm, 1 if l.kind == 'entering' else -1, l.lane_index)]
        d = orthogonal_distances(resample(l.center), truth)
        errs.append(np.nanmean(d))
    assert np.mean(errs) < 0.35


def test_an_initialisation_in_two_halves_is_the_whole_one():
    """``prepare`` then ``finish`` (two ticks apart in the node) build exactly the lanelets
    of ``initialise``; until ``finish`` the previous lane course stands."""
    topo, _, _, dets = CASE
    whole, halves = LaneCourseEstimator(LaneConfig(), 3), LaneCourseEstimator(LaneConfig(), 3)
    whole.initialise(topo, dets)
    halves.prepare(topo, dets)
    assert halves.pending and halves.lanelets == [] and halves.graph is None
    halves.finish()
    assert not halves.pending
    a, b = whole.lanelets, halves.lanelets
    assert [l.id for l in a] == [l.id for l in b] and any(l.kind == 'connector' for l in a)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.center, y.center)


def test_split_at_closest_point_to_center():
    xy = np.array([[10.0, 0.0], [5.0, 0.0], [1.0, 0.5], [0.0, 4.0], [0.0, 9.0]])
    assert split_at_center(xy, np.zeros(2)) == 2


def _crossing_track(topo, beyond_stop: float) -> Trajectory:
    """A vehicle on arm 0's entering lane, straight through the box, on arm 2's leaving
    lane up to ``beyond_stop`` metres past that arm's stop line (1 m apart)."""
    fr, stops = arm_frames(topo), stop_distances(topo, LaneConfig())
    f_in, f_out = fr[0], fr[2]
    s_in = np.arange(50.0, -0.5, -1.0)
    s_out = np.arange(1.0, stops[2] + beyond_stop + 0.01, 1.0)
    xy = np.concatenate([f_in.point(s_in, f_in.lat[(ENTERING, 0)]),
                         f_out.point(s_out, f_out.lat[(LEAVING, 0)])])
    return Trajectory(0, xy)


@pytest.mark.parametrize('beyond', [1.5, 3.0])
def test_a_track_seen_only_a_few_metres_beyond_the_stop_line_still_gets_its_lane(beyond):
    """The stop line is a corner construction, metres out on real junctions: a track that
    leaves the sensor's range just past it keeps its leaving lane (``assign_inside``), and
    with it the connector; counted from the stop line alone (0) it had none."""
    topo = Intersection(center=[0.0, 0.0], arms=[Arm(angle=a, gap=1.0) for a in
                                                   (0.0, np.pi / 2, np.pi, -np.pi / 2)])
    for inside, lane_out in ((0.0, None), (LaneConfig().assign_inside, (2, 0))):
        tr = _crossing_track(topo, beyond)
        assign_parts([tr], topo, LaneConfig(assign_inside=inside))
        assert tr.lane_in == (0, 0) and tr.lane_out == lane_out


def _two_lane_arm():
    """A four-arm junction whose arm along +x has two entering lanes; (topology, that arm's
    index, its stop distance [m])."""
    topo = Intersection(center=[0.0, 0.0], arms=[Arm(angle=0.0, lanes_in=2), Arm(angle=np.pi / 2),
                                                   Arm(angle=np.pi), Arm(angle=-np.pi / 2)])
    a = next(i for i, arm in enumerate(topo.arms) if arm.lanes_in == 2)
    return topo, a, stop_distances(topo, LaneConfig())


def _approach(topo, a: int, s, lat, tid: int = 0) -> Trajectory:
    """A vehicle on arm ``a`` (along +x) at axis distances ``s`` and lateral positions
    ``lat``, then across the box (-x)."""
    f = arm_frames(topo)[a]
    return Trajectory(tid, np.concatenate([f.point(s, lat), np.stack([-np.arange(1.0, 40.0), np.zeros(39)], 1)]))


def test_an_entering_part_takes_the_lane_it_drives_at_the_stop_line():
    """``assign_reach``: a vehicle that drives entering lane 1 far out and changes into lane 0
    (a turn pocket) 25-30 m before the stop line belongs to the pocket lane, where its turn
    starts; the mean of its whole part (paper §III-A, ``assign_reach`` inf) lies on the lane it
    drove far out, which it left."""
    topo, a, stops = _two_lane_arm()
    f = arm_frames(topo)[a]
    s = np.arange(110.0, -0.5, -1.0)
    lat = np.interp(s, [stops[a] + 25.0, stops[a] + 30.0], [f.lat[(ENTERING, 0)], f.lat[(ENTERING, 1)]])
    for reach, lane in ((LaneConfig().assign_reach, (a, 0)), (float('inf'), (a, 1))):
        tr = _approach(topo, a, s, lat)
        assign_parts([tr], topo, LaneConfig(assign_reach=reach))
        assert tr.lane_in == lane


def test_the_lanes_are_fitted_where_their_parts_were_assigned():
    """``fit_frames`` places an entering lane by the same window as the assignment: an
    approach whose traffic drifts up to 4 m sideways beyond 35 m (a curve) leaves the lane where
    the vehicles drive next to the stop line; the whole parts' mean put it 1 m off."""
    topo, a, stops = _two_lane_arm()
    lat0 = arm_frames(topo)[a].lat[(ENTERING, 0)]
    s = np.arange(stops[a] + 70.0, -0.5, -1.0)
    lat = lat0 + np.interp(s, [stops[a] + 35.0, stops[a] + 70.0], [0.0, 4.0])
    trajs = [_approach(topo, a, s, lat, k) for k in range(4)]
    got = {}
    for reach in (LaneConfig().assign_reach, float('inf')):
        cfg = LaneConfig(assign_reach=reach, max_refit_angle_deg=0.0)   # lane positions only
        assign_parts(trajs, topo, cfg, stops)
        assert all(tr.lane_in == (a, 0) for tr in trajs)
        got[reach] = fit_frames(topo, trajs, stops, cfg)[a].lat[(ENTERING, 0)]
    assert abs(got[LaneConfig().assign_reach] - lat0) < 0.05
    assert got[float('inf')] - lat0 > 0.5


def test_trajectories_sorted_by_time_and_ignore_untracked():
    d = Detections.make([[0, 0], [1, 0], [2, 0], [5, 5]], t=[2.0, 1.0, 3.0, 0.0],
                        track_id=[4, 4, 4, -1])
    (tr,) = trajectories(d)
    np.testing.assert_array_equal(tr.xy[:, 0], [1, 0, 2])


@pytest.mark.parametrize('dets', [None, Detections.empty(),
                                  Detections.make([[1.0, 2.0], [3.0, 4.0]], track_id=[-1, -1])])
def test_no_trajectories_gives_straight_lanes(dets):
    topo = CASE[0]
    est = LaneCourseEstimator(LaneConfig(), 0)
    est.initialise(topo, dets)
    assert est.run(n_samples=500) == 500
    ls = est.lanelets
    assert len(ls) == topo.n_lanes and all(l.kind != 'connector' for l in ls)
    assert all(np.isfinite(l.center).all() for l in ls)


def test_one_trajectory():
    topo, _, _, dets = CASE
    one = dets.subset(dets.track_id == 0)
    est = LaneCourseEstimator(LaneConfig(), 0)
    est.initialise(topo, one)
    est.run(n_samples=2000)
    ls = est.lanelets
    assert sum(l.kind == 'connector' for l in ls) == 1
    assert all(np.isfinite(l.center).all() for l in ls)


def test_empty_topology():
    est = LaneCourseEstimator(LaneConfig(), 0)
    est.initialise(Intersection(center=[0.0, 0.0], arms=[]), CASE[3])
    assert est.run(n_samples=100) == 0 and est.lanelets == []


def test_warm_start_keeps_the_chain():
    topo, _, _, dets = CASE
    est = LaneCourseEstimator(LaneConfig(), 0)
    est.initialise(topo, dets)
    est.run(n_samples=2000)
    g = est.graph
    est.initialise(topo, dets)               # same topology and connectors: keep going
    assert est.graph is g
    moved = Intersection(center=topo.center + 3.0, arms=topo.arms)
    est.initialise(moved, dets)              # topology changed: re-initialise
    assert est.graph is not g


def test_lanelets_from_topology():
    topo = Intersection(center=[1.0, 2.0], arms=[Arm(0.0, 1.0, 2, 1), Arm(2.0, 0.0, 1, 1),
                                                 Arm(-2.0, 0.5, 1, 3)])
    ls = lanelets_from_topology(topo, length=50.0)
    assert len(ls) == topo.n_lanes and {l.kind for l in ls} == {'entering', 'leaving'}
    for l in ls:
        assert abs(np.linalg.norm(l.center[-1] - l.center[0]) - 50.0) < 1e-6
        a = topo.arms[l.arm]
        v = (l.center[-1] - l.center[0]) / 50.0
        assert np.allclose(v, -a.direction if l.kind == 'entering' else a.direction)


def test_connector_initial_shape_is_the_arc_bezier():
    """Without the traffic fit (``connector_traffic`` 0) and the start's refinement
    (``refine_init`` 0) connectors start on the arc-like Bezier tangent to their lanes
    (equidistant stations)."""
    from intersection_estimator.lanes.init import arc_bezier
    from intersection_estimator.evaluate import orthogonal_distances
    topo, _, _, dets = CASE
    est = LaneCourseEstimator(LaneConfig(stop_fit=0, connector_traffic=0, refine_init=0), 0)
    est.initialise(topo, dets)
    ls = {l.id: l for l in est.lanelets}
    for c in (l for l in ls.values() if l.kind == 'connector'):
        e = next(l for l in ls.values() if c.id in l.successors)
        o = ls[c.successors[0]]
        t0 = e.center[-1] - e.center[-2]
        t1 = o.center[1] - o.center[0]
        ref = arc_bezier(e.center[-1], t0 / np.linalg.norm(t0), o.center[0],
                         t1 / np.linalg.norm(t1), np.linspace(0, 1, 400))
        assert np.nanmax(orthogonal_distances(c.center, ref)) < 0.02
        step = np.linalg.norm(np.diff(c.center[::2], axis=0), axis=1)
        assert step.max() - step.min() < 0.1 * step.mean()


def test_skipped_labels_stay_out_of_the_lane_course_trajectories():
    """``LaneConfig.skip_labels``: a cyclist's track (Autoware 6) is not a lane trajectory,
    a car's is; with ``()`` both are."""
    from intersection_estimator.lanes.init import trajectories
    from intersection_estimator.observations import Detections
    x = np.arange(-40.0, 40.0, 1.0)
    xy = np.concatenate([np.column_stack([x, np.full_like(x, -1.75)]),
                         np.column_stack([x, np.full_like(x, -3.2)])])
    tid = np.r_[np.zeros(len(x), int), np.ones(len(x), int)]
    label = np.r_[np.full(len(x), 1), np.full(len(x), 6)]
    dets = Detections.make(xy, t=np.r_[x, x] * 0.1, heading=0.0, track_id=tid, label=label)
    assert [t.track_id for t in trajectories(dets, (6, 7))] == [0]
    assert [t.track_id for t in trajectories(dets)] == [0, 1]
