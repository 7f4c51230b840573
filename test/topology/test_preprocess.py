"""Preprocessing (paper §II-A): Doppler direction, clutter filter, voxels, trajectory split."""

from dataclasses import replace
import math

import numpy as np

from intersection_estimator.observations import Detections
from intersection_estimator.topology.init import initial_center, seed_lines
from intersection_estimator.topology.preprocess import (heading_observations, preprocess,
                                                        radar_observations,
                                                        tracked_observations)

from .scenes import LEGACY_PREPROCESS as CFG, easy_intersection, scene


def test_straight_trajectory_splits_at_closest_point():
    """A vehicle crossing straight through the center gives one entering and one leaving
    part with the mean point on each side and the driving direction."""
    x = np.arange(-50.0, 50.5, 1.0)
    xy = np.stack([x, np.full_like(x, -1.75)], axis=1)
    dets = Detections.make(xy, t=np.arange(len(x)) * 0.1, heading=0.0, track_id=7)
    obs = tracked_observations(dets, (0.0, 0.0), CFG)
    assert len(obs) == 2
    i_in = int(np.argmin(obs.x))
    assert obs.x[i_in] < -20 and obs.x[1 - i_in] > 20
    assert np.allclose(obs.y, -1.75) and np.allclose(obs.hx, 1.0) and np.allclose(obs.hy, 0.0)
    assert obs.d[i_in] == 1.0 and obs.d[1 - i_in] == -1.0     # entering, then leaving


def test_turn_is_trimmed_from_the_part():
    """Entering along +x toward the center, then turning left: the entering part's mean
    stays on the straight lane (the arc inside the box is trimmed)."""
    s = np.arange(60.0, 10.0, -1.0)
    p_in = np.stack([s, np.full_like(s, 1.75)], axis=1)
    phi = np.linspace(-math.pi / 2, 0.0, 20)
    arc = np.stack([10.0 * np.cos(phi) + 0.0, 10.0 * np.sin(phi) + 11.75], axis=1)[::-1] * [1, 1]
    arc = np.stack([10.0 - 10.0 * np.sin(np.linspace(0, math.pi / 2, 20)),
                    1.75 + 10.0 * (1 - np.cos(np.linspace(0, math.pi / 2, 20)))], axis=1)
    xy = np.concatenate([p_in, arc])
    d = np.gradient(xy, axis=0)
    dets = Detections.make(xy, t=np.arange(len(xy)) * 0.1, heading=np.arctan2(d[:, 1], d[:, 0]),
                           track_id=1)
    trimmed = tracked_observations(dets, (0.0, 0.0), CFG)
    whole = tracked_observations(dets, (0.0, 0.0), replace(CFG, trim_turn_deg=0.0))
    k = int(np.argmax(trimmed.x))
    assert abs(trimmed.y[k] - 1.75) < 0.05 and abs(trimmed.hy[k]) < 0.05
    assert abs(whole.y[int(np.argmax(whole.x))] - 1.75) > abs(trimmed.y[k] - 1.75)


def test_part_outside_keeps_the_approach_of_a_vehicle_seen_near_the_box_only():
    """A vehicle seen from 32 m before to 32 m after the center: its parts' means lie
    ~16 m out and are dropped as vehicles in the box (``min_center_dist`` 20 m); with
    ``part_outside`` 20 m each part is its rows beyond 20 m, counted from the far end,
    and both survive on the lane. A long track's parts only lose their inner rows."""
    cfg = replace(CFG, min_center_dist=20.0, track_radius=math.inf)   # whole parts (paper)
    x = np.arange(-32.0, 32.5, 1.0)
    xy = np.stack([x, np.full_like(x, -1.75)], axis=1)
    dets = Detections.make(xy, t=np.arange(len(x)) * 0.1, heading=0.0, track_id=3)
    assert len(tracked_observations(dets, (0.0, 0.0), cfg)) == 0
    obs = tracked_observations(dets, (0.0, 0.0), replace(cfg, part_outside=20.0))
    assert len(obs) == 2
    assert sorted(np.round(obs.x, 6)) == [-26.0, 26.0]     # means of the rows 20..32 m out
    assert np.allclose(obs.y, -1.75) and sorted(obs.d) == [-1.0, 1.0]
    x = np.arange(-80.0, 80.5, 1.0)
    long = Detections.make(np.stack([x, np.full_like(x, -1.75)], axis=1),
                           t=np.arange(len(x)) * 0.1, heading=0.0, track_id=4)
    obs = tracked_observations(long, (0.0, 0.0), replace(cfg, part_outside=20.0))
    assert sorted(np.round(obs.x, 6)) == [-50.0, 50.0]


