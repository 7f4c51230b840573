"""Arms that the posterior nearly pays for (beyond the paper, topology/weak_arms.py): a road
one vehicle drove out of is added when the state with it is within ``weak_arm_nats`` of
the state without, a false track far out and a neighbouring arm's traffic never make one,
and the reported estimate takes it."""

import copy
from dataclasses import replace
import math

import numpy as np
import pytest

from intersection_estimator.model import ENTERING, LEAVING
from intersection_estimator.observations import Detections
from intersection_estimator.topology import TopologyConfig, TopologyEstimator
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.mcmc import Posterior
from intersection_estimator.topology.side_by_side import tracks_of
from intersection_estimator.topology.state import HDR, NARMS, STRIDE, WID, arm_angles, pack_state
from intersection_estimator.topology.support import reported
from intersection_estimator.topology.unexplained import best_new_arm, unexplained_angles
from intersection_estimator.topology.weak_arms import add_weak_arms, box_tracks, near_tracks

from .scenes import EASY, _lane_point, trajectories

CFG = TopologyConfig(chains_tracked=1)
GT = EASY[0]
LONE = 1          # the arm only one vehicle drives (out of the junction)


def _path(points, rng, tid, noise=0.3):
    xy = np.asarray(points) + rng.normal(0.0, noise, (len(points), 2))
    d = np.gradient(np.asarray(points), axis=0)
    return Detections.make(xy, np.arange(len(xy)) * 0.1, heading=np.arctan2(d[:, 1], d[:, 0]),
                           track_id=tid)


def _lone_vehicle(rng, tid, far=60.0):
    """In on arm 0, through the box, out on arm ``LONE``'s leaving lane up to ``far`` m."""
    a, b = GT.arms[0], GT.arms[LONE]
    p_in = [_lane_point(GT, a, ENTERING, 0, s) for s in np.arange(60.0, 12.0, -1.0)]
    p_out = [_lane_point(GT, b, LEAVING, 0, s) for s in np.arange(12.0, far, 1.0)]
    mid = [p_in[-1] + f * (p_out[0] - p_in[-1]) for f in np.linspace(0, 1, 20)[1:-1]]
    return _path(p_in + mid + p_out, rng, tid)


def _dets(extra=()):
    """The traffic of GT without arm ``LONE`` (2 vehicles per lane) plus ``extra``."""
    rng = np.random.default_rng(5)
    three = copy.deepcopy(GT)
    del three.arms[LONE]
    paths = trajectories(three, rng, per_lane=2)
    parts = [_path(xy, rng, tid) for tid, (xy, _) in enumerate(paths)]
    return Detections.concat(parts + [f(rng, 1000 + i) for i, f in enumerate(extra)])


def _posterior(dets, cfg=CFG):
    est = TopologyEstimator(cfg, seed=0)
    est.set_observations(dets)
    return Posterior(Tables(cfg), est.observations)


def _three_arms():
    three = copy.deepcopy(GT)
    del three.arms[LONE]
    return pack_state(three)


def _gap_deg(a, b):
    return abs(math.degrees(math.remainder(a - b, 2 * math.pi)))


def _drop(post, S):
    """How far the best candidate arm over the unexplained parts lies below ``S``."""
    phi, = unexplained_angles(S, post, CFG, min_support=1.0, max_angles=1)
    return post(S) - post(best_new_arm(S, phi, post, CFG))


def test_a_road_one_vehicle_drove_is_added_within_the_nats():
    dets = _dets([_lone_vehicle])
    post, tr, S = _posterior(dets), tracks_of(dets), _three_arms()
    drop = _drop(post, S)
    assert drop > 0          # one passage does not pay for an arm's prior: the MAP lacks it
    yes = replace(CFG, weak_arm_nats=drop + 0.1)
    S2, L2 = add_weak_arms(post, S, post(S), yes, tr)
    assert int(S2[NARMS]) == 4 and L2 == pytest.approx(post(S2))
    assert min(_gap_deg(a, GT.arms[LONE].angle) for a in arm_angles(S2)) < 6.0
    no = replace(CFG, weak_arm_nats=drop - 0.1)
    assert int(add_weak_arms(post, S, post(S), no, tr)[0][NARMS]) == 3
    off = replace(CFG, weak_arm_nats=0.0)
    assert add_weak_arms(post, S, post(S), off, tr)[0] is S


