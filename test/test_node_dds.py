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
