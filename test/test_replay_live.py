"""Issue 16: ``replay --live`` publishes ``/clock`` in bag time (for nodes with use_sim_time),
over real DDS from its own process (localhost, the run's own domain id, see conftest)."""

from __future__ import annotations

import pytest

from conftest import script, wait_for

from test_replay_routes import synthetic_bag

pytestmark = pytest.mark.dds


def test_replay_live_publishes_clock_in_bag_time(tmp_path, ros_context, node_process):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rosgraph_msgs.msg import Clock
    from intersection_estimator.bagio import BAG_T0, open_bags
    bag = synthetic_bag(tmp_path / 'bag')                        # 20 s of odometry + radar at 10 Hz
    with open_bags(bag) as b:
        first, last = b.time_span
    node = rclpy.create_node('ie_clock_listener', context=ros_context)
    got = []
    node.create_subscription(Clock, '/clock', lambda m: got.append(m.clock.sec + 1e-9 * m.clock.nanosec), 100)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)

    def spin(t):
        ex.spin_once(timeout_sec=t)
    try:
        player = node_process([script('intersection-estimator'), 'replay', '--live', '--rate', '4.0', str(bag)])
        assert wait_for(lambda: player.proc.poll() is not None, 90, spin), player.output()
        assert player.proc.returncode == 0, player.output()
        wait_for(lambda: got and got[-1] >= last - 1e-6, 5, spin)
    finally:
        node.destroy_node()
    assert got, player.output()
    assert abs(first - BAG_T0) < 1e-6
    assert all(first - 1e-6 <= t <= last + 1e-6 for t in got)   # bag time, not wall time
    assert got == sorted(got)                                   # never backwards
    assert got[-1] >= last - 1e-6 and got[0] <= first + 1.0
    # between messages as well (40 Hz of wall time at rate 4 -> ~10 per bag second), not only at them
    assert len(got) > 400, len(got)
