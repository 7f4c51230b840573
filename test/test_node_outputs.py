"""Issue 16, the node in-process (no second process): outputs stamped with data time, a reset
clears latched lanes and markers, missing message packages are errors on /diagnostics,
array parameters (mount_*) settable at run time."""

from __future__ import annotations

import array
from dataclasses import replace
import time

import numpy as np
import pytest

from intersection_estimator.lanes import lanelets_from_topology
from intersection_estimator.model import Arm, Intersection
from intersection_estimator.pipeline import EstimateResult

T_DATA = 1_700_000_123.25


@pytest.fixture
def make_node(ros_context):
    """Factory of in-process nodes (a long timer period: the test drives the publishing);
    every publish is recorded per topic in ``node.sent``."""
    from rclpy.parameter import Parameter
    from intersection_estimator.node import IntersectionEstimatorNode
    nodes = []

    def make(**params):
        params.setdefault('timer_period', 10.0)
        node = IntersectionEstimatorNode(context=ros_context,
                                         parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
        node.sent = {}
        for name in ('topology', 'lanelets', 'markers', 'diag', 'map_changes'):
            pub = getattr(node, f'pub_{name}')
            pub.publish = (lambda msg, n=name: node.sent.setdefault(n, []).append(msg))
        nodes.append(node)
        return node
    yield make
    for node in nodes:
        node.destroy_node()


def _result() -> EstimateResult:
    inter = Intersection(center=np.array([10.0, 20.0]), arms=[Arm(angle=a) for a in (0.0, 1.6, 3.1, 4.7)])
    return EstimateResult(inter, lanelets_from_topology(inter), {'total': 1.0}, 100, 10, -5.0,
                          'CONVERGED', 500, True)


def test_outputs_carry_data_time_and_zero_before_data(make_node):
    node = make_node()
    node._publish(None, time.perf_counter(), None)
    stamp = node.sent['topology'][-1].header.stamp
    assert (stamp.sec, stamp.nanosec) == (0, 0)          # no data yet: no (wall) time to claim
    node._publish(_result(), time.perf_counter(), T_DATA)
    for name in ('topology', 'lanelets', 'diag'):
        s = node.sent[name][-1].header.stamp
        assert s.sec + 1e-9 * s.nanosec == pytest.approx(T_DATA, abs=1e-6), name
    assert all(m.header.stamp.sec == int(T_DATA) for m in node.sent['markers'][-1].markers)


def test_a_reset_deletes_all_markers_and_publishes_empty_lanelets(make_node):
    from visualization_msgs.msg import Marker
    node = make_node()
    node._publish(_result(), time.perf_counter(), T_DATA)
    assert node.sent['lanelets'][-1].lanelets and node.sent['markers'][-1].markers
    node.estimator.reset()                               # what "ego passed" / a time jump do
    node._publish(None, time.perf_counter(), T_DATA + 1.0)
    (clear,) = node.sent['markers'][-1].markers
    assert clear.action == Marker.DELETEALL
    assert list(node.sent['lanelets'][-1].lanelets) == []
    n = len(node.sent['markers'])
    node._publish(None, time.perf_counter(), T_DATA + 2.0)               # once per reset, not every tick
    assert len(node.sent['markers']) == n


def test_topics_of_missing_packages_are_an_error_on_diagnostics(make_node):
    from diagnostic_msgs.msg import DiagnosticStatus
    node = make_node(radar_scan_topics=['/radar/scan'], autoware_object_topics=['/aw/objects'])
    node._publish(None, time.perf_counter(), None)
    (err,) = [s for s in node.sent['diag'][-1].status if s.level == DiagnosticStatus.ERROR]
    for text in ('/radar/scan', 'radar_msgs', '/aw/objects', 'autoware_perception_msgs'):
        assert text in err.message


def test_mount_arrays_are_settable_at_run_time(make_node):
    """``ros2 param set`` hands array parameters over as array('d'): accepted, applied."""
    from rclpy.parameter import Parameter
    node = make_node()
    res = node.set_parameters([Parameter('mount_x', Parameter.Type.DOUBLE_ARRAY, array.array('d', [2.5]))])
    assert res[0].successful, res[0].reason
    assert node.ingest.opts.mounts['radar'] == (2.5, 0.0, 0.0)
    res = node.set_parameters_atomically([
        Parameter('mount_frames', Parameter.Type.STRING_ARRAY, ['radar', 'rear']),
        Parameter('mount_x', Parameter.Type.DOUBLE_ARRAY, array.array('d', [2.5, -1.0])),
        Parameter('mount_y', Parameter.Type.DOUBLE_ARRAY, array.array('d', [0.0, 0.0])),
        Parameter('mount_yaw', Parameter.Type.DOUBLE_ARRAY, array.array('d', [0.0, 3.14]))])
    assert res.successful, res.reason
    assert node.ingest.opts.mounts['rear'] == (-1.0, 0.0, 3.14)
    res = node.set_parameters([Parameter('mount_y', Parameter.Type.DOUBLE_ARRAY, array.array('d', [1.0]))])
    assert not res[0].successful and 'mount_y' in res[0].reason


def test_osm_path_gets_the_lane_course_with_its_geo_origin_and_is_emptied_on_reset(make_node, tmp_path):
    from intersection_estimator.export.osm import load_osm, read_origin
    target = tmp_path / 'maps' / 'live.osm'
    node = make_node(osm_path=str(target), geo_origin=[48.1, 11.6])
    node._publish(_result(), time.perf_counter(), T_DATA)
    assert not target.exists()                       # its folder is missing: logged, the node goes on
    target.parent.mkdir()
    node._publish(_result(), time.perf_counter(), T_DATA + 1.0)
    assert read_origin(target) == (48.1, 11.6)
    assert len(load_osm(target).laneletLayer) == len(_result().lanelets)
    assert not list(target.parent.glob('.*tmp*'))    # written beside it and renamed
    node.estimator.reset()                           # what "ego passed" does
    node._publish(None, time.perf_counter(), T_DATA + 2.0)
    assert len(load_osm(target).laneletLayer) == 0


def test_bad_geo_origin_is_refused_naming_it(make_node):
    from rclpy.parameter import Parameter
    node = make_node()
    res = node.set_parameters([Parameter('geo_origin', value=[95.0, 8.4])])
    assert not res[0].successful and 'geo_origin' in res[0].reason
    assert list(node.values['geo_origin']) == [49.0, 8.4]


def test_prior_map_publishes_map_changes_and_their_markers(make_node, tmp_path):
    """prior_map set: the newest lane update is compared with the map in the two ticks after
    it, at most every map_changes_period (~/map_changes, markers in namespace map_changes); a
    reset publishes an empty report."""
    from intersection_estimator.export.osm import write_osm
    from intersection_estimator.fleet.edits import apply_edit
    from intersection_estimator.sim import simulate_scenario
    from msg_adapters.map_changes import NAMESPACE
    sc = simulate_scenario(1)          # its ground truth as the estimate, the map with one lane moved
    res = EstimateResult(sc.gt, sc.gt_lanelets, {'total': 1.0}, 100, 10, -5.0, 'CONVERGED', 500, True)
    moved, _ = apply_edit(sc, 'lane_moved', np.random.default_rng(1))
    node = make_node(prior_map=str(write_osm(tmp_path / 'prior.osm', moved)), map_changes_period=600.0)
    node._publish(res, time.perf_counter(), T_DATA)
    # the lanelets go out at once, their comparison with the map in the next tick
    assert node.sent['lanelets'] and 'map_changes' not in node.sent
    assert node._changes_due is not None and node._compare_now()
    # in two ticks: the window's vehicles matched to the map, then the rules and the message
    node._publish(None, time.perf_counter(), T_DATA + 0.1)
    assert 'map_changes' not in node.sent and node._comparing is not None and node._compare_now()
    assert len(node._match_ms) == 1 and node._comparing[2].mapped is not None
    node._publish(None, time.perf_counter(), T_DATA + 0.2)
    (msg,) = node.sent['map_changes']
    assert node._changes_due is None and node._comparing is None and len(node._change_ms) == 1
    # the next lane update waits for map_changes_period; the newest one is compared then
    node._publish(res, time.perf_counter(), T_DATA + 0.4)
    node._publish(None, time.perf_counter(), T_DATA + 0.6)
    assert len(node.sent['map_changes']) == 1 and not node._compare_now()
    node._change_t -= 600.0
    node._publish(None, time.perf_counter(), T_DATA + 0.7)
    node._publish(None, time.perf_counter(), T_DATA + 0.8)
    s = node.sent['map_changes'][-1].header.stamp
    assert len(node.sent['map_changes']) == 2 and s.sec + 1e-9 * s.nanosec == pytest.approx(T_DATA + 0.4)
    assert msg.intersection_id and msg.header.stamp.sec == int(T_DATA)
    assert [c.kind for c in msg.changes] == ['lane_moved'], [c.kind for c in msg.changes]
    assert any(m.ns == NAMESPACE for arr in node.sent['markers'] for m in arr.markers)
    node.estimator.reset()
    node._publish(None, time.perf_counter(), T_DATA + 1.0)
    assert list(node.sent['map_changes'][-1].changes) == []


def test_a_prior_map_that_does_not_load_is_refused_naming_it(make_node, tmp_path):
    bad = tmp_path / 'broken.osm'
    bad.write_text('<osm><node id="1"')
    with pytest.raises(ValueError, match='prior_map'):
        make_node(prior_map=str(bad))


def test_lanelets_of_a_late_tick_go_out_with_the_next_one(make_node):
    """A tick whose estimation left no room for publishing the new lane course (its
    recent worst cost) publishes topology only; the next tick publishes the lanelets and
    markers, whatever its own lateness (at most one tick late)."""
    node = make_node()
    node._overhead_ms[True].append(40.0)             # publishing lanes cost 40 ms lately
    late = time.perf_counter() - 0.001 * (node.values['budget_ms'] - 20.0)   # 20 ms left
    node._publish(_result(), late, T_DATA)
    assert 'lanelets' not in node.sent and node.sent['topology']
    node._publish(replace(_result(), lanes_updated=False), late, T_DATA + 0.2)
    assert len(node.sent['lanelets']) == 1 and node.sent['markers']
    s = node.sent['lanelets'][-1].header.stamp         # the data time of its own estimate
    assert s.sec + 1e-9 * s.nanosec == pytest.approx(T_DATA, abs=1e-6)
    node._overhead_ms[True].clear()
    node._overhead_ms[True].append(10.0)             # (the late ticks above recorded theirs)
    node._publish(_result(), time.perf_counter(), T_DATA + 0.4)   # room: at once
    assert len(node.sent['lanelets']) == 2
