"""Small helpers shared by the adapters: stamps, frames, yaw <-> quaternion."""

from __future__ import annotations

import math

import numpy as np

from .errors import AdapterError

__all__ = ['stamp_s', 'header_of', 'norm_frame', 'yaw_from_quat', 'quat_from_yaw',
           'split_stamp', 'as_u8']


def stamp_s(stamp) -> float:
    """``builtin_interfaces/Time`` -> seconds (float); non-finite or negative -> error."""
    t = float(stamp.sec) + 1e-9 * float(stamp.nanosec)
    if not math.isfinite(t):
        raise AdapterError('non_finite', f'stamp {t}')
    return t


def norm_frame(frame_id) -> str:
    """Frame id without the ROS 1 leading slash."""
    return str(frame_id).lstrip('/')


def header_of(msg) -> tuple[str, float]:
    """(frame_id, stamp_s) of a message with a ``header``."""
    return norm_frame(msg.header.frame_id), stamp_s(msg.header.stamp)


def split_stamp(t: float) -> tuple[int, int]:
    """Seconds -> (sec, nanosec) with the carry done right (nanosec < 1e9)."""
    ns = int(round(float(t) * 1e9))
    return ns // 1_000_000_000, ns % 1_000_000_000


def yaw_from_quat(qx, qy, qz, qw) -> np.ndarray:
    """Yaw of (arrays of) quaternions, scale invariant; NaN for a zero quaternion."""
    qx, qy, qz, qw = (np.asarray(q, dtype=np.float64) for q in (qx, qy, qz, qw))
    with np.errstate(over='ignore', invalid='ignore'):   # absurd quaternions give NaN, quietly
        yaw = np.arctan2(2.0 * (qw * qz + qx * qy), qw * qw + qx * qx - qy * qy - qz * qz)
        n2 = qx * qx + qy * qy + qz * qz + qw * qw
    return np.where(n2 > 1e-12, yaw, np.nan)


def quat_from_yaw(yaw) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, z, w) of rotations about z by ``yaw``."""
    h = 0.5 * np.asarray(yaw, dtype=np.float64)
    z = np.zeros_like(h)
    with np.errstate(invalid='ignore'):                  # a non-finite yaw gives a NaN quaternion
        return z, z, np.sin(h), np.cos(h)


def as_u8(data) -> np.ndarray:
    """A message's ``uint8[]`` (numpy array, array.array, bytes or list) as a uint8 view."""
    if isinstance(data, np.ndarray):
        if data.dtype == np.uint8:
            return np.ascontiguousarray(data).reshape(-1)
        return np.asarray(data).astype(np.uint8).reshape(-1)
    if isinstance(data, (bytes, bytearray, memoryview)) or hasattr(data, 'typecode'):
        return np.frombuffer(memoryview(data).cast('B'), dtype=np.uint8)
    return np.asarray(list(data), dtype=np.uint8)
