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
        assert wait_for(lambda: node.count_publishers('/intersection_estimator/topology') > 0, 20, spin), \
            proc.output()
        assert wait_for(lambda: len(got) > 0, 20, spin), proc.output()
        assert proc.alive(), proc.output()
        msg = got[-1]
        assert msg.state == Topology.NO_DATA
        assert msg.header.frame_id == 'map'
        assert len(msg.arms) == 0
    finally:
        node.destroy_node()


def test_node_refuses_bad_parameter_at_startup(node_process):
    """A parameter outside its range stops the node with a message naming it."""
    proc = node_process([script('intersection_estimator_node'), '--ros-args', '-p', 'budget_ms:=-5.0'])
    proc.proc.wait(30)
    assert proc.proc.returncode != 0
    assert 'budget_ms' in proc.output()


def test_node_estimates_live_traffic_from_another_process(ros_context, node_process):
    """replay --live plays a bundled bag in its own process; the node, in another, publishes
    a topology with the right number of arms, lanelets and markers."""
    from intersection_estimator.estimate_io import read_gt
    from intersection_estimator_msgs.msg import LaneletArray, Topology
    from visualization_msgs.msg import MarkerArray
    gt = read_gt(ROOT / 'bags' / 'tracked.gt.json')
    node_proc = node_process([script('intersection_estimator_node'), '--ros-args',
                              '-p', 'timer_period:=0.2', '-p', 'budget_ms:=150.0'])
    listener, topos = _subscribe(ros_context, Topology, '/intersection_estimator/topology', 'latched')
    lanelets, markers = [], []
    listener.create_subscription(LaneletArray, '/intersection_estimator/lanelets', lanelets.append, 10)
    listener.create_subscription(MarkerArray, '/intersection_estimator/markers', markers.append, 10)
    try:
        spin = _spinner(ros_context, listener)
        assert wait_for(lambda: len(topos) > 0, 20, spin), node_proc.output()
        player = node_process([script('intersection-estimator'), 'replay', '--live', '--rate', '2.0',
                               str(ROOT / 'bags' / 'tracked')])

        def converged():
            return any(m.state != Topology.NO_DATA and len(m.arms) == len(gt.intersection.arms) for m in topos)
        assert wait_for(converged, 60, spin), (node_proc.output() + player.output()
                                                + str([(m.state, len(m.arms), m.observations) for m in topos[-5:]]))
        assert wait_for(lambda: player.proc.poll() is not None, 60, spin), player.output()
        assert player.proc.returncode == 0, player.output()
        assert wait_for(lambda: lanelets and markers, 20, spin)
        kinds = {l.kind for l in lanelets[-1].lanelets}
        assert kinds == {0, 1, 2}, kinds        # entering, leaving and connectors
        spaces = {m.ns for arr in markers for m in arr.markers}
        assert {'center', 'left_lane_bound', 'right_lane_bound', 'center_lane_line'} <= spaces
        assert node_proc.alive(), node_proc.output()
    finally:
        listener.destroy_node()
