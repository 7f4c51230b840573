"""Radars that do not remove the ego motion from their Doppler (``doppler_ego_compensated``
false): the adapter adds the sensor's own velocity -- from the ego poses, the mount's lever
arm included -- along each line of sight, so the estimator reads Doppler over ground as
from a compensating radar. End to end: a simulated drive whose radar reports Doppler
relative to the moving sensor, through the ingest, and replayed."""

from __future__ import annotations

import numpy as np
import pytest

from intersection_estimator import params as P
from intersection_estimator.bagio import SCENARIO_TOPICS, BagWriter, scenario_messages
from intersection_estimator.ingest import Ingest
from intersection_estimator.observations import Detections
from intersection_estimator.replay import replay
from intersection_estimator.sim import SimConfig, simulate_scenario
from msg_adapters.detections import over_ground
from msg_adapters.odometry import EgoPose, EgoPoseBuffer

ROLES = {SCENARIO_TOPICS['radar']: 'radar_topics', SCENARIO_TOPICS['odometry']: 'odometry_topic'}


def test_a_static_point_seen_from_a_moving_sensor_is_static_over_ground():
    sensor, v = np.array([10.0, 5.0]), np.array([12.0, -3.0])
    pts = np.array([[40.0, 5.0], [10.0, 40.0], [-20.0, -20.0]])
    los = (pts - sensor) / np.linalg.norm(pts - sensor, axis=1, keepdims=True)
    measured = -(los @ v)                          # a static point closes at the sensor's speed
    np.testing.assert_allclose(over_ground(measured, pts, sensor, v), 0.0, atol=1e-12)


def test_the_sensor_velocity_includes_the_mounts_lever_arm():
    ego = EgoPoseBuffer()
    w, r = 0.5, 10.0                               # a turn of radius 10 m at 0.5 rad/s
    for k in range(21):
        t = 0.05 * k
        a = w * t
        ego.add(EgoPose(t, 'map', 'base_link', r * np.sin(a), r - r * np.cos(a), a, r * w, 0.0, w))
    v = ego.velocity('radar', 0.5, {'radar': (3.7, 0.0, 0.0)})
    a = w * 0.5                                    # base: r w along the heading; mount: w x (3.7 ahead)
    expect = r * w * np.array([np.cos(a), np.sin(a)]) + w * 3.7 * np.array([-np.sin(a), np.cos(a)])
    np.testing.assert_allclose(v, expect, atol=0.02)


class _Window:
    def __init__(self):
        self.parts = []

    def add(self, dets):
        self.parts.append(dets)
        return len(dets)


def _ingested(scenario, types, over_ground_bag: bool, compensated_param: bool) -> Detections:
    values = P.defaults() | {'doppler_ego_compensated': compensated_param}
    ingest, window = Ingest(values, types), _Window()
    for _, topic, msg in scenario_messages(scenario, types, sensors=('raw',),
                                           doppler_over_ground=over_ground_bag):
        if topic in ROLES:
            ingest.handle(ROLES[topic], msg, window)
    return Detections.concat(window.parts)


@pytest.fixture(scope='module')
def drive():
    return simulate_scenario(4, SimConfig(duration=(20.0, 20.0)))


def test_the_node_removes_the_ego_motion_a_radar_left_in(drive, tmp_path):
    with BagWriter(tmp_path / 'types') as w:
        types = w.types
        truth = _ingested(drive, types, True, True)
        fixed = _ingested(drive, types, False, False)
        raw = _ingested(drive, types, False, True)          # the wrong setting for such a radar
    assert len(truth) == len(fixed) == len(raw) > 1000
    assert np.median(np.abs(fixed.doppler - truth.doppler)) < 0.05
    assert np.percentile(np.abs(fixed.doppler - truth.doppler), 95) < 0.3
    off = np.abs(raw.doppler - truth.doppler)
    assert off.mean() > 1.0 and (off > 5.0).mean() > 0.1, (off.mean(), (off > 5.0).mean())


def test_a_relative_doppler_bag_replays_to_the_same_junction(drive, tmp_path):
    with BagWriter(tmp_path / 'bag') as w:
        for t, topic, msg in scenario_messages(drive, w.types, sensors=('raw',), doppler_over_ground=False):
            w.write(topic, msg, t)
    params = tmp_path / 'p.yaml'
    params.write_text('intersection_estimator:\n  ros__parameters:\n    doppler_ego_compensated: false\n'
                      '    topology_samples: 600\n    lane_samples: 600\n')
    s = replay([str(tmp_path / 'bag')], tmp_path / 'out', params_file=str(params), progress=False,
               write_outputs=False)
    assert not s.dropped, s.dropped
    assert len(s.result.intersection.arms) == len(drive.gt.arms)
