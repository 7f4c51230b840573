"""Issue 16: TF -- sensor mounts from /tf_static (mount_* parameters as fallback) and
odometry in ``odom`` with ``map -> odom`` from /tf (REP 105), all without rclpy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from intersection_estimator import params as P
from intersection_estimator.bagio import typestore
from intersection_estimator.ingest import Ingest
from intersection_estimator.pipeline import OnlineEstimator
from intersection_estimator.tf import TfBuffer, TfMounts
from msg_adapters._common import quat_from_yaw
from msg_adapters.odometry import odometry_msg
from msg_adapters.pointcloud2 import radar_cloud_msg
from msg_adapters.types import RosbagsTypes, make_header

T0 = 1_700_000_000.0


@pytest.fixture(scope='module')
def types():
    return RosbagsTypes(typestore())


def tf_msg(types, items):
    """TFMessage of ``(t, parent, child, (x, y, yaw))`` items."""
    g = types.get
    out = []
    for t, parent, child, (x, y, yaw) in items:
        qx, qy, qz, qw = (float(v) for v in quat_from_yaw(yaw))
        tr = g('geometry_msgs/msg/Transform')(
            translation=g('geometry_msgs/msg/Vector3')(x=x, y=y, z=0.0),
            rotation=g('geometry_msgs/msg/Quaternion')(x=qx, y=qy, z=qz, w=qw))
        out.append(g('geometry_msgs/msg/TransformStamped')(header=make_header(types, parent, t),
                                                           child_frame_id=child, transform=tr))
    return g('tf2_msgs/msg/TFMessage')(transforms=out)


def test_buffer_composes_interpolates_and_refuses_gaps(types):
    tf = TfBuffer(tolerance=0.5)
    tf.add(tf_msg(types, [(T0, 'base_link', 'radar', (3.0, 0.0, math.pi / 2))]), static=True)
    tf.add(tf_msg(types, [(T0, 'map', 'odom', (10.0, 0.0, 0.0)),
                          (T0 + 1.0, 'map', 'odom', (12.0, 0.0, 0.0)),
                          (T0, 'odom', 'base_link', (0.0, 5.0, math.pi / 2))]), static=False)
    np.testing.assert_allclose(tf.lookup('map', 'odom', T0 + 0.5), (11.0, 0.0, 0.0))
    # radar at (3, 0) in base_link; base_link at (0, 5) in odom facing +y; odom at (10, 0)
    x, y, yaw = tf.lookup('map', 'radar', T0)
    np.testing.assert_allclose((x, y, math.cos(yaw), math.sin(yaw)), (10.0, 8.0, -1.0, 0.0), atol=1e-9)
    back = tf.lookup('radar', 'map', T0)
    c, s = math.cos(back[2]), math.sin(back[2])
    np.testing.assert_allclose((back[0] + c * 10.0 - s * 8.0, back[1] + s * 10.0 + c * 8.0), (0, 0), atol=1e-9)
    assert tf.lookup('map', 'odom', T0 + 5.0) is None          # past the newest + tolerance
    assert tf.lookup('map', 'lidar') is None                   # not in the tree
    bad = tf_msg(types, [(T0, 'map', 'map', (0.0, 0.0, 0.0)), (T0, 'map', 'x', (math.nan, 0.0, 0.0))])
    assert tf.add(bad, static=False) == 0 and tf.rejected == 2


def test_mounts_come_from_tf_static_and_fall_back_to_parameters(types):
    tf = TfBuffer()
    mounts = TfMounts(tf, 'base_link', {'radar': (1.0, 0.0, 0.0), 'rear': (-1.0, 0.0, math.pi)})
    assert mounts['radar'] == (1.0, 0.0, 0.0) and 'lidar' not in mounts
    tf.add(tf_msg(types, [(T0, 'base_link', 'radar', (3.7, 0.5, 0.1)),
                          (T0, 'base_link', 'lidar', (1.0, 0.0, 0.0))]), static=True)
    np.testing.assert_allclose(mounts['radar'], (3.7, 0.5, 0.1))
    assert mounts['rear'] == (-1.0, 0.0, math.pi) and 'lidar' in mounts
    assert list(mounts) == ['lidar', 'radar', 'rear']


def _cloud(types, t):
    return radar_cloud_msg(types, make_header(types, 'radar', t), np.array([[1.0, 0.0, 0.0]]), np.array([2.0]))


def test_ingest_takes_the_radar_mount_from_tf_static_over_the_parameter(types):
    values = dict(P.defaults(), mount_x=[0.0])          # a wrong parameter; TF knows better
    ingest, est = Ingest(values, types), OnlineEstimator()
    for t in (T0, T0 + 0.1):
        ingest.handle('odometry_topic', odometry_msg(types, t, 100.0, 0.0, 0.0), est)
    ingest.handle('radar_topics', _cloud(types, T0 + 0.05), est)
    assert ingest.handle_tf(tf_msg(types, [(T0, 'base_link', 'radar', (3.7, 0.0, 0.0))]), static=True) == 1
    ingest.handle('radar_topics', _cloud(types, T0 + 0.05), est)
    np.testing.assert_allclose(est.window().xy, [[101.0, 0.0], [104.7, 0.0]], atol=1e-9)
    assert ingest.received['tf_static'] == 1


def test_odometry_in_odom_reaches_map_through_tf(types):
    ingest, est = Ingest(P.defaults(), types), OnlineEstimator()
    odom = odometry_msg(types, T0, 5.0, 0.0, 0.0, frame_id='odom')
    ingest.handle('odometry_topic', odom, est)
    assert ingest.dropped['frame_mismatch'] == 1 and ingest.ego.latest is None
    ingest.handle_tf(tf_msg(types, [(T0 - 0.1, 'map', 'odom', (100.0, 50.0, math.pi / 2)),
                                    (T0 + 0.1, 'map', 'odom', (100.0, 50.0, math.pi / 2))]), static=False)
    ingest.handle('odometry_topic', odom, est)
    p = ingest.ego.latest
    assert p.frame_id == 'map'
    np.testing.assert_allclose((p.x, p.y, p.yaw), (100.0, 55.0, math.pi / 2), atol=1e-9)


def test_the_bundled_bag_tf_static_gives_the_mount(types):
    """Bags carry /tf_static (tf2_msgs from the bag's own schema): the buffer reads it."""
    from conftest import ROOT
    from rosbags.highlevel import AnyReader
    ingest = Ingest(P.defaults(), types)
    with AnyReader([ROOT / 'bags' / 'tracked']) as reader:
        conns = [c for c in reader.connections if c.topic == '/tf_static']
        assert conns
        for conn, _, raw in reader.messages(connections=conns):
            ingest.handle_tf(reader.deserialize(raw, conn.msgtype), static=True)
    assert ingest.tf.lookup('base_link', 'radar') is not None
