"""A small 2-D TF buffer over ``tf2_msgs/TFMessage`` (``/tf``, ``/tf_static``), no rclpy.

The node feeds it what it receives live, the replay what a bag holds (rosbags messages:
the buffer only reads ``transforms[i].header``, ``child_frame_id`` and
``transform.translation / rotation``). The estimator works in the ground plane, so every
transform is kept as ``(x, y, yaw)`` (REP 103: z up; roll and pitch are ignored).

Two uses (REP 105):

* sensor mounts: :class:`TfMounts` gives the pose of a sensor frame in ``base_link`` from
  the tree and falls back to the ``mount_*`` parameters for frames the tree lacks;
* odometry in ``odom``: :meth:`TfBuffer.lookup` gives ``map -> odom`` at the pose stamp, so
  poses reach the fixed frame even when the localisation publishes its correction on /tf.

Static transforms are kept for ever (last one per child wins); dynamic ones per child in a
time-sorted, bounded buffer, interpolated (position linearly, yaw on the shortest arc) and
held up to ``tolerance`` seconds past the newest (a map -> odom correction at a few Hz).
"""

from __future__ import annotations

import bisect
from collections.abc import Mapping
import math

from msg_adapters._common import norm_frame, yaw_from_quat

__all__ = ['TfBuffer', 'TfMounts', 'compose', 'invert']

Pose2 = tuple[float, float, float]
MAX_DEPTH = 64        # longer parent chains are refused (a cycle in a broken tree)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def compose(a: Pose2, b: Pose2) -> Pose2:
    """``a`` then ``b``: the pose ``b`` (given in frame ``a``) in ``a``'s parent."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], _wrap(a[2] + b[2])


def invert(a: Pose2) -> Pose2:
    c, s = math.cos(a[2]), math.sin(a[2])
    return -c * a[0] - s * a[1], s * a[0] - c * a[1], _wrap(-a[2])


class TfBuffer:
    """Transforms ``parent -> child`` as 2-D poses of the child in its parent."""

    def __init__(self, cache_s: float = 10.0, maxlen: int = 1000, tolerance: float = 0.5):
        self.cache_s, self.maxlen, self.tolerance = float(cache_s), int(maxlen), float(tolerance)
        self._static: dict[str, tuple[str, Pose2]] = {}
        self._dyn: dict[str, tuple[str, list[float], list[Pose2]]] = {}
        self.rejected = 0     # transforms refused (non-finite, self-parented, empty frames)

    def clear(self, static: bool = False) -> None:
        """Forget dynamic transforms (a time-base jump), and the static ones too if asked."""
        self._dyn.clear()
        if static:
            self._static.clear()

    def frames(self) -> set[str]:
        return set(self._static) | set(self._dyn)

    def add(self, msg, static: bool) -> int:
        """Take the transforms of a TFMessage; returns how many were usable."""
        n = 0
        for tf in getattr(msg, 'transforms', ()):
            try:
                parent, child = norm_frame(tf.header.frame_id), norm_frame(tf.child_frame_id)
                st = tf.header.stamp
                stamp = float(st.sec) + 1e-9 * float(st.nanosec)
                tr, q = tf.transform.translation, tf.transform.rotation
                pose = (float(tr.x), float(tr.y), float(yaw_from_quat(q.x, q.y, q.z, q.w)))
            except (AttributeError, TypeError, ValueError, OverflowError):
                self.rejected += 1
                continue
            if not (parent and child and parent != child and math.isfinite(stamp)
                    and all(math.isfinite(v) for v in pose)):
                self.rejected += 1
                continue
            if static:
                self._static[child] = (parent, pose)
            else:
                self._add_dynamic(parent, child, stamp, pose)
            n += 1
        return n

    def _add_dynamic(self, parent: str, child: str, stamp: float, pose: Pose2) -> None:
        old = self._dyn.get(child)
        if old is None or old[0] != parent or (old[1] and stamp < old[1][-1] - self.cache_s):
            old = self._dyn[child] = (parent, [], [])     # new parent or time went back: restart
        _, ts, ps = old
        i = bisect.bisect_left(ts, stamp)
        if i < len(ts) and ts[i] == stamp:
            ps[i] = pose
            return
        ts.insert(i, stamp)
        ps.insert(i, pose)
        while len(ts) > self.maxlen or (len(ts) > 2 and ts[0] < ts[-1] - self.cache_s):
            del ts[0], ps[0]

    def _edge(self, child: str, stamp: float | None) -> tuple[str, Pose2] | None:
        """(parent, pose of ``child`` in it) at ``stamp`` (None: the newest)."""
        if child in self._static:
            return self._static[child]
        entry = self._dyn.get(child)
        if entry is None or not entry[1]:
            return None
        parent, ts, ps = entry
        if stamp is None or stamp >= ts[-1]:
            ok = stamp is None or stamp - ts[-1] <= self.tolerance
            return (parent, ps[-1]) if ok else None
        if stamp <= ts[0]:
            return (parent, ps[0]) if ts[0] - stamp <= self.tolerance else None
        i = bisect.bisect_right(ts, stamp)
        a, b = ps[i - 1], ps[i]
        w = (stamp - ts[i - 1]) / (ts[i] - ts[i - 1])
        return parent, (a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1]), _wrap(a[2] + w * _wrap(b[2] - a[2])))

    def _to_root(self, frame: str, stamp: float | None) -> tuple[list[str], list[Pose2]] | None:
        """Frames from ``frame`` up to its root and the pose of ``frame`` in each of them."""
        chain, poses, pose = [frame], [(0.0, 0.0, 0.0)], (0.0, 0.0, 0.0)
        while len(chain) <= MAX_DEPTH:
            edge = self._edge(chain[-1], stamp)
            if edge is None:
                return chain, poses
            parent, p = edge
            pose = compose(p, pose)
            chain.append(parent)
            poses.append(pose)
        return None

    def lookup(self, target: str, source: str, stamp: float | None = None) -> Pose2 | None:
        """Pose (x, y, yaw) of frame ``source`` in frame ``target`` at ``stamp``
        (None: the newest transforms), or None when the tree does not connect them then."""
        target, source = norm_frame(target), norm_frame(source)
        if target == source:
            return 0.0, 0.0, 0.0
        up_s, up_t = self._to_root(source, stamp), self._to_root(target, stamp)
        if up_s is None or up_t is None:
            return None
        common = [f for f in up_s[0] if f in set(up_t[0])]
        if not common:
            return None
        f = common[0]
        s_in_f = up_s[1][up_s[0].index(f)]
        t_in_f = up_t[1][up_t[0].index(f)]
        return compose(invert(t_in_f), s_in_f)


class TfMounts(Mapping):
    """``{frame: (x, y, yaw)}`` of sensors in ``base_frame``: from the TF tree when it knows
    the frame, else from ``fallback`` (the ``mount_*`` parameters)."""

    def __init__(self, tf: TfBuffer, base_frame: str, fallback: dict):
        self.tf, self.base_frame, self.fallback = tf, norm_frame(base_frame), dict(fallback)

    def __getitem__(self, frame: str) -> Pose2:
        pose = self.tf.lookup(self.base_frame, frame) if frame in self.tf.frames() else None
        if pose is not None:
            return pose
        return self.fallback[frame]

    def __iter__(self):
        known = {f for f in self.tf.frames() if f != self.base_frame
                 and self.tf.lookup(self.base_frame, f) is not None}
        return iter(sorted(known | set(self.fallback)))

    def __len__(self) -> int:
        return sum(1 for _ in self)

    def __bool__(self) -> bool:     # EgoPoseBuffer.transform does ``mounts or {}``
        return True
