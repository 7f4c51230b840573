"""``nav_msgs/msg/Odometry`` -> ego pose, and the ego pose buffer that puts inputs in the fixed frame.

Frames (REP 105): the odometry's ``header.frame_id`` is the fixed frame (``map`` or
``odom``), its ``child_frame_id`` the ego frame (``base_link``). Sensors are mounted on the
ego with a static offset ``(x, y, yaw)`` in the ego frame, given per frame id
(``mounts = {'radar': (3.7, 0.0, 0.0)}``). :meth:`EgoPoseBuffer.transform` gives the pose of
any of these frames in the fixed frame at a stamp: linear interpolation of position,
shortest-arc interpolation of yaw, constant-velocity extrapolation up to ``tolerance``
past the newest pose (sensors are often a few ms ahead of odometry), the oldest pose up to
``tolerance`` before it.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from ._common import header_of, norm_frame, quat_from_yaw, yaw_from_quat
from .errors import AdapterError, guarded
from .types import make_header

__all__ = ['EgoPose', 'EgoPoseBuffer', 'read_odometry', 'read_tf_static', 'apply', 'odometry_msg']


@dataclass(frozen=True)
class EgoPose:
    """Ego pose in ``frame_id``; vx, vy in the child frame [m/s], yaw_rate [rad/s]."""

    stamp: float
    frame_id: str
    child_frame_id: str
    x: float
    y: float
    yaw: float
    vx: float = 0.0
    vy: float = 0.0
    yaw_rate: float = 0.0


@guarded
def read_odometry(msg) -> EgoPose:
    """Odometry -> :class:`EgoPose`; a non-finite pose raises ``AdapterError('non_finite')``."""
    frame_id, stamp = header_of(msg)
    p = msg.pose.pose
    tw = msg.twist.twist
    yaw = float(yaw_from_quat(p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w))
    pose = EgoPose(stamp, frame_id, norm_frame(msg.child_frame_id), float(p.position.x),
                   float(p.position.y), yaw, float(tw.linear.x), float(tw.linear.y),
                   float(tw.angular.z))
    if not all(math.isfinite(v) for v in (pose.x, pose.y, pose.yaw)):
        raise AdapterError('non_finite', f'ego pose ({pose.x}, {pose.y}, {pose.yaw})')
    return pose


@guarded
def read_tf_static(msg, base_frame: str = 'base_link') -> dict[str, tuple[float, float, float]]:
    """Mounts ``{child: (x, y, yaw)}`` of the transforms from ``base_frame`` in a
    ``tf2_msgs/TFMessage`` (e.g. ``/tf_static``): what :meth:`EgoPoseBuffer.transform` takes."""
    out = {}
    for tf in msg.transforms:
        if norm_frame(tf.header.frame_id) != norm_frame(base_frame):
            continue
        tr, q = tf.transform.translation, tf.transform.rotation
        yaw = float(yaw_from_quat(q.x, q.y, q.z, q.w))
        mount = (float(tr.x), float(tr.y), yaw)
        if all(math.isfinite(v) for v in mount):
            out[norm_frame(tf.child_frame_id)] = mount
    return out


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class EgoPoseBuffer:
    """Bounded, time-sorted buffer of ego poses with interpolation and frame transforms.

    fixed_frame: the frame estimates live in (odometry in another frame is refused);
    base_frame: the ego frame name (the odometry child frame is accepted as well);
    maxlen: poses kept; tolerance: seconds a stamp may lie outside the buffer;
    reset_after: a stamp this far before the newest one clears the buffer (bag loop,
    simulation restart) instead of being inserted.
    """

    def __init__(self, fixed_frame: str = 'map', base_frame: str = 'base_link',
                 maxlen: int = 2000, tolerance: float = 0.2, reset_after: float = 1.0):
        self.fixed_frame = norm_frame(fixed_frame)
        self.base_frame = norm_frame(base_frame)
        self.maxlen = int(maxlen)
        self.tolerance = float(tolerance)
        self.reset_after = float(reset_after)
        self.resets = 0
        self._t: list[float] = []
        self._p: list[EgoPose] = []
        self._child = self.base_frame

    def __len__(self) -> int:
        return len(self._t)

    @property
    def latest(self) -> EgoPose | None:
        return self._p[-1] if self._p else None

    def clear(self) -> None:
        self._t.clear()
        self._p.clear()

    def add(self, pose: EgoPose) -> None:
        """Insert by stamp (same stamp replaces); see ``reset_after``."""
        if pose.frame_id and pose.frame_id != self.fixed_frame:
            raise AdapterError('frame_mismatch',
                               f'odometry in {pose.frame_id!r}, fixed frame is {self.fixed_frame!r}')
        if self._t and pose.stamp < self._t[-1] - self.reset_after:
            self.clear()
            self.resets += 1
        if pose.child_frame_id:
            self._child = pose.child_frame_id
        i = bisect.bisect_left(self._t, pose.stamp)
        if i < len(self._t) and self._t[i] == pose.stamp:
            self._p[i] = pose
            return
        self._t.insert(i, pose.stamp)
        self._p.insert(i, pose)
        if len(self._t) > self.maxlen:
            del self._t[0], self._p[0]

    def add_msg(self, msg) -> EgoPose:
        """Read an Odometry message and add it; returns the pose."""
        pose = read_odometry(msg)
        self.add(pose)
        return pose

    def pose_at(self, t: float) -> tuple[float, float, float]:
        """Ego (x, y, yaw) in the fixed frame at ``t``."""
        if not self._t:
            raise AdapterError('no_ego_pose', 'no odometry received yet')
        if not math.isfinite(t):
            raise AdapterError('non_finite', f'stamp {t}')
        t0, t1 = self._t[0], self._t[-1]
        if t < t0 - self.tolerance or t > t1 + self.tolerance:
            raise AdapterError('no_ego_pose', f'stamp {t:.3f} outside ego poses [{t0:.3f}, {t1:.3f}] '
                                              f'+- {self.tolerance} s')
        if t >= t1:
            return self._extrapolate(self._p[-1], t - t1)
        if t <= t0:
            p = self._p[0]
            return p.x, p.y, p.yaw
        i = bisect.bisect_right(self._t, t)
        a, b = self._p[i - 1], self._p[i]
        w = (t - a.stamp) / (b.stamp - a.stamp)
        return (a.x + w * (b.x - a.x), a.y + w * (b.y - a.y),
                _wrap(a.yaw + w * _wrap(b.yaw - a.yaw)))

    @staticmethod
    def _extrapolate(p: EgoPose, dt: float):
        c, s = math.cos(p.yaw), math.sin(p.yaw)
        return (p.x + dt * (c * p.vx - s * p.vy), p.y + dt * (s * p.vx + c * p.vy),
                _wrap(p.yaw + dt * p.yaw_rate))

    def transform(self, frame_id: str, stamp: float, mounts=None) -> tuple[float, float, float]:
        """Pose (x, y, yaw) of ``frame_id`` in the fixed frame at ``stamp``.

        The fixed frame is the identity (no ego pose needed); the ego frame is the ego
        pose; a frame in ``mounts`` (``{frame: (x, y, yaw)}`` in the ego frame) is the ego
        pose composed with its mount. Anything else: ``AdapterError('unknown_frame')``.
        """
        frame = norm_frame(frame_id)
        if frame == self.fixed_frame:
            return 0.0, 0.0, 0.0
        mounts = mounts or {}
        if frame in (self.base_frame, self._child):
            mx, my, myaw = 0.0, 0.0, 0.0
        elif frame in mounts:
            mx, my, myaw = (float(v) for v in mounts[frame])
        else:
            raise AdapterError('unknown_frame', f'{frame!r} is not {self.fixed_frame!r}, '
                                                f'{self.base_frame!r} or a mount {sorted(mounts)}')
        ex, ey, eyaw = self.pose_at(stamp)
        c, s = math.cos(eyaw), math.sin(eyaw)
        return ex + c * mx - s * my, ey + s * mx + c * my, _wrap(eyaw + myaw)

    def velocity(self, frame_id: str, stamp: float, mounts=None, h: float = 0.05) -> np.ndarray:
        """Velocity (vx, vy) of the origin of ``frame_id`` in the fixed frame at ``stamp``
        [m/s]: the central difference of :meth:`transform` over +-``h`` within the poses (a
        mounted sensor's lever arm on a turning ego included; the odometry's twist is not
        needed). Beyond the newest pose the twist extrapolates, as in :meth:`pose_at`."""
        if not self._t:
            raise AdapterError('no_ego_pose', 'no odometry received yet')
        a = max(stamp - h, self._t[0])
        b = min(stamp + h, max(self._t[-1], stamp))
        if b - a < 1e-3:                  # one pose: its twist
            a, b = stamp, stamp + h
        pa = self.transform(frame_id, a, mounts)
        pb = self.transform(frame_id, b, mounts)
        return np.array([(pb[0] - pa[0]) / (b - a), (pb[1] - pa[1]) / (b - a)])

    def to_fixed(self, frame_id: str, stamp: float, xy, mounts=None) -> np.ndarray:
        """Points (N, 2) in ``frame_id`` at ``stamp`` -> fixed frame (N, 2)."""
        return apply(self.transform(frame_id, stamp, mounts), xy)


def apply(tf, xy) -> np.ndarray:
    """Apply a 2-D pose (x, y, yaw) to points (N, 2)."""
    x, y, yaw = tf
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if x == 0.0 and y == 0.0 and yaw == 0.0:
        return xy
    c, s = math.cos(yaw), math.sin(yaw)
    return np.stack([x + c * xy[:, 0] - s * xy[:, 1], y + s * xy[:, 0] + c * xy[:, 1]], axis=1)


def odometry_msg(types, stamp: float, x: float, y: float, yaw: float, vx: float = 0.0,
                 vy: float = 0.0, yaw_rate: float = 0.0, frame_id: str = 'map',
                 child_frame_id: str = 'base_link'):
    """Odometry ``frame_id`` -> ``child_frame_id``; twist in the child frame."""
    g = types.get
    qx, qy, qz, qw = (float(v) for v in quat_from_yaw(yaw))
    pose = g('geometry_msgs/msg/Pose')(
        position=g('geometry_msgs/msg/Point')(x=float(x), y=float(y), z=0.0),
        orientation=g('geometry_msgs/msg/Quaternion')(x=qx, y=qy, z=qz, w=qw))
    V = g('geometry_msgs/msg/Vector3')
    twist = g('geometry_msgs/msg/Twist')(linear=V(x=float(vx), y=float(vy), z=0.0),
                                          angular=V(x=0.0, y=0.0, z=float(yaw_rate)))
    return g('nav_msgs/msg/Odometry')(
        header=make_header(types, frame_id, stamp), child_frame_id=child_frame_id,
        pose=g('geometry_msgs/msg/PoseWithCovariance')(pose=pose),
        twist=g('geometry_msgs/msg/TwistWithCovariance')(twist=twist))
