"""Glue to observations.Detections: frames, Doppler, filters, dispatch."""

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from msg_adapters.detections import AdapterOptions, message_kind, to_detections
from msg_adapters.errors import AdapterError
from msg_adapters.odometry import EgoPoseBuffer, odometry_msg
from msg_adapters.pointcloud2 import radar_cloud_msg
from msg_adapters.pose_array import pose_array_msg
from msg_adapters.tracked_objects import tracked_object_array_msg
from msg_adapters.types import RclpyTypes, make_header

T = RclpyTypes()
OPTS = AdapterOptions(mounts={'radar': (3.0, 0.0, math.pi / 2)})


def ego():
    buf = EgoPoseBuffer('map', 'base_link')
    for t, x in ((0.0, 0.0), (1.0, 10.0)):
        to_detections(odometry_msg(T, 100.0 + t, x, 5.0, math.pi / 2, vx=10.0), buf)
    return buf


def test_radar_cloud_in_sensor_frame():
    # ego at t=100.5: (5, 5) heading +y; radar 3 m ahead -> (5, 8), looking -x (yaw pi)
    msg = radar_cloud_msg(T, make_header(T, 'radar', 100.5), [[2.0, 1.0, 0.5]], [-4.0], [12.0])
    d = to_detections(msg, ego(), OPTS)
    np.testing.assert_allclose(d.xy, [[3.0, 7.0]], atol=1e-6)
    np.testing.assert_allclose(d.sensor_xy, [[5.0, 8.0]], atol=1e-9)
    assert d.doppler[0] == -4.0 and d.rcs[0] == 12.0 and d.t[0] == 100.5
    assert d.track_id[0] == -1 and np.isnan(d.heading[0])


def test_doppler_sign_option():
    msg = radar_cloud_msg(T, make_header(T, 'radar', 100.5), [[2.0, 1.0]], [-4.0])
    d = to_detections(msg, ego(), AdapterOptions(mounts=OPTS.mounts, doppler_sign=-1))
    assert d.doppler[0] == 4.0


def test_objects_in_base_link_label_and_existence_filter():
    hdr = make_header(T, 'base_link', 100.0)       # ego at (0, 5), yaw pi/2
    msg = tracked_object_array_msg(T, hdr, [1, 2, 3, 4], [[10.0, 0.0]] * 4, [0.0] * 4, [5.0] * 4,
                                   label=[1, 7, 6, 3], existence=[0.9, 0.9, 0.9, 0.1])
    d = to_detections(msg, ego(), AdapterOptions(min_existence=0.5))
    np.testing.assert_array_equal(d.track_id, [1])
    np.testing.assert_allclose(d.xy, [[0.0, 15.0]], atol=1e-9)
    assert d.heading[0] == pytest.approx(math.pi / 2) and d.speed[0] == 5.0 and d.label[0] == 1
    d = to_detections(msg, ego(), AdapterOptions(labels=None))
    assert len(d) == 4


def test_pose_array_in_fixed_frame_passes_through():
    msg = pose_array_msg(T, make_header(T, 'map', 100.2), [[1.0, 2.0]], [0.5])
    d = to_detections(msg, EgoPoseBuffer('map'), OPTS)      # no ego needed
    np.testing.assert_allclose(d.xy, [[1.0, 2.0]])
    assert d.heading[0] == 0.5 and np.isnan(d.sensor_xy).all()


def test_errors_and_dispatch():
    msg = radar_cloud_msg(T, make_header(T, 'lidar', 100.5), [[2.0, 1.0]], [1.0])
    with pytest.raises(AdapterError) as err:
        to_detections(msg, ego(), OPTS)
    assert err.value.reason == 'unknown_frame'
    msg = radar_cloud_msg(T, make_header(T, 'radar', 300.0), [[2.0, 1.0]], [1.0])
    with pytest.raises(AdapterError) as err:
        to_detections(msg, ego(), OPTS)
    assert err.value.reason == 'no_ego_pose'
    with pytest.raises(AdapterError) as err:
        message_kind(NS(data=b''))
    assert err.value.reason == 'unknown_type'
    empty = radar_cloud_msg(T, make_header(T, 'nowhere', 1.0), np.zeros((0, 3)), [])
    assert len(to_detections(empty, EgoPoseBuffer(), OPTS)) == 0
