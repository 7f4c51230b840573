"""Issue 8: degenerate scenes give a defined state, never an exception (in-process).

Every scene goes through the one-shot :func:`pipeline.estimate` and the anytime
:class:`pipeline.OnlineEstimator` (add, several ticks); the state must be one of
NO_DATA / CONVERGING / CONVERGED and an intersection, when there is one, finite.
"""

from __future__ import annotations

import numpy as np
import pytest

from intersection_estimator.observations import Detections
from intersection_estimator.pipeline import OnlineEstimator, PipelineConfig, estimate

STATES = {'NO_DATA', 'CONVERGING', 'CONVERGED'}
T0 = 1_700_000_000.0


def _check(result) -> None:
    assert result.state in STATES
    I = result.intersection
    if I is None:
        assert result.lanelets == [] or result.lanelets is not None
        return
    assert np.isfinite(I.center).all()
    for a in I.arms:
        assert np.isfinite([a.angle, a.gap]).all() and a.lanes_in >= 0 and a.lanes_out >= 0
    for ll in result.lanelets:
        assert np.isfinite(np.asarray(ll.center)).all()


def run_both(dets: Detections, ticks: int = 3):
    """estimate() in its mode and in raw mode, and OnlineEstimator over ``ticks`` ticks."""
    out = [estimate(dets, topology_samples=300, lane_samples=300, seed=1)]
    out.append(estimate(dets, mode='raw', topology_samples=300, seed=1))
    est = OnlineEstimator(PipelineConfig(topology_samples=300, lane_samples=300), seed=1)
    est.add(dets)
    now = float(dets.t.max()) if len(dets) else T0
    for k in range(ticks):
        out.append(est.tick(now + 0.2 * k))
    for r in out:
        _check(r)
    return out


def _track(rng, start, heading, speed, n, tid, t0=T0, noise=0.3):
    """A vehicle driving straight: n detections 0.1 s apart."""
    t = t0 + 0.1 * np.arange(n)
    d = np.array([np.cos(heading), np.sin(heading)])
    xy = np.asarray(start, float) + np.outer(speed * (t - t0), d) + rng.normal(0, noise, (n, 2))
    return Detections.make(xy, t, heading=np.full(n, heading), speed=np.full(n, speed),
                           track_id=np.full(n, tid), label=np.ones(n))


def test_no_traffic_is_no_data():
    for r in run_both(Detections.empty()):
        assert r.state == 'NO_DATA' and r.intersection is None and r.lanelets == []


def test_one_vehicle():
    rng = np.random.default_rng(0)
    run_both(_track(rng, (-60.0, -1.5), 0.0, 10.0, 120, tid=1))


def test_all_traffic_in_one_direction():
    rng = np.random.default_rng(1)
    dets = Detections.concat([_track(rng, (-70.0, -1.5 - 3.5 * (k % 2)), 0.0, 9.0 + k % 3, 150, tid=k,
                                     t0=T0 + 2.0 * k) for k in range(12)])
    run_both(dets)


def test_only_clutter():
    rng = np.random.default_rng(2)
    n = 3000
    r, a = 80.0 * np.sqrt(rng.random(n)), rng.uniform(-np.pi, np.pi, n)
    xy = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
    t = T0 + rng.uniform(0, 30, n)
    run_both(Detections.make(xy, t))                                          # position only
    run_both(Detections.make(xy, t, heading=rng.uniform(-np.pi, np.pi, n)))  # random headings
    run_both(Detections.make(xy, t, doppler=rng.normal(0, 3, n), sensor_xy=(0.0, -40.0)))


def test_vehicles_waiting_at_a_red_light():
    """Standing still: zero speed, hundreds of detections at one place per vehicle (heading known
    for some, unknown for others), plus one crossing stream."""
    rng = np.random.default_rng(3)
    parts = []
    for k in range(6):                                 # a queue of 6 cars, 40 s at 10 Hz
        n = 400
        xy = np.array([-8.0 - 6.0 * k, -1.7]) + rng.normal(0, 0.05, (n, 2))
        heading = np.zeros(n) if k % 2 else np.full(n, np.nan)
        parts.append(Detections.make(xy, T0 + 0.1 * np.arange(n), heading=heading, speed=np.zeros(n),
                                     track_id=np.full(n, 100 + k), label=np.ones(n)))
    parts += [_track(rng, (1.7, -60.0 - 20 * k), np.pi / 2, 10.0, 120, tid=k, t0=T0 + 3.0 * k) for k in range(5)]
    run_both(Detections.concat(parts))
    run_both(Detections.concat(parts[:6]))             # only the waiting queue


def test_pedestrians_and_cyclists_are_filtered_by_the_adapters():
    from intersection_estimator.bagio import typestore
    from msg_adapters.detections import AdapterOptions, object_detections
    from msg_adapters.odometry import EgoPoseBuffer
    from msg_adapters.tracked_objects import tracked_object_array_msg
    from msg_adapters.types import RosbagsTypes, make_header
    types = RosbagsTypes(typestore())
    labels = np.array([1, 6, 7, 2, 7, 6, 5, 0, 3, 4, 8, 9])   # car, bicycle, pedestrian, ...
    n = len(labels)
    msg = tracked_object_array_msg(types, make_header(types, 'map', T0), np.arange(n),
                                   np.stack([np.arange(n, dtype=float), np.zeros(n)], axis=1),
                                   np.zeros(n), np.full(n, 1.2), labels)
    dets = object_detections(msg, EgoPoseBuffer(), AdapterOptions())
    assert sorted(dets.label.tolist()) == [0, 1, 2, 3, 4, 5]
    assert not set(dets.track_id.tolist()) & {1, 2, 4, 5, 10, 11}
    only_people = tracked_object_array_msg(types, make_header(types, 'map', T0), np.arange(4),
                                           np.zeros((4, 2)), np.zeros(4), np.full(4, 1.2), [6, 7, 7, 6])
    assert len(object_detections(only_people, EgoPoseBuffer(), AdapterOptions())) == 0
    # and a scene of walking people among the cars gives a defined state
    rng = np.random.default_rng(4)
    cars = [_track(rng, (-60.0, -1.7), 0.0, 10.0, 120, tid=k, t0=T0 + 2 * k) for k in range(4)]
    people = _track(rng, (3.0, -20.0), np.pi / 2, 1.3, 300, tid=99)
    people.label[:] = 7
    run_both(Detections.concat(cars + [people]))


@pytest.mark.parametrize('offset', [(0.0, 0.0), (500_000.0, 5_400_000.0)])
def test_a_map_frame_far_from_its_origin_gives_the_same_topology(offset):
    """Map frames in UTM (Autoware's MGRS grid is ~1e5 m): coordinates of 1e6 m are legal input."""
    from dataclasses import replace
    from intersection_estimator.sim import simulate_scenario
    sc = simulate_scenario(3)
    dets = sc.detections('tracked')
    moved = replace(dets, xy=dets.xy + np.asarray(offset))
    r = estimate(moved, topology_samples=2000, lane_samples=0, seed=0)
    _check(r)
    assert len(r.intersection.arms) == len(sc.gt.arms)
    assert np.hypot(*(r.intersection.center - offset - sc.gt.center)) < 5.0
