"""Tracked objects (ours, Autoware, derived_object_msgs) and PoseArray readers."""

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from intersection_estimator.bagio import typestore
from msg_adapters.errors import AdapterError
from msg_adapters.pose_array import pose_array_msg, read_pose_array
from msg_adapters.tracked_objects import (autoware_tracked_objects_msg, derived_object_array_msg,
                                          id_to_uuid, object_family, read_objects,
                                          tracked_object_array_msg, uuid_to_id)
from msg_adapters.types import RclpyTypes, RosbagsTypes, make_header

IDS = np.array([3, 17, 2**40 + 5, 1_000_007])
XY = np.array([[1.0, 2.0], [-30.5, 4.25], [10.0, -7.5], [0.0, 0.0]])
YAW = np.array([0.3, -2.5, math.pi / 2, 3.0])
SPEED = np.array([5.0, 0.0, 12.5, 1.0])
LABEL = np.array([1, 2, 7, 0])
EXIST = np.array([0.9, 0.5, 1.0, 0.25])


def through_cdr(msg, msgtype):
    ts = typestore()
    return ts.deserialize_cdr(ts.serialize_cdr(msg, msgtype), msgtype)


def check(objs, family, labels=LABEL, existence=EXIST):
    assert objs.family == family and objs.frame_id == 'map' and objs.stamp == pytest.approx(7.5)
    np.testing.assert_array_equal(objs.ids, IDS)
    np.testing.assert_allclose(objs.xy, XY)
    np.testing.assert_allclose(np.angle(np.exp(1j * (objs.yaw - YAW))), 0, atol=1e-9)
    np.testing.assert_allclose(objs.speed, SPEED, atol=1e-9)
    np.testing.assert_array_equal(objs.label, labels)
    np.testing.assert_allclose(objs.existence, existence, atol=1e-6)
    assert objs.ids.dtype == np.int64 and objs.label.dtype == np.int16


def test_ours_rclpy_and_rosbags():
    import intersection_estimator_msgs.msg as im
    T = RclpyTypes()
    msg = tracked_object_array_msg(T, make_header(T, 'map', 7.5), IDS, XY, YAW, SPEED, LABEL, EXIST)
    assert isinstance(msg, im.TrackedObjectArray)
    check(read_objects(msg), 'ours')
    R = RosbagsTypes(typestore())
    msg = tracked_object_array_msg(R, make_header(R, 'map', 7.5), IDS, XY, YAW, SPEED, LABEL, EXIST)
    check(read_objects(through_cdr(msg, 'intersection_estimator_msgs/msg/TrackedObjectArray')), 'ours')


def test_ours_heading_from_velocity_when_orientation_missing():
    T = RclpyTypes()
    msg = tracked_object_array_msg(T, make_header(T, 'map', 7.5), [1, 2], XY[:2], [np.nan, np.nan],
                                   [0.0, 0.0])
    msg.objects[0].velocity.x, msg.objects[0].velocity.y = 0.0, -3.0
    objs = read_objects(msg)
    assert objs.yaw[0] == pytest.approx(-math.pi / 2) and np.isnan(objs.yaw[1])


def test_autoware_rosbags():
    R = RosbagsTypes(typestore())
    msg = autoware_tracked_objects_msg(R, make_header(R, 'map', 7.5), IDS, XY, YAW, SPEED, LABEL, EXIST)
    back = through_cdr(msg, 'autoware_perception_msgs/msg/TrackedObjects')
    assert object_family(back) == 'autoware'
    check(read_objects(back), 'autoware')


def test_autoware_heading_rules_and_best_label():
    R = RosbagsTypes(typestore())
    msg = autoware_tracked_objects_msg(R, make_header(R, 'map', 7.5), [1, 2, 3, 4], np.zeros((4, 2)),
                                       [0.5, 0.5, 0.5, 0.5], [0.0, 0.0, 0.0, 0.0])
    o = msg.objects
    o[0].kinematics.twist_with_covariance.twist.linear.x = -4.0      # sign-unknown axis, driving backwards
    o[0].kinematics.orientation_availability = 1
    o[1].kinematics.twist_with_covariance.twist.linear.y = 2.0       # lateral velocity in the object frame
    o[2].kinematics.orientation_availability = 0                     # standing, orientation unknown
    Cls = R.get('autoware_perception_msgs/msg/ObjectClassification')
    o[3].classification = [Cls(label=7, probability=0.2), Cls(label=3, probability=0.7),
                           Cls(label=1, probability=0.1)]
    objs = read_objects(through_cdr(msg, 'autoware_perception_msgs/msg/TrackedObjects'))
    assert objs.yaw[0] == pytest.approx(0.5 - math.pi)
    assert objs.yaw[1] == pytest.approx(0.5 + math.pi / 2)
    assert np.isnan(objs.yaw[2]) and objs.yaw[3] == pytest.approx(0.5)
    assert objs.label[3] == 3 and objs.speed[0] == pytest.approx(4.0)


