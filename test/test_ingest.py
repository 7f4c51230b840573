"""Ingest: messages -> detections, held back until the ego pose, guarded time base."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from intersection_estimator import params as P
from intersection_estimator.bagio import typestore
from intersection_estimator.ingest import JUMP_CONFIRM, PENDING_MAX, Ingest, RateLimitedLog, tick
from intersection_estimator.model import Arm, Intersection
from intersection_estimator.pipeline import EstimateResult, OnlineEstimator
from msg_adapters.odometry import odometry_msg
from msg_adapters.tracked_objects import tracked_object_array_msg
from msg_adapters.types import RosbagsTypes, make_header

T0 = 1_700_000_000.0


@pytest.fixture(scope='module')
def types():
    return RosbagsTypes(typestore())


class Sink:
    """Stands in for OnlineEstimator where only add/reset matter."""

    def __init__(self):
        self.parts, self.resets = [], 0

    def add(self, dets):
        self.parts.append(dets)
        return len(dets)

    def reset(self):
        self.resets += 1


def objects(types, t, frame='map', xy=((10.0, 2.0),)):
    xy = np.asarray(xy, float)
    n = len(xy)
    return tracked_object_array_msg(types, make_header(types, frame, t), np.arange(n), xy,
                                    np.zeros(n), np.full(n, 10.0))


def test_objects_in_base_link_wait_for_the_ego_pose(types):
    ingest, sink = Ingest(P.defaults(), types), Sink()
    assert ingest.handle('object_topics', objects(types, T0 + 1.0, 'base_link'), sink) == 0
    assert sink.parts == [] and ingest.dropped == {}
    ingest.handle('odometry_topic', odometry_msg(types, T0 + 0.9, 100.0, 0.0, np.pi / 2), sink)
    assert sink.parts == []                     # the pose for t=1.0 is not there yet
    ingest.handle('odometry_topic', odometry_msg(types, T0 + 1.1, 100.0, 2.0, np.pi / 2), sink)
    (dets,) = sink.parts
    # base_link (10, 2) at pose (100, 1, 90 deg) -> (98, 11)
    np.testing.assert_allclose(dets.xy, [[98.0, 11.0]], atol=1e-9)
    assert dets.track_id.tolist() == [0]


def test_without_odometry_held_back_messages_are_bounded_and_counted(types):
    ingest, sink = Ingest(P.defaults(), types), Sink()
    for k in range(PENDING_MAX + 10):
        ingest.handle('object_topics', objects(types, T0 + 0.1 * k, 'base_link'), sink)
    assert ingest.dropped['no_ego_pose'] == 10
    assert ingest.received['object_topics'] == PENDING_MAX + 10


def test_fixed_frame_objects_pass_through(types):
    ingest, sink = Ingest(P.defaults(), types), Sink()
    ingest.handle('object_topics', objects(types, T0, 'map', [(1.0, 2.0), (3.0, 4.0)]), sink)
    np.testing.assert_allclose(sink.parts[0].xy, [[1, 2], [3, 4]])
    assert ingest.latest_stamp == pytest.approx(T0)


def test_time_jump_is_dropped_until_confirmed_then_resets(types):
    ingest, sink = Ingest(P.defaults(), types), Sink()
    ingest.handle('object_topics', objects(types, T0), sink)
    for k in range(JUMP_CONFIRM - 1):
        ingest.handle('object_topics', objects(types, T0 + 1000.0 + k), sink)
    assert ingest.dropped['stamp_jump'] == JUMP_CONFIRM - 1 and sink.resets == 0
    ingest.handle('object_topics', objects(types, T0 + 1010.0), sink)
    assert sink.resets == 1
    assert ingest.latest_stamp == pytest.approx(T0 + 1010.0)
    assert len(sink.parts) == 2


def test_malformed_and_unknown_messages_are_dropped_not_raised(types):
    ingest, sink = Ingest(P.defaults(), types), Sink()
    ingest.handle('object_topics', SimpleNamespace(header=None), sink)
    ingest.handle('object_topics', SimpleNamespace(), sink)
    stamp = SimpleNamespace(sec=1_700_000_000, nanosec=0)
    ingest.handle('radar_topics', SimpleNamespace(header=SimpleNamespace(stamp=stamp, frame_id='map')), sink)
    assert sum(ingest.dropped.values()) == 3
    reasons = {r for r, _ in ingest.pop_warnings()}
    assert 'unknown_type' in reasons and 'malformed' in reasons and ingest.pop_warnings() == []


def test_rate_limited_log_prints_once_per_reason_and_period():
    lines = []
    log = RateLimitedLog(SimpleNamespace(warning=lines.append), period_s=60.0)
    for _ in range(100):
        log.warn('a', 'problem a')
    log.warn('b', 'problem b')
    assert lines == ['problem a', 'problem b']
    assert log.suppressed['a'] == 99


def test_tick_resets_when_the_ego_has_passed_the_center(types):
    ingest = Ingest(P.defaults(), types)
    est = OnlineEstimator(P.pipeline_config(P.defaults()))
    assert tick(ingest, est, wall_budget=False) is None          # nothing received yet
    est.result = EstimateResult(Intersection([0.0, 0.0], [Arm(0.0), Arm(2.0), Arm(-2.0)]), [],
                                state='CONVERGED')
    ingest.handle('odometry_topic', odometry_msg(types, T0, 40.0, 0.0, 0.0), est)
    resets = est._resets
    assert not est.passed((40.0, 0.0), 0.0)      # never seen approaching: an early, wrong center
    assert not est.passed((-30.0, 0.0), 0.0)     # approaching
    r = tick(ingest, est, wall_budget=False)
    assert est._resets == resets + 1 and r.intersection is None and r.state == 'NO_DATA'


def test_a_road_behind_the_ego_is_not_a_passed_intersection():
    """A converged estimate of two arms is a road: the ego driving past its center does not
    end the window (the demo bag's first seconds showed one and threw its data away)."""
    est = OnlineEstimator(P.pipeline_config(P.defaults()))
    for arms, expected in (([Arm(0.0), Arm(3.1)], False),
                           ([Arm(0.0), Arm(3.1), Arm(1.6)], True)):
        est._approached = False
        est.result = EstimateResult(Intersection([0.0, 0.0], arms), [], state='CONVERGED')
        assert not est.passed((-30.0, 0.0), 0.0)          # approaching
        assert est.passed((40.0, 0.0), 0.0) is expected, arms
