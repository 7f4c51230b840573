"""Tracked objects of three message families <-> numpy, one entry point :func:`read_objects`.

Families (detected by their fields, so rclpy and rosbags messages read alike):

* ``intersection_estimator_msgs/msg/TrackedObjectArray`` (ours): ``uint64 id``, pose whose
  yaw is the driving direction, velocity in the header frame, ``classification`` (Autoware
  label ids), ``existence_probability``.
* ``autoware_perception_msgs/msg/TrackedObjects``: UUID ``object_id`` (first 8 bytes ->
  a stable non-negative int64), ``existence_probability``, ``classification[]`` (the
  highest-probability label wins), ``kinematics.pose_with_covariance.pose`` and
  ``kinematics.twist_with_covariance.twist.linear`` in the *object* frame. Heading = pose
  yaw + direction of that velocity when moving; when standing, the pose yaw if
  ``orientation_availability`` is AVAILABLE, else unknown (NaN).
* ``autoware_perception_msgs/msg/PredictedObjects`` (what Autoware's perception publishes
  last): as TrackedObjects with ``kinematics.initial_pose_with_covariance`` /
  ``initial_twist_with_covariance``; ``DetectedObjects`` (no identity: ids -1).
  ``autoware_auto_perception_msgs`` (pre-2024 names) read the same.
* ``derived_object_msgs/msg/ObjectArray``: ``uint32 id``, pose (yaw = heading), twist;
  its classification is mapped to Autoware label ids; existence is 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._common import header_of, yaw_from_quat
from .errors import AdapterError, guarded
from .pose_array import pose_msg

__all__ = ['ObjectList', 'read_objects', 'object_family', 'uuid_to_id', 'id_to_uuid',
           'DERIVED_TO_AUTOWARE', 'tracked_object_array_msg', 'autoware_tracked_objects_msg',
           'derived_object_array_msg', 'MIN_SPEED_FOR_HEADING']

#: Below this speed [m/s] the velocity direction is not trusted as heading.
MIN_SPEED_FOR_HEADING = 0.5
_MASK63 = (1 << 63) - 1
# Autoware ObjectClassification labels
UNKNOWN, CAR, TRUCK, BUS, TRAILER, MOTORCYCLE, BICYCLE, PEDESTRIAN, ANIMAL, HAZARD = range(10)
#: derived_object_msgs/Object CLASSIFICATION_* -> Autoware label (barrier/sign -> HAZARD).
DERIVED_TO_AUTOWARE = {0: UNKNOWN, 1: UNKNOWN, 2: UNKNOWN, 3: UNKNOWN, 4: PEDESTRIAN,
                       5: BICYCLE, 6: CAR, 7: TRUCK, 8: MOTORCYCLE, 9: CAR, 10: HAZARD, 11: HAZARD}
AUTOWARE_TO_DERIVED = {UNKNOWN: 0, CAR: 6, TRUCK: 7, BUS: 7, TRAILER: 7, MOTORCYCLE: 8,
                       BICYCLE: 5, PEDESTRIAN: 4}
_AVAILABLE = 2


@dataclass
class ObjectList:
    """Objects in the message frame: ids int64 (>= 0; -1 without identity), xy (N, 2),
    yaw = heading (N,) [rad, NaN unknown], speed (N,) [m/s], label int16 (Autoware ids),
    existence (N,) in [0, 1]."""

    frame_id: str
    stamp: float
    ids: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    label: np.ndarray
    existence: np.ndarray
    family: str = ''
    dropped: int = 0

    def __len__(self) -> int:
        return len(self.xy)


def uuid_to_id(uuid) -> int:
    """16-byte UUID -> stable non-negative int64 (its first 8 bytes, little endian)."""
    b = bytes(np.asarray(uuid, dtype=np.uint8).reshape(-1)[:8].tobytes())
    if len(b) != 8:
        raise AdapterError('malformed', f'UUID of {len(b)} bytes')
    return int.from_bytes(b, 'little') & _MASK63


def id_to_uuid(i: int) -> np.ndarray:
    """Inverse of :func:`uuid_to_id` for ids < 2**63 (the other 8 bytes are zero)."""
    return np.frombuffer(int(i).to_bytes(8, 'little') + bytes(8), dtype=np.uint8).copy()


def object_family(msg) -> str:
    """'ours' | 'autoware' | 'autoware_predicted' | 'autoware_detected' | 'derived' | 'empty'
    by the fields of the first object."""
    objs = msg.objects
    if len(objs) == 0:
        return 'empty'
    o = objs[0]
    k = getattr(o, 'kinematics', None)
    if k is not None:
        if hasattr(k, 'initial_pose_with_covariance'):
            return 'autoware_predicted'
        if hasattr(o, 'object_id'):
            return 'autoware'
        if hasattr(k, 'pose_with_covariance'):
            return 'autoware_detected'
    if hasattr(o, 'velocity') and hasattr(o, 'existence_probability'):
        return 'ours'
    if hasattr(o, 'twist') and hasattr(o, 'pose'):
        return 'derived'
    raise AdapterError('unknown_type', f'objects of type {type(o).__name__}')


def _pose_row(p):
    return (p.position.x, p.position.y, p.orientation.x, p.orientation.y,
            p.orientation.z, p.orientation.w)


def _best_label(classes) -> int:
    """Label of the most probable classification (a list, or one classification)."""
    best, prob = 0, -np.inf
    for c in (classes if hasattr(classes, '__len__') else [classes]):
        if float(c.probability) > prob:
            best, prob = int(c.label), float(c.probability)
    return best


def _autoware_row(o, family):
    k = o.kinematics
    if family == 'autoware_predicted':  # PredictedObjects: id (old) or object_id (current)
        uuid = getattr(o, 'object_id', None) or o.id
        pose, twist = k.initial_pose_with_covariance.pose, k.initial_twist_with_covariance.twist
        avail = _AVAILABLE
    else:
        uuid = getattr(o, 'object_id', None)
        pose, twist = k.pose_with_covariance.pose, k.twist_with_covariance.twist
        avail = k.orientation_availability
    oid = uuid_to_id(uuid.uuid) if uuid is not None else -1
    v = twist.linear
    return (oid, *_pose_row(pose), v.x, v.y, _best_label(o.classification),
            getattr(o, 'existence_probability', 1.0), avail)


def _rows(msg, family):
    """ids (N,) and (N, 11) rows: x, y, qx, qy, qz, qw, vx, vy, label, existence, availability."""
    out = []
    for o in msg.objects:
        if family.startswith('autoware'):
            out.append(_autoware_row(o, family))
        elif family == 'ours':
            out.append((int(o.id) & _MASK63, *_pose_row(o.pose), o.velocity.x, o.velocity.y,
                        o.classification, o.existence_probability, _AVAILABLE))
        else:
            out.append((int(o.id), *_pose_row(o.pose), o.twist.linear.x, o.twist.linear.y,
                        DERIVED_TO_AUTOWARE.get(int(o.classification), UNKNOWN), 1.0, _AVAILABLE))
    ids = np.array([r[0] for r in out], dtype=np.int64)
    num = np.array([r[1:] for r in out], dtype=np.float64).reshape(-1, 11)
    return ids, num


@guarded
def read_objects(msg, *, min_speed_for_heading: float = MIN_SPEED_FOR_HEADING) -> ObjectList:
    """Any supported tracked-object array -> :class:`ObjectList` (message frame).

    Objects with a non-finite position are dropped and counted.
    """
    frame_id, stamp = header_of(msg)
    family = object_family(msg)
    if family == 'empty':
        z = np.zeros(0)
        return ObjectList(frame_id, stamp, np.zeros(0, np.int64), np.zeros((0, 2)), z, z.copy(),
                          np.zeros(0, np.int16), z.copy(), family)
    ids, a = _rows(msg, family)
    xy, q, v = a[:, 0:2], a[:, 2:6], a[:, 6:8]
    q = np.where(np.isfinite(q), q, 0.0)
    qyaw = yaw_from_quat(*q.T)
    speed = np.hypot(v[:, 0], v[:, 1])
    moving = np.isfinite(speed) & (speed >= min_speed_for_heading)
    vdir = np.arctan2(v[:, 1], v[:, 0])
    if family.startswith('autoware'):   # twist in the object frame
        yaw = np.where(moving, qyaw + vdir, np.where(a[:, 10] == _AVAILABLE, qyaw, np.nan))
        yaw = (yaw + np.pi) % (2.0 * np.pi) - np.pi
    elif family == 'ours':
        yaw = np.where(np.isfinite(qyaw), qyaw, np.where(moving, vdir, np.nan))
    else:
        yaw = qyaw
    ok = np.isfinite(xy).all(axis=1)
    label = np.clip(np.nan_to_num(a[:, 8]), -32768, 32767).astype(np.int16)
    existence = np.nan_to_num(a[:, 9], nan=0.0)
    return ObjectList(frame_id, stamp, ids[ok], xy[ok], yaw[ok],
                      np.where(np.isfinite(speed), speed, np.nan)[ok], label[ok], existence[ok],
                      family, int((~ok).sum()))


def _cols(xy, *cols):
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    n = len(xy)
    return xy, [np.broadcast_to(np.asarray(c), (n,)) for c in cols]


def _vec3(types, x=0.0, y=0.0, z=0.0):
    return types.get('geometry_msgs/msg/Vector3')(x=float(x), y=float(y), z=float(z))


def tracked_object_array_msg(types, header, ids, xy, yaw, speed, label=CAR, existence=1.0):
    """Our ``TrackedObjectArray``: velocity = speed along yaw, in the header frame."""
    xy, (ids, yaw, speed, label, existence) = _cols(xy, ids, yaw, speed, label, existence)
    Obj = types.get('intersection_estimator_msgs/msg/TrackedObject')
    objs = [Obj(id=int(i), pose=pose_msg(types, p[0], p[1], h),
                velocity=_vec3(types, s * np.cos(h), s * np.sin(h)),
                classification=int(lb), existence_probability=float(e))
            for i, p, h, s, lb, e in zip(ids, xy, yaw, speed, label, existence)]
    return types.get('intersection_estimator_msgs/msg/TrackedObjectArray')(header=header, objects=objs)


def autoware_tracked_objects_msg(types, header, ids, xy, yaw, speed, label=CAR, existence=1.0,
                                 dimensions=(4.5, 1.8, 1.5)):
    """``autoware_perception_msgs/TrackedObjects``: twist along the object's x axis."""
    xy, (ids, yaw, speed, label, existence) = _cols(xy, ids, yaw, speed, label, existence)
    g = types.get
    Obj, Kin, Cls = (g('autoware_perception_msgs/msg/TrackedObject'),
                     g('autoware_perception_msgs/msg/TrackedObjectKinematics'),
                     g('autoware_perception_msgs/msg/ObjectClassification'))
    PwC, TwC, Tw = (g('geometry_msgs/msg/PoseWithCovariance'),
                    g('geometry_msgs/msg/TwistWithCovariance'), g('geometry_msgs/msg/Twist'))
    shape = g('autoware_perception_msgs/msg/Shape')(type=0, dimensions=_vec3(types, *dimensions))
    objs = []
    for i, p, h, s, lb, e in zip(ids, xy, yaw, speed, label, existence):
        kin = Kin(pose_with_covariance=PwC(pose=pose_msg(types, p[0], p[1], h)),
                  twist_with_covariance=TwC(twist=Tw(linear=_vec3(types, s))),
                  orientation_availability=_AVAILABLE if np.isfinite(h) else 0,
                  is_stationary=bool(s < 0.1))
        objs.append(Obj(object_id=g('unique_identifier_msgs/msg/UUID')(uuid=id_to_uuid(i)),
                        existence_probability=float(e),
                        classification=[Cls(label=int(lb), probability=1.0)],
                        kinematics=kin, shape=shape))
    return g('autoware_perception_msgs/msg/TrackedObjects')(header=header, objects=objs)


def derived_object_array_msg(types, header, ids, xy, yaw, speed, label=CAR):
    """``derived_object_msgs/ObjectArray`` (tracked, classified), twist in the header frame."""
    xy, (ids, yaw, speed, label) = _cols(xy, ids, yaw, speed, label)
    g = types.get
    Obj = g('derived_object_msgs/msg/Object')
    objs = [Obj(header=header, id=int(i), detection_level=1, object_classified=True,
                pose=pose_msg(types, p[0], p[1], h),
                twist=g('geometry_msgs/msg/Twist')(linear=_vec3(types, s * np.cos(h), s * np.sin(h))),
                classification=AUTOWARE_TO_DERIVED.get(int(lb), 0), classification_certainty=255)
            for i, p, h, s, lb in zip(ids, xy, yaw, speed, label)]
    return g('derived_object_msgs/msg/ObjectArray')(header=header, objects=objs)