def test_part_pieces_keep_a_curved_approach():
    """With ``part_piece_m`` 10 m a 60 m approach that bends by 30 deg gives six means
    along the curve, each 1/6 of the part (the part weighs one vehicle passage, as
    without pieces), each within 0.3 m of the path and with its local direction; one mean
    for the whole part lies metres inside the curve."""
    s = np.arange(0.0, 60.5, 0.5)
    head = np.radians(30.0) * np.clip(s / 60.0, 0.0, 1.0)
    path = np.cumsum(0.5 * np.stack([np.cos(head), np.sin(head)], axis=1), axis=0)
    xy = (path - path[-1])[::-1] - [12.0, 0.0]      # entering, toward the center at the origin
    hd = head[::-1] + math.pi
    dets = Detections.make(np.concatenate([xy, [[0.0, 0.0]]]), t=np.arange(len(xy) + 1) * 0.1,
                           heading=np.r_[hd, hd[-1]], track_id=2)
    cfg = replace(CFG, part_outside=10.0, trim_turn_deg=0.0)
    one = tracked_observations(dets, (0.0, 0.0), cfg)
    obs = tracked_observations(dets, (0.0, 0.0), replace(cfg, part_piece_m=10.0))
    assert len(one) == 1 and len(obs) == 6
    assert np.allclose(obs.w, 1.0 / 6.0) and np.allclose(obs.passages, 1.0 / 6.0)
    gap = [np.min(np.hypot(*(xy - p).T)) for p in obs.xy]
    assert max(gap) < 0.3 < np.min(np.hypot(*(xy - one.xy[0]).T))
    turn = np.degrees(np.abs(np.diff(np.unwrap(np.arctan2(obs.hy, obs.hx)))))
    assert turn.sum() > 20.0


def test_static_false_tracks_are_dropped():
    rng = np.random.default_rng(0)
    xy = rng.normal([30.0, 5.0], 0.8, (4, 2))
    dets = Detections.make(xy, t=np.arange(4) * 0.1, heading=rng.uniform(-3, 3, 4), track_id=99)
    assert len(tracked_observations(dets, (0.0, 0.0), CFG)) == 0


def _radar(xy, dop, sensor, rcs=10.0):
    return Detections.make(np.asarray(xy, float), doppler=dop, sensor_xy=sensor, rcs=rcs)


def test_doppler_direction_rule_with_line_of_sight():
    """Sensor on the arm at (30, -1.75) looking toward the center at (0, 0)."""
    sensor = (30.0, -1.75)
    cfg = replace(CFG, voxel_size=0.5)
    # ahead of the sensor (between sensor and center): moving toward the center = toward
    # the sensor's look direction = away from the sensor -> doppler > 0 -> entering
    ahead = radar_observations(_radar([[15.0, 1.75]], 5.0, sensor), (0.0, 0.0), cfg)
    assert ahead.d.tolist() == [1.0]
    # behind the sensor: the paper's rule flips
    behind = radar_observations(_radar([[50.0, 1.75]], 5.0, sensor), (0.0, 0.0), cfg)
    assert behind.d.tolist() == [-1.0]
    # beyond the center on the opposite arm: moving away from the sensor = leaving
    far = radar_observations(_radar([[-30.0, -1.75]], 5.0, sensor), (0.0, 0.0), cfg)
    assert far.d.tolist() == [-1.0]
    # cross traffic seen at a right angle: direction unknown (d = 0), or dropped
    side = radar_observations(_radar([[15.0, 15.0]], 5.0, (30.0, 0.0)), (0.0, 0.0),
                              replace(CFG, min_radial_cos=0.25))
    assert side.d.tolist() == [0.0]
    side = radar_observations(_radar([[15.0, 15.0]], 5.0, (30.0, 0.0)), (0.0, 0.0),
                              replace(CFG, min_radial_cos=0.25, keep_unknown_direction=False))
    assert len(side) == 0


def test_radar_clutter_filter():
    sensor = (30.0, 0.0)
    dets = Detections.concat([_radar([[10.0, 2.0]], 0.1, sensor, rcs=-5),   # static clutter
                              _radar([[10.0, 2.0]], 6.0, sensor, rcs=-10),  # weak
                              _radar([[12.0, 2.0]], 6.0, sensor, rcs=np.nan),
                              _radar([[14.0, 2.0]], 6.0, sensor),
                              _radar([[16.0, 2.0]], 0.1, sensor, rcs=12)])  # slow vehicle
    obs = radar_observations(dets, (0.0, 0.0), replace(CFG, voxel_size=1.0))
    assert sorted(zip(obs.x.round(1).tolist(), obs.d.tolist())) == [(12.0, 1.0), (14.0, 1.0),
                                                                    (16.0, 0.0)]


