"""Vehicles that stand through the recording (beyond the paper, topology/standing.py): a
queue heading into the box is evidence of its arm at ``sigma_track_weak`` across; short
clutter tracks, vehicles in the box, standing pedestrians and moving tracks are not; and an
arm whose only traffic is a standing queue is found with it and missed without it."""

import copy
from dataclasses import replace
import math

import numpy as np

from intersection_estimator.model import ENTERING
from intersection_estimator.observations import Detections
from intersection_estimator.topology import PreprocessConfig, TopologyConfig, TopologyEstimator
from intersection_estimator.topology.preprocess import moving_mask, preprocess, track_bounds
from intersection_estimator.topology.standing import standing_observations, standing_tracks

from .scenes import EASY, _lane_point, trajectories

GT = EASY[0]
QUEUE_ARM = 1
CFG = PreprocessConfig(standing_weight=1.0)


def _standing(xy, heading, tid, rng, seconds=30.0, noise=1.0, label=0):
    """One vehicle standing at ``xy`` for ``seconds`` at 10 Hz, speed below 1 m/s."""
    n = int(seconds * 10)
    p = np.asarray(xy, float) + rng.normal(0.0, noise, (n, 2))
    return Detections.make(p, np.arange(n) * 0.1, heading=heading + rng.normal(0, 0.05, n),
                           track_id=tid, speed=rng.uniform(0.0, 0.9, n), label=label)


def _queue(rng, tid0=500, n=5):
    """``n`` vehicles standing on arm QUEUE_ARM's entering lane, 14-46 m out, facing the box."""
    arm = GT.arms[QUEUE_ARM]
    return [_standing(_lane_point(GT, arm, ENTERING, 0, 14.0 + 8.0 * k), arm.angle + math.pi,
                      tid0 + k, rng) for k in range(n)]


def _driven(inter, rng, per_lane):
    """Moving tracks (10 m/s, 0.3 m noise) over every lane of ``inter``."""
    return [Detections.make(xy + rng.normal(0, 0.3, xy.shape), np.arange(len(xy)) * 0.1,
                            heading=hd, track_id=k, speed=10.0)
            for k, (xy, hd) in enumerate(trajectories(inter, rng, per_lane))]


def _obs(dets, cfg=CFG, moving=()):
    """standing_observations of ``dets`` with the track ids ``moving`` taken as moving."""
    order, starts, ends = track_bounds(dets, dets.track_id >= 0)
    still = ~np.isin(dets.track_id[order[starts]], np.asarray(moving, np.int64))
    return standing_observations(dets, GT.center, order, starts, ends, still, cfg)


def test_a_standing_queue_becomes_weak_entering_observations():
    rng = np.random.default_rng(0)
    dets = Detections.concat(_queue(rng))
    obs = _obs(dets)
    assert len(obs) == 5
    assert np.all(obs.d == 1.0) and np.all(obs.has_o)
    assert np.allclose(obs.sigma, CFG.sigma_track_weak) and np.allclose(obs.w, 1.0)
    lane = np.array([_lane_point(GT, GT.arms[QUEUE_ARM], ENTERING, 0, 14.0 + 8.0 * k)
                     for k in range(5)])
    assert np.abs(np.stack([obs.x, obs.y], 1) - lane).max() < 0.5
    # on by default, off with weight 0, and a moving id is not standing
    assert len(_obs(dets, PreprocessConfig())) == 5
    assert len(_obs(dets, replace(CFG, standing_weight=0.0))) == 0
    assert len(_obs(dets, moving=[500, 501])) == 3
    # the speed test of the trajectory parts finds them static
    order, starts, _ = track_bounds(dets, dets.track_id >= 0)
    assert not moving_mask(dets, order, starts, CFG.min_track_speed).any()


def test_clutter_pedestrians_and_vehicles_in_the_box_are_not_standing_traffic():
    rng = np.random.default_rng(1)
    arm = GT.arms[QUEUE_ARM]
    far = _lane_point(GT, arm, ENTERING, 0, 30.0)
    dets = Detections.concat([
        _standing(far, arm.angle + math.pi, 1, rng, seconds=1.0),            # clutter: 1 s
        _standing(far, arm.angle + math.pi, 2, rng, label=7),                # pedestrian
        _standing(GT.center + 3.0, 0.0, 3, rng),                             # in the box
        _standing(GT.center + 200.0, 0.0, 4, rng)])                          # far away
    order, starts, ends = track_bounds(dets, dets.track_id >= 0)
    xy, _, label = standing_tracks(dets, order, starts, ends, np.ones(4, bool), CFG.standing_min_s)
    assert len(xy) == 3 and label.tolist() == [7, 0, 0]
    assert len(_obs(dets)) == 0


