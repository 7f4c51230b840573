"""``geometry_msgs/msg/PoseArray`` (camera / lidar detections without identity) <-> numpy.

The orientation of each pose is the driving direction; a zero quaternion means "no
heading" (NaN).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._common import header_of, yaw_from_quat
from .errors import AdapterError, guarded

__all__ = ['PoseList', 'read_pose_array', 'pose_array_msg']


@dataclass
class PoseList:
    """Positions (N, 2) and yaw (N,) [rad, NaN = unknown] in the message frame."""

    frame_id: str
    stamp: float
    xy: np.ndarray
    yaw: np.ndarray
    dropped: int = 0

    def __len__(self) -> int:
        return len(self.xy)


@guarded
def read_pose_array(msg, *, max_points: int | None = None) -> PoseList:
    """PoseArray -> :class:`PoseList`; poses with a non-finite position are dropped."""
    frame_id, stamp = header_of(msg)
    poses = msg.poses
    if max_points is not None and len(poses) > max_points:
        raise AdapterError('too_large', f'{len(poses)} poses > max_points {max_points}')
    a = np.array([(p.position.x, p.position.y, p.orientation.x, p.orientation.y,
                   p.orientation.z, p.orientation.w) for p in poses], dtype=np.float64).reshape(-1, 6)
    ok = np.isfinite(a[:, :2]).all(axis=1)
    q = np.where(np.isfinite(a[:, 2:]), a[:, 2:], 0.0)
    yaw = yaw_from_quat(*q.T)
    return PoseList(frame_id, stamp, a[ok, :2], yaw[ok], int((~ok).sum()))


def pose_msg(types, x, y, yaw, z=0.0):
    """``geometry_msgs/Pose`` at (x, y, z) with yaw (NaN -> zero quaternion)."""
    yaw = float(yaw)
    if math.isfinite(yaw):
        qx, qy, qz, qw = 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)
    else:
        qx = qy = qz = qw = 0.0
    return types.get('geometry_msgs/msg/Pose')(
        position=types.get('geometry_msgs/msg/Point')(x=float(x), y=float(y), z=float(z)),
        orientation=types.get('geometry_msgs/msg/Quaternion')(x=qx, y=qy, z=qz, w=qw))


def pose_array_msg(types, header, xy, yaw=None):
    """PoseArray from positions (N, 2) and yaw (N,) (None / NaN: no heading)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    yaw = np.full(len(xy), np.nan) if yaw is None else np.asarray(yaw, float).reshape(len(xy))
    return types.get('geometry_msgs/msg/PoseArray')(
        header=header, poses=[pose_msg(types, x, y, h) for (x, y), h in zip(xy, yaw)])