def test_the_vehicle_must_drive_the_arm_across_the_box_line():
    """The lone vehicle crosses the line 25 m out on the new arm; traffic of the other arms
    (another heading) never counts for it; a vehicle that leaves the sensor at 20 m does
    not cross."""
    dets = _dets([_lone_vehicle])
    post, tr, S = _posterior(dets), tracks_of(dets), _three_arms()
    S2, _ = add_weak_arms(post, S, post(S), replace(CFG, weak_arm_nats=50.0), tr)
    k = int(S2[NARMS]) - 1
    assert box_tracks(S2, k, tr, 12.0, 25.0) == 1
    assert box_tracks(S2, k, tr, 12.0, 80.0) == 0       # nothing beyond 80 m
    short = tracks_of(_dets([lambda rng, tid: _lone_vehicle(rng, tid, far=20.0)]))
    assert box_tracks(S2, k, short, 12.0, 25.0) == 0


def test_a_false_track_far_out_makes_no_arm_however_cheap():
    """Two tracks 55-75 m out along arm ``LONE`` (a false track, a neighbouring road): the
    posterior may pay for an arm there, the rule never adds it."""
    def far_track(rng, tid):
        b = GT.arms[LONE]
        return _path([_lane_point(GT, b, LEAVING, 0, s) for s in np.arange(55.0, 75.0, 1.0)],
                     rng, tid)
    dets = _dets([far_track, far_track])
    post, tr, S = _posterior(dets), tracks_of(dets), _three_arms()
    assert unexplained_angles(S, post, CFG, min_support=1.0)
    S2, _ = add_weak_arms(post, S, post(S), replace(CFG, weak_arm_nats=50.0), tr)
    assert int(S2[NARMS]) == 3


def test_the_reported_estimate_takes_the_arm_with_tracks_only():
    dets = _dets([_lone_vehicle])
    post, tr, S = _posterior(dets), tracks_of(dets), _three_arms()
    cfg = replace(CFG, weak_arm_nats=_drop(post, S) + 0.1)
    S2, conf, lpost = reported(post, S, post(S), cfg, tr)
    assert int(S2[NARMS]) == 4 and lpost == pytest.approx(post(S2))
    assert len(conf) == 4 and 0.0 < min(conf) < 0.5      # one passage: a weak arm
    assert int(reported(post, S, post(S), cfg)[0][NARMS]) == 3


def test_a_box_line_inside_part_outside_is_refused_by_name():
    with pytest.raises(ValueError, match='weak_arm_box'):
        TopologyConfig(weak_arm_box=10.0).validate()        # part_outside is 12 m
    TopologyConfig(weak_arm_box=30.0).validate()


def test_a_road_seen_only_next_to_the_box_has_near_tracks_but_no_box_tracks():
    """A vehicle that leaves the sensor 20 m out on arm ``LONE`` drove it next to the box
    (``near_tracks``) without crossing the 25 m line (``box_tracks``); the other arms'
    traffic (another heading) counts for neither."""
    S = pack_state(GT)
    short = tracks_of(_dets([lambda rng, tid: _lone_vehicle(rng, tid, far=20.0)]))
    assert near_tracks(S, LONE, short, 12.0, 25.0, 3) == 1
    assert box_tracks(S, LONE, short, 12.0, 25.0) == 0
    assert near_tracks(S, LONE, tracks_of(_dets()), 12.0, 25.0, 3) == 0
    assert near_tracks(S, LONE, short, 12.0, 25.0, 100) == 0      # too few rows


def test_near_tracks_counts_only_traffic_within_reach_of_the_arms_lanes():
    """A vehicle driving along arm ``LONE`` 1.5 lane widths beyond the outer edge of its
    entering lanes (its wider side; another road beside it, a curved neighbouring approach)
    drove beside the arm, not along it: it counts with ``reach`` 2 lane widths and not with
    1 (``empty_arm_reach``; SUMO seed 118: a phantom arm kept by one track 2 lanes beyond
    its lanes)."""
    S = pack_state(GT)
    b = GT.arms[LONE]
    assert b.lanes_in > b.lanes_out
    w = float(S[HDR + LONE * STRIDE + WID])               # the arm's lane width in the state
    offsets = b.lane_offsets(ENTERING, GT.traffic_side)
    edge = float(np.abs(offsets).max()) + 0.5 * w
    side = np.sign(offsets[0])

    def beside(rng, tid):
        pts = [GT.center + s * b.direction + side * (edge + 1.5 * w) * b.normal
               for s in np.arange(13.0, 24.0, 1.0)]
        return _path(pts, rng, tid, noise=0.05)
    tr = tracks_of(_dets([beside]))
    assert near_tracks(S, LONE, tr, 12.0, 25.0, 3, reach=2.0) == 1
    assert near_tracks(S, LONE, tr, 12.0, 25.0, 3, reach=1.0) == 0
