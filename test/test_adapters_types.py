"""Message namespaces: one builder call gives rclpy or rosbags messages."""

import array

import numpy as np
import pytest

from intersection_estimator.bagio import typestore
from msg_adapters.types import RclpyTypes, RosbagsTypes, full_name, make_header


def test_full_name():
    assert full_name('sensor_msgs/PointCloud2') == 'sensor_msgs/msg/PointCloud2'
    assert full_name('sensor_msgs/msg/PointCloud2') == 'sensor_msgs/msg/PointCloud2'


def test_rosbags_defaults_and_conversions():
    ts = typestore()
    T = RosbagsTypes(ts)
    scale = T.get('geometry_msgs/msg/Vector3')(x=1)
    m = T.get('visualization_msgs/Marker')(ns='a', id=np.int64(3), scale=scale)
    assert m.id == 3 and type(m.id) is int and m.text == '' and m.points == []
    assert m.pose.orientation.w == 0.0 and isinstance(m.header.stamp.sec, int)
    ts.serialize_cdr(m, 'visualization_msgs/msg/Marker')         # every field present and typed
    pwc = T.get('geometry_msgs/msg/PoseWithCovariance')(covariance=[1.0] * 36)
    assert pwc.covariance.dtype == np.float64 and pwc.covariance.shape == (36,)
    cloud = T.get('sensor_msgs/msg/PointCloud2')(data=b'\x01\x02')
    assert cloud.data.dtype == np.uint8 and list(cloud.data) == [1, 2]
    with pytest.raises(TypeError):
        T.get('geometry_msgs/msg/Point')(w=1.0)


def test_rclpy_conversions():
    T = RclpyTypes()
    cloud = T.get('sensor_msgs/msg/PointCloud2')(data=np.arange(4, dtype=np.uint8), width=np.uint32(4))
    assert isinstance(cloud.data, array.array) and list(cloud.data) == [0, 1, 2, 3] and cloud.width == 4
    pwc = T.get('geometry_msgs/PoseWithCovariance')(covariance=np.ones(36, np.float32))
    assert pwc.covariance.dtype == np.float64
    h = make_header(T, 'map', 2.999999999999)
    assert (h.stamp.sec, h.stamp.nanosec) == (3, 0)