def test_heading_detections_are_voxelised_with_their_heading():
    xy = np.array([[20.0, 1.0], [20.4, 1.2], [20.2, 1.1], [-20.0, -1.0]])
    h = np.array([2.9, 2.85, 2.95, math.pi])
    obs = heading_observations(Detections.make(xy, heading=h), (0.0, 0.0),
                               replace(CFG, voxel_size=2.0))
    assert len(obs) == 2
    k = int(np.argmax(obs.x))
    assert obs.w[k] == 3.0 * obs.w[1 - k] and abs(math.atan2(obs.hy[k], obs.hx[k]) - 2.9) < 1e-3
    assert obs.d[k] == 1.0 and obs.d[1 - k] == -1.0   # toward / away from the center


def test_empty_and_degenerate_inputs():
    empty = Detections.empty()
    assert len(preprocess(empty, (0, 0), CFG)) == 0
    assert initial_center(*seed_lines(empty, CFG)) is None
    one = Detections.make([[1.0, 2.0]], heading=0.0, track_id=0)
    assert len(preprocess(one, (0, 0), CFG)) == 0


def _corridor_weight(obs, center, angle, reach=12.0):
    """Observation weight within ``reach`` of the ray from ``center`` at ``angle``, beyond 10 m."""
    v = np.stack([obs.x - center[0], obs.y - center[1]], axis=1)
    s = v @ np.array([math.cos(angle), math.sin(angle)])
    t = v @ np.array([-math.sin(angle), math.cos(angle)])
    return float(obs.w[(s > 10.0) & (np.abs(t) < reach)].sum())


def test_an_arm_the_chain_has_not_found_keeps_its_radar_and_heading_data():
    """Rows on no current arm are voxelised along rays, not along a neighbouring arm, where
    the straight-run filter used to drop them all: the chain could never add that arm."""
    inter = easy_intersection(4, lanes=((2, 2),) * 4)
    angles = [a.angle for a in inter.arms]
    for mode, fn in (('raw', radar_observations), ('heading', heading_observations)):
        dets = scene(inter, mode, seed=3)
        full = fn(dets, inter.center, CFG, angles)
        for k in range(len(angles)):
            missing = fn(dets, inter.center, CFG, angles[:k] + angles[k + 1:])
            w_full = _corridor_weight(full, inter.center, angles[k])
            assert w_full > 0
            assert _corridor_weight(missing, inter.center, angles[k]) > 0.5 * w_full, (mode, k)








def _curved_approach():
    """A vehicle driving toward the center (0, 0) along +x's lane at y = -1.75 for its last
    60 m, on a road that bends away by 30 deg beyond 60 m (a curved approach)."""
    near = np.stack([np.arange(60.0, 20.0, -1.0), np.full(40, -1.75)], axis=1)
    a = math.radians(30.0)
    far = near[0] + np.outer(np.arange(60.0, 0.0, -1.0), [math.cos(a), math.sin(a)])
    xy = np.concatenate([far, near])
    d = np.gradient(xy, axis=0)
    return Detections.make(xy, t=np.arange(len(xy)) * 0.1, heading=np.arctan2(d[:, 1], d[:, 0]),
                           track_id=3)


def test_track_radius_keeps_the_part_next_to_the_box():
    """Beyond the paper: the part's mean point and direction from the rows within
    track_radius describe the straight piece of a curved approach; without it the bend
    pulls them off the lane."""
    dets = _curved_approach()
    whole = tracked_observations(dets, (0.0, 0.0), replace(CFG, min_center_dist=20.0, track_radius=math.inf,
                                                           trim_longest=False))
    near = tracked_observations(dets, (0.0, 0.0), replace(CFG, min_center_dist=20.0, track_radius=65.0,
                                                               trim_longest=True))
    assert len(whole) == len(near) == 1
    assert abs(near.y[0] + 1.75) < 0.05 and abs(near.hy[0]) < 0.02
    assert abs(whole.y[0] + 1.75) > 1.0 or abs(whole.hy[0]) > 0.1
    # each alone is not enough: the radius keeps part of the bend, which the far-end run keeps
    first = tracked_observations(dets, (0.0, 0.0), replace(CFG, min_center_dist=20.0, track_radius=65.0,
                                                           trim_longest=False))
    assert abs(first.y[0] + 1.75) > 1.0 or abs(first.hy[0]) > 0.1
    # no row within the radius: no part
    assert len(tracked_observations(dets, (500.0, 0.0), replace(CFG, track_radius=30.0))) == 0


def test_max_center_dist_bounds_the_ring_of_voxel_observations():
    I = easy_intersection(center=(0.0, 0.0))
    dets = scene(I, 'heading', seed=4)
    ring = heading_observations(dets, (0.0, 0.0), replace(CFG, min_center_dist=10.0, max_center_dist=40.0))
    r = np.hypot(ring.x, ring.y)
    assert len(ring) and r.min() >= 10.0 and r.max() <= 40.0
    free = heading_observations(dets, (0.0, 0.0), replace(CFG, min_center_dist=10.0))
    assert np.hypot(free.x, free.y).max() > 40.0
