"""The node as its own process, over real DDS (localhost, own domain id)."""

from __future__ import annotations

import pytest

from conftest import ROOT, script, wait_for

pytestmark = pytest.mark.dds


def _subscribe(ctx, msg_type, topic, qos=10):
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    node = rclpy.create_node('ie_test_listener', context=ctx)
    got = []
    if qos == 'latched':
        qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_subscription(msg_type, topic, got.append, qos)
    return node, got


def _spinner(ctx, node):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    return lambda t: ex.spin_once(timeout_sec=t)


@pytest.mark.colcon_smoke
def test_node_publishes_topology_without_data(ros_context, node_process):
    """Started through its console script, the node publishes ~/topology (state NO_DATA)."""
    from intersection_estimator_msgs.msg import Topology
    proc = node_process([script('intersection_estimator_node'), '--ros-args',
                         '--params-file', str(ROOT / 'config' / 'intersection_estimator.yaml'),
                         '-p', 'timer_period:=0.1'])
    node, got = _subscribe(ros_context, Topology, '/intersection_estimator/topology', 'latched')
    try:
        spin = _spinner(ros_context, node)
        assert wait_for(lambda: node.count_publishers('/intersection_estimator/topology') > 0, 120, spin), \
            proc.output()
        assert wait_for(lambda: len(got) > 0, 60, spin), proc.output()
        assert proc.alive(), proc.output()
        msg = got[-1]
        assert msg.state == Topology.NO_DATA
        assert msg.header.frame_id == 'map'
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (0, 0)   # no data: no time
        assert len(msg.arms) == 0
    finally:
        node.destroy_node()


def test_node_refuses_bad_parameter_at_startup(node_process):
    """A parameter outside its range stops the node with a message naming it."""
    proc = node_process([script('intersection_estimator_node'), '--ros-args', '-p', 'budget_ms:=-5.0'])
    proc.proc.wait(120)
    assert proc.proc.returncode != 0
    assert 'budget_ms' in proc.output()


def _bag_span(bag) -> tuple[float, float]:
    """[first, last] message stamp of a bag [s] and its duration, from metadata.yaml."""
    import yaml
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    start = info['starting_time']['nanoseconds_since_epoch'] * 1e-9
    return start, start + info['duration']['nanoseconds'] * 1e-9


def test_node_estimates_live_traffic_from_another_process(ros_context, node_process):
    """replay --live plays a bundled bag in its own process; the node, in another, publishes
    a topology with the right number of arms, lanelets and markers, stamped in bag time.

    Robust on a loaded machine: every wait is bounded by what it waits for (the bag's
    duration at the play rate, then the node's anytime estimate on the data it holds: the
    window is in data time, so it keeps estimating after the player is done), never by an
    assumed tick rate."""
    from intersection_estimator.estimate_io import read_gt
    from intersection_estimator_msgs.msg import LaneletArray, Topology
    from visualization_msgs.msg import MarkerArray
    bag, rate = ROOT / 'bags' / 'tracked', 2.0
    gt = read_gt(ROOT / 'bags' / 'tracked.gt.json')
    first, last = _bag_span(bag)
    node_proc = node_process([script('intersection_estimator_node'), '--ros-args',
                              '-p', 'timer_period:=0.2', '-p', 'budget_ms:=150.0'])
    listener, topos = _subscribe(ros_context, Topology, '/intersection_estimator/topology', 'latched')
    lanelets, markers = [], []
    listener.create_subscription(LaneletArray, '/intersection_estimator/lanelets', lanelets.append, 100)
    listener.create_subscription(MarkerArray, '/intersection_estimator/markers', markers.append, 100)
    try:
        spin = _spinner(ros_context, listener)
        assert wait_for(lambda: len(topos) > 0, 120, spin), node_proc.output()   # up, subscribed
        player = node_process([script('intersection-estimator'), 'replay', '--live', '--rate', str(rate),
                               str(bag)])
        # the player: discovery + the bag at `rate` + a generous margin for a loaded machine
        assert wait_for(lambda: player.proc.poll() is not None, 10 + 4 * (last - first) / rate + 60, spin), \
            player.output()
        assert player.proc.returncode == 0, player.output()

        def converged():
            return any(m.state != Topology.NO_DATA and len(m.arms) == len(gt.intersection.arms) for m in topos)
        assert wait_for(converged, 180, spin), (node_proc.output() + player.output()
                                                 + str([(m.state, len(m.arms), m.observations) for m in topos[-5:]]))
        assert wait_for(lambda: any(l.lanelets for l in lanelets) and markers, 120, spin), node_proc.output()
        kinds = [{l.kind for l in arr.lanelets} for arr in lanelets]
        assert {0, 1, 2} in kinds, kinds        # entering, leaving and connectors
        spaces = {m.ns for arr in markers for m in arr.markers}
        assert {'center', 'left_lane_bound', 'right_lane_bound', 'center_lane_line'} <= spaces
        stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in topos]
        assert all(s == 0.0 or first - 1e-3 <= s <= last + 1e-3 for s in stamps), (first, last, stamps[-5:])
        assert node_proc.alive(), node_proc.output()
    finally:
        listener.destroy_node()


def test_node_stops_cleanly_while_estimating(ros_context, node_process):
    """SIGINT while a tick is running (long budget, short period: the thread is estimating
    nearly all the time) -> exit 0, no 'tick failed' / 'context is invalid', no traceback."""
    from intersection_estimator_msgs.msg import Topology
    node_proc = node_process([script('intersection_estimator_node'), '--ros-args',
                              '-p', 'timer_period:=0.05', '-p', 'budget_ms:=1500.0'])
    listener, topos = _subscribe(ros_context, Topology, '/intersection_estimator/topology', 'latched')
    try:
        spin = _spinner(ros_context, listener)
        assert wait_for(lambda: len(topos) > 0, 120, spin), node_proc.output()
        player = node_process([script('intersection-estimator'), 'replay', '--live', '--rate', '4.0',
                               str(ROOT / 'bags' / 'tracked')])
        assert wait_for(lambda: any(m.state != Topology.NO_DATA for m in topos)
                        or player.proc.poll() not in (None, 0), 180, spin), node_proc.output() + player.output()
        assert any(m.state != Topology.NO_DATA for m in topos), node_proc.output() + player.output()
        spin(0.3)
        assert node_proc.stop(timeout=60) == 0, node_proc.output()
        out = node_proc.output()
        for bad in ('tick failed', 'context is invalid', 'Traceback', 'tick_error'):
            assert bad not in out, out
    finally:
        listener.destroy_node()
