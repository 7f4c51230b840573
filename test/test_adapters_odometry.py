"""Ego pose buffer: interpolation, extrapolation, frames, hand-computed transforms."""

import math

import numpy as np
import pytest

from msg_adapters.errors import AdapterError
from msg_adapters.odometry import EgoPose, EgoPoseBuffer, odometry_msg, read_odometry
from msg_adapters.types import RclpyTypes

S2 = math.sqrt(2) / 2
MOUNTS = {'radar': (2.0, 1.0, math.pi / 2)}


def buffer():
    """Ego at (0, 0, 0) at t=10 and at (10, 0, pi/2) at t=11, 10 m/s forward."""
    buf = EgoPoseBuffer('map', 'base_link', tolerance=0.2)
    buf.add(EgoPose(10.0, 'map', 'base_link', 0.0, 0.0, 0.0, vx=10.0))
    buf.add(EgoPose(11.0, 'map', 'base_link', 10.0, 0.0, math.pi / 2, vx=10.0))
    return buf


def test_interpolation_linear_xy_and_yaw():
    assert buffer().pose_at(10.5) == pytest.approx((5.0, 0.0, math.pi / 4))


def test_base_link_and_sensor_frame_transform():
    buf = buffer()
    # ego (5, 0, pi/4): base_link point (1, 0) -> (5 + c, s)
    np.testing.assert_allclose(buf.to_fixed('base_link', 10.5, [[1.0, 0.0]]), [[5 + S2, S2]])
    # radar origin = ego + R(pi/4) (2, 1) = (5 + S2, 3 S2), radar yaw 3pi/4
    assert buf.transform('radar', 10.5, MOUNTS) == pytest.approx((5 + S2, 3 * S2, 3 * math.pi / 4))
    # radar point (1, 0) -> origin + (-S2, S2) = (5, 4 S2)
    np.testing.assert_allclose(buf.to_fixed('/radar', 10.5, [[1.0, 0.0]], MOUNTS), [[5.0, 4 * S2]])


def test_fixed_frame_passes_through_without_ego():
    empty = EgoPoseBuffer('map')
    xy = np.array([[1.0, 2.0]])
    np.testing.assert_array_equal(empty.to_fixed('map', 123.0, xy), xy)
    with pytest.raises(AdapterError) as err:
        empty.to_fixed('base_link', 123.0, xy)
    assert err.value.reason == 'no_ego_pose'


def test_unknown_frame_and_stamp_outside():
    buf = buffer()
    with pytest.raises(AdapterError) as err:
        buf.to_fixed('lidar', 10.5, [[0.0, 0.0]], MOUNTS)
    assert err.value.reason == 'unknown_frame'
    for t in (9.7, 11.3, float('nan')):
        with pytest.raises(AdapterError) as err:
            buf.pose_at(t)
        assert err.value.reason in ('no_ego_pose', 'non_finite')


def test_extrapolation_and_hold_within_tolerance():
    buf = buffer()
    assert buf.pose_at(11.1) == pytest.approx((10.0, 1.0, math.pi / 2))   # 10 m/s along +y
    assert buf.pose_at(9.9) == pytest.approx((0.0, 0.0, 0.0))


def test_shortest_arc_yaw():
    buf = EgoPoseBuffer()
    buf.add(EgoPose(0.0, 'map', 'base_link', 0, 0, 3.0))
    buf.add(EgoPose(1.0, 'map', 'base_link', 0, 0, -3.0))
    yaw = buf.pose_at(0.5)[2]
    assert abs(abs(yaw) - math.pi) < 1e-9


def test_out_of_order_insert_reset_and_bound():
    buf = EgoPoseBuffer(maxlen=5, reset_after=1.0)
    for t in (0.0, 0.2, 0.1, 0.4, 0.3):
        buf.add(EgoPose(t, 'map', 'base_link', t, 0, 0))
    assert buf.pose_at(0.25)[0] == pytest.approx(0.25)
    buf.add(EgoPose(0.5, 'map', 'base_link', 0.5, 0, 0))
    assert len(buf) == 5                       # bounded
    buf.add(EgoPose(-5.0, 'map', 'base_link', 9.0, 0, 0))   # time jumped back (bag loop)
    assert len(buf) == 1 and buf.resets == 1 and buf.pose_at(-5.0)[0] == 9.0
    with pytest.raises(AdapterError) as err:
        buf.add(EgoPose(1.0, 'odom', 'base_link', 0, 0, 0))
    assert err.value.reason == 'frame_mismatch'


def test_odometry_message_roundtrip_rclpy():
    from nav_msgs.msg import Odometry
    msg = odometry_msg(RclpyTypes(), 12.25, 1.0, -2.0, 2.5, vx=3.0, yaw_rate=0.1)
    assert isinstance(msg, Odometry)
    p = read_odometry(msg)
    assert (p.stamp, p.frame_id, p.child_frame_id) == (12.25, 'map', 'base_link')
    assert (p.x, p.y, p.yaw, p.vx, p.yaw_rate) == pytest.approx((1.0, -2.0, 2.5, 3.0, 0.1))
    msg.pose.pose.position.x = float('inf')
    with pytest.raises(AdapterError) as err:
        read_odometry(msg)
    assert err.value.reason == 'non_finite'