def test_uuid_ids_stable_and_non_negative():
    for i in (0, 1, 2**62, 2**63 - 1):
        assert uuid_to_id(id_to_uuid(i)) == i
    assert uuid_to_id(np.full(16, 255, np.uint8)) == 2**63 - 1


def test_derived_objects_rosbags():
    R = RosbagsTypes(typestore())
    msg = derived_object_array_msg(R, make_header(R, 'map', 7.5), IDS[:2], XY[:2], YAW[:2], SPEED[:2],
                                   [1, 7])
    objs = read_objects(through_cdr(msg, 'derived_object_msgs/msg/ObjectArray'))
    assert objs.family == 'derived'
    np.testing.assert_array_equal(objs.ids, IDS[:2])
    np.testing.assert_array_equal(objs.label, [1, 7])      # CAR -> CAR, PEDESTRIAN -> PEDESTRIAN
    np.testing.assert_allclose(objs.yaw, YAW[:2])
    np.testing.assert_allclose(objs.speed, SPEED[:2])


def test_empty_unknown_and_non_finite():
    hdr = NS(frame_id='map', stamp=NS(sec=1, nanosec=0))
    assert len(read_objects(NS(header=hdr, objects=[]))) == 0
    with pytest.raises(AdapterError) as err:
        read_objects(NS(header=hdr, objects=[NS(foo=1)]))
    assert err.value.reason == 'unknown_type'
    T = RclpyTypes()
    msg = tracked_object_array_msg(T, make_header(T, 'map', 1.0), [1, 2], XY[:2], YAW[:2], SPEED[:2])
    msg.objects[0].pose.position.x = float('nan')
    objs = read_objects(msg)
    assert len(objs) == 1 and objs.dropped == 1 and objs.ids[0] == 2


def test_pose_array_rclpy_and_rosbags():
    from geometry_msgs.msg import PoseArray
    yaw = np.array([0.1, np.nan, -3.0])
    for T in (RclpyTypes(), RosbagsTypes(typestore())):
        msg = pose_array_msg(T, make_header(T, 'map', 2.0), XY[:3], yaw)
        if isinstance(T, RosbagsTypes):
            msg = through_cdr(msg, 'geometry_msgs/msg/PoseArray')
        else:
            assert isinstance(msg, PoseArray)
        res = read_pose_array(msg)
        np.testing.assert_allclose(res.xy, XY[:3])
        np.testing.assert_allclose(res.yaw, yaw)


def test_pose_array_non_unit_quaternion():
    hdr = NS(frame_id='map', stamp=NS(sec=1, nanosec=0))
    h = 0.7
    q = NS(x=0.0, y=0.0, z=3 * math.sin(h / 2), w=3 * math.cos(h / 2))
    res = read_pose_array(NS(header=hdr, poses=[NS(position=NS(x=1.0, y=2.0, z=0.0), orientation=q)]))
    assert res.yaw[0] == pytest.approx(h)


def _uuid(i):
    return NS(uuid=id_to_uuid(i))


def _kin_pose(x, y, yaw):
    return NS(pose=NS(position=NS(x=x, y=y, z=0.0),
                      orientation=NS(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))))


def test_autoware_predicted_and_detected_objects():
    hdr = NS(frame_id='map', stamp=NS(sec=7, nanosec=500_000_000))
    cls = [NS(label=2, probability=0.8), NS(label=1, probability=0.2)]
    lin = NS(twist=NS(linear=NS(x=0.0, y=4.0, z=0.0)))
    pred = NS(header=hdr, objects=[NS(object_id=_uuid(42), existence_probability=0.7, classification=cls,
                                      kinematics=NS(initial_pose_with_covariance=_kin_pose(1.0, 2.0, 0.5),
                                                    initial_twist_with_covariance=lin))])
    objs = read_objects(pred)
    assert objs.family == 'autoware_predicted' and objs.ids[0] == 42 and objs.label[0] == 2
    assert objs.yaw[0] == pytest.approx(0.5 + math.pi / 2) and objs.speed[0] == 4.0
    old = NS(header=hdr, objects=[NS(id=_uuid(9), classification=NS(label=3, probability=1.0),
                                     kinematics=pred.objects[0].kinematics)])
    objs = read_objects(old)              # pre-2024: 'id' and one classification
    assert objs.ids[0] == 9 and objs.label[0] == 3 and objs.existence[0] == 1.0
    det = NS(header=hdr, objects=[NS(existence_probability=0.9, classification=cls,
                                     kinematics=NS(pose_with_covariance=_kin_pose(5.0, 6.0, -1.0),
                                                   twist_with_covariance=lin, orientation_availability=2))])
    objs = read_objects(det)
    assert objs.family == 'autoware_detected' and objs.ids[0] == -1
    np.testing.assert_allclose(objs.xy, [[5.0, 6.0]])