def test_a_queue_seen_for_a_few_seconds_counts_but_not_flickering_tracks():
    """A recording car passes a queue: each waiting vehicle is tracked for 2-3 s only
    (AV2 scenario 2's side street; docs/real_junctions.md, "Queues seen for two seconds").
    Such tracks count from ``standing_min_s`` (2 s) on; tracks of one second do not."""
    arm = GT.arms[QUEUE_ARM]

    def queue(seconds):
        rng = np.random.default_rng(3)
        return Detections.concat([
            _standing(_lane_point(GT, arm, ENTERING, 0, 14.0 + 7.0 * k), arm.angle + math.pi,
                      600 + k, rng, seconds=seconds) for k in range(3)])
    assert PreprocessConfig().standing_min_s == 2.0
    assert len(_obs(queue(2.5), PreprocessConfig())) == 3
    assert len(_obs(queue(1.0), PreprocessConfig())) == 0
    assert len(_obs(queue(2.5), replace(PreprocessConfig(), standing_min_s=3.0))) == 0


def test_only_vehicles_queued_towards_the_box_count():
    rng = np.random.default_rng(5)
    arm = GT.arms[QUEUE_ARM]
    lone = [_standing(_lane_point(GT, arm, ENTERING, 0, 30.0), arm.angle + math.pi, 1, rng)]
    away = [_standing(_lane_point(GT, arm, ENTERING, 0, 20.0 + 8.0 * k), arm.angle, 10 + k, rng)
            for k in range(3)]                                  # a row facing away from the box
    apart = [_standing(_lane_point(GT, arm, ENTERING, 0, 15.0 + 25.0 * k), arm.angle + math.pi,
                       20 + k, rng) for k in range(2)]           # 25 m apart: no queue
    for dets in (lone, away, apart):
        assert len(_obs(Detections.concat(dets))) == 0
    alone = replace(CFG, standing_queue=1)
    assert len(_obs(Detections.concat(lone), alone)) == 1
    assert len(_obs(Detections.concat(apart), alone)) == 2
    assert len(_obs(Detections.concat(away), alone)) == 0
    # a queue is the whole line: with 3 asked for, two vehicles are none, four are four
    three = replace(CFG, standing_queue=3)
    assert len(_obs(Detections.concat(_queue(rng, n=2)), three)) == 0
    assert len(_obs(Detections.concat(_queue(rng, n=4)), three)) == 4


def test_preprocess_adds_standing_vehicles_beside_the_trajectory_parts():
    rng = np.random.default_rng(2)
    dets = Detections.concat(_driven(GT, rng, per_lane=1) + _queue(rng))
    base = preprocess(dets, GT.center, replace(CFG, standing_weight=0.0))
    more = preprocess(dets, GT.center, CFG)
    assert len(more) == len(base) + 5
    assert np.count_nonzero(more.sigma == CFG.sigma_track_weak) == 5


def _without_queue_arm_traffic(rng):
    """GT's traffic with arm QUEUE_ARM driven by nobody, plus a standing queue on it."""
    three = copy.deepcopy(GT)
    del three.arms[QUEUE_ARM]
    return Detections.concat(_driven(three, rng, per_lane=2) + _queue(rng, n=6))


def _arm_found(cfg) -> bool:
    est = TopologyEstimator(cfg, seed=0)
    est.set_observations(_without_queue_arm_traffic(np.random.default_rng(4)))
    est.run(n_samples=3000)
    want = GT.arms[QUEUE_ARM].angle
    return any(abs((a.angle - want + math.pi) % (2 * math.pi) - math.pi) < math.radians(10)
               for a in est.best.arms)


def test_an_arm_only_a_standing_queue_shows_is_found_with_it_and_missed_without():
    cfg = TopologyConfig(chains_tracked=1)
    assert not _arm_found(replace(cfg, standing_weight=0.0))
    assert _arm_found(replace(cfg, standing_weight=1.0))


def test_headless_standing_tracks_face_the_box_and_queue_on_its_radial_lines():
    """A radar track that never moved has no heading (tracking/tracker.py): it is taken to
    face the box, so a queue of them on an arm counts, heading along the arm into the box;
    a lone one and a row across the arm (a line of cars that are not one behind the other
    towards the box) do not."""
    rng = np.random.default_rng(6)
    arm = GT.arms[QUEUE_ARM]
    headless = [replace(d, heading=np.full(len(d), np.nan)) for d in _queue(rng)]
    obs = _obs(Detections.concat(headless))
    assert len(obs) == 5 and np.all(obs.has_o) and np.all(obs.d == 1.0)
    into = np.array([math.cos(arm.angle + math.pi), math.sin(arm.angle + math.pi)])
    assert (obs.hx * into[0] + obs.hy * into[1]).min() > math.cos(math.radians(10))
    assert len(_obs(Detections.concat(headless[:1]))) == 0
    u = np.array([math.cos(arm.angle), math.sin(arm.angle)])
    across = [_standing(GT.center + 30.0 * u + np.array([-u[1], u[0]]) * (7.0 * k - 7.0),
                        np.nan, 600 + k, rng) for k in range(3)]
    assert len(_obs(Detections.concat(across))) == 0
