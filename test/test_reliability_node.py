"""Issue 8 over real DDS: the node survives >= 10 000 fuzzed input messages and bad parameters.

The fuzzed messages are rclpy messages built with a seeded numpy Generator (the in-process
Hypothesis fuzz of the adapters is test_adapters_fuzz.py): PointCloud2 with mangled layouts
and bytes, TrackedObjectArray with NaN/Inf/huge values, duplicate ids and absurd stamps,
Odometry with bad values. They are interleaved with a valid simulated stream; afterwards
the node must be alive, have logged a bounded number of warnings per reason, report the
drops on /diagnostics and publish the right number of arms.
"""

from __future__ import annotations

import math
import re
import time

import numpy as np
import pytest

from conftest import script, wait_for

SEED = 3                  # simulated scenario of the valid stream (4 arms)
RADAR = '/perception/radar/points'
OBJECTS = '/perception/objects'
ODOM = '/localization/odometry'
NODE = '/intersection_estimator'

# -- fuzzed messages (rclpy) ---------------------------------------------------------------------
_F32 = (np.nan, np.inf, -np.inf, 1e30, -1e30, 3.4e38, 0.0, -0.0, 1e-40)
_F64 = (np.nan, np.inf, -np.inf, 1e300, -1e300, 1e12, 0.0, 5e-324)
_FRAMES = ('map', 'radar', 'base_link', 'odom', '', 'lidar_top', '/map', 'm\u00e4p', 'x' * 300)


class Fuzzer:
    """Seeded generator of malformed input messages; ``kinds`` counts what was made."""

    def __init__(self, types, seed: int, t_base: float):
        self.types, self.rng, self.t_base = types, np.random.default_rng(seed), t_base
        self.kinds: dict[str, int] = {}

    def _pick(self, seq):
        return seq[int(self.rng.integers(len(seq)))]

    def stamp(self, t: float, p_near: float = 0.7):
        """Mostly near ``t``; else backwards, jumping, negative, maximal or nanosec overflow."""
        Time = self.types.get('builtin_interfaces/msg/Time')
        if self.rng.random() < p_near:
            t = t + float(self.rng.normal(0.0, 0.5))
            sec = int(math.floor(t))
            return Time(sec=sec, nanosec=int((t - sec) * 1e9) % 1_000_000_000)
        choice = int(self.rng.integers(6))
        sec = [int(t) - int(self.rng.integers(2, 3600)), int(t) + int(self.rng.integers(31, 10**6)),
               -int(self.rng.integers(1, 2**31)), 2**31 - 1, 0, int(t)][choice]
        nsec = 4_294_967_295 if choice == 5 else int(self.rng.integers(0, 10**9))
        return Time(sec=sec, nanosec=nsec)

    def header(self, t: float, frame: str | None = None, p_near: float = 0.7):
        frame = self._pick(_FRAMES) if frame is None or self.rng.random() < 0.1 else frame
        return self.types.get('std_msgs/msg/Header')(stamp=self.stamp(t, p_near), frame_id=frame)

    def _count(self, kind: str) -> None:
        self.kinds[kind] = self.kinds.get(kind, 0) + 1

    # -- sensor_msgs/PointCloud2 -------------------------------------------------------------------
    def cloud(self, t: float):
        """A radar cloud with a mangled layout or bytes. Its points are NaN/Inf (or all bytes
        0xFF, NaN in any byte order and alignment): whatever is read of it is cleaned away."""
        from msg_adapters.pointcloud2 import radar_cloud_msg
        g = self.rng
        n = int(g.integers(0, 64))
        xyz = g.normal(0.0, 30.0, (n, 3))
        xyz[np.arange(n), g.integers(0, 3, n)] = g.choice([np.nan, np.inf, -np.inf], n)
        msg = radar_cloud_msg(self.types, self.header(t, 'radar'), xyz, g.normal(0.0, 5.0, n))
        kind = self._pick(('nan_points', 'empty', 'step_mismatch', 'truncated', 'extra_bytes',
                           'row_step', 'missing_field', 'bad_datatype', 'field_overflow', 'count',
                           'duplicate_field', 'big_endian', 'random_bytes', 'huge_width', 'height',
                           'no_fields'))
        self._count('cloud_' + kind)
        if kind != 'nan_points':
            msg.data = b'\xff' * (20 * n)
        data = bytes(msg.data)
        PointField = self.types.get('sensor_msgs/msg/PointField')
        if kind == 'empty':
            msg.width, msg.row_step, msg.data = 0, 0, b''
        elif kind == 'step_mismatch':
            msg.point_step = int(g.choice([0, 1, 7, 16, 21, 40, 2**16, 2**32 - 1]))
        elif kind == 'truncated':
            msg.data = data[:int(g.integers(0, max(1, len(data))))]
        elif kind == 'extra_bytes':
            msg.data = data + b'\xff' * int(g.integers(1, 100))
        elif kind == 'row_step':
            msg.row_step = int(g.integers(0, 2**32))
        elif kind == 'missing_field':
            drop = self._pick(('x', 'y', 'z', 'doppler'))
            msg.fields = [f for f in msg.fields if f.name != drop]
        elif kind == 'bad_datatype':
            msg.fields[int(g.integers(len(msg.fields)))].datatype = int(g.choice([0, 9, 42, 255]))
        elif kind == 'field_overflow':
            msg.fields[int(g.integers(len(msg.fields)))].offset = int(g.choice([17, 20, 100, 2**32 - 1]))
        elif kind == 'count':
            for f in msg.fields:
                f.count = int(g.choice([0, 3, 2**32 - 1]))
        elif kind == 'duplicate_field':
            msg.fields = list(msg.fields) + [PointField(name='x', offset=8, datatype=8, count=1)]
        elif kind == 'big_endian':
            msg.is_bigendian = True
        elif kind == 'random_bytes':       # random bytes where the points' y, z, doppler, rcs are
            arr = np.frombuffer(g.bytes(len(data)), np.uint8).copy().reshape(n, 20)
            arr[:, :4] = 0xFF              # x stays NaN
            msg.data = arr.tobytes()
        elif kind == 'huge_width':
            msg.width = int(g.choice([2**20, 2**31, 2**32 - 1]))
            msg.row_step = msg.width * 20 % 2**32
        elif kind == 'height':
            msg.height = int(g.choice([0, 2, 3, 2**32 - 1]))
        elif kind == 'no_fields':
            msg.fields = []
        return msg

    def huge_cloud(self, t: float, n: int = 1_000_000):
        """A real 10^6-point cloud (20 MB): refused as too large, never processed."""
        from msg_adapters.pointcloud2 import radar_cloud_msg
        self._count('cloud_1e6_points')
        xyz = self.rng.normal(0.0, 30.0, (n, 3))
        return radar_cloud_msg(self.types, self.header(t, 'radar'), xyz, np.zeros(n))

    # -- intersection_estimator_msgs/TrackedObjectArray ---------------------------------------------
    def objects(self, base):
        """A mutation of the valid TrackedObjectArray ``base``: one thing wrong with it."""
        from msg_adapters.tracked_objects import read_objects, tracked_object_array_msg
        g = self.rng
        o = read_objects(base)
        ids, xy, yaw, speed = o.ids.copy(), o.xy.copy(), o.yaw.copy(), o.speed.copy()
        n = len(ids)
        label, exist = np.ones(n, int), np.ones(n)
        kind = self._pick(('nan_pose', 'inf_pose', 'huge_pose', 'duplicate_ids', 'zero_quat',
                           'bad_velocity', 'bad_existence', 'labels', 'empty', 'max_ids', 'frames',
                           'stamp'))
        self._count('objects_' + kind)
        if kind in ('nan_pose', 'inf_pose', 'huge_pose') and n:
            vals = {'nan_pose': (np.nan,), 'inf_pose': (np.inf, -np.inf),
                    'huge_pose': (1e300, -1e300, 1e30, 1.7e308)}[kind]
            xy[g.random(n) < 0.5, int(g.integers(2))] = self._pick(vals)
        elif kind == 'duplicate_ids' and n:
            ids[:] = ids[0]
        elif kind == 'bad_velocity':
            speed[:] = self._pick(_F64)
        elif kind == 'bad_existence':
            exist[:] = self._pick((np.nan, -np.inf, -1.0, 0.0))
        elif kind == 'labels':             # pedestrians, bicycles, animals, hazards, junk ids
            label = g.choice([6, 7, 8, 9, 10, 200, 255], n)
        elif kind == 'empty':
            ids, xy, yaw, speed, label, exist = ids[:0], xy[:0], yaw[:0], speed[:0], label[:0], exist[:0]
        elif kind == 'max_ids':
            ids = np.full(n, 2**63 - 1)
        frame = self._pick(('odom', '', 'lidar_top', 'm\u00e4p', 'x' * 300)) if kind == 'frames' else 'map'
        header = (self.header(o.stamp, frame, p_near=0.0) if kind == 'stamp' else
                  self.types.get('std_msgs/msg/Header')(stamp=base.header.stamp, frame_id=frame))
        msg = tracked_object_array_msg(self.types, header, ids, xy, yaw, speed, label, exist)
        if kind == 'zero_quat':
            for ob in msg.objects:
                q = ob.pose.orientation
                q.x = q.y = q.z = 0.0
                q.w = self._pick((0.0, np.nan, np.inf, 1e300))
        if kind == 'max_ids':
            for ob in msg.objects:
                ob.id = 2**64 - 1
        return msg

    # -- nav_msgs/Odometry -------------------------------------------------------------------------
    def odometry(self, t: float, ego=(0.0, 0.0, 0.0)):
        """Odometry at the true ego pose ``ego`` (x, y, yaw) with one thing wrong."""
        from msg_adapters.odometry import odometry_msg
        g = self.rng
        kind = self._pick(('nan_pose', 'inf_pose', 'huge_pose', 'zero_quat', 'bad_twist', 'frame',
                           'child_frame', 'teleport', 'glitch'))
        self._count('odometry_' + kind)
        x, y, yaw = ego
        v = [float(g.uniform(0, 15)), 0.0, 0.0]
        if kind in ('nan_pose', 'inf_pose', 'huge_pose'):
            bad = {'nan_pose': np.nan, 'inf_pose': np.inf, 'huge_pose': 1e300}[kind]
            x, y, yaw = [bad if g.random() < 0.5 else val for val in (x, y, yaw)]
        elif kind == 'bad_twist':
            v = [self._pick(_F64) for _ in range(3)]
        elif kind == 'teleport':
            x, y = g.uniform(-1e8, 1e8, 2)
        elif kind == 'glitch':             # a localisation glitch tens of metres off
            x, y = x + g.normal(0, 80), y + g.normal(0, 80)
        frame = self._pick(_FRAMES) if kind == 'frame' else 'map'
        child = self._pick(_FRAMES) if kind == 'child_frame' else 'base_link'
        msg = odometry_msg(self.types, 0.0, x, y, yaw, *v, frame_id=frame, child_frame_id=child)
        msg.header = self.header(t, frame)
        if kind == 'zero_quat':
            q = msg.pose.pose.orientation
            q.x = q.y = q.z = q.w = self._pick((0.0, np.nan, 1e300))
        return msg


# -- the ingest guards the fuzz found missing (in-process, fast) ------------------------------------
T0 = 1_700_000_000.0


class _Sink:
    def __init__(self):
        self.parts, self.resets = [], 0

    def add(self, dets):
        self.parts.append(dets)
        return len(dets)

    def reset(self):
        self.resets += 1


@pytest.fixture(scope='module')
def btypes():
    from intersection_estimator.bagio import typestore
    from msg_adapters.types import RosbagsTypes
    return RosbagsTypes(typestore())


def _ingest(btypes):
    from intersection_estimator import params as P
    from intersection_estimator.ingest import Ingest
    return Ingest(P.defaults(), btypes), _Sink()


def _objects(types, t, xy, ids=None):
    from msg_adapters.tracked_objects import tracked_object_array_msg
    from msg_adapters.types import make_header
    xy = np.asarray(xy, float)
    ids = np.arange(len(xy)) if ids is None else ids
    return tracked_object_array_msg(types, make_header(types, 'map', t), ids, xy, np.zeros(len(xy)),
                                    np.full(len(xy), 10.0))


def test_inconsistent_garbage_stamps_in_a_row_do_not_reset_the_time_base(btypes):
    from intersection_estimator.ingest import JUMP_CONFIRM
    ingest, sink = _ingest(btypes)
    ingest.handle('object_topics', _objects(btypes, T0, [(1.0, 2.0)]), sink)
    for k in range(4 * JUMP_CONFIRM):      # far from the time base and from each other
        ingest.handle('object_topics', _objects(btypes, T0 + (-1) ** k * (100.0 + 1000.0 * k), [(1.0, 2.0)]), sink)
    assert sink.resets == 0 and ingest.dropped['stamp_jump'] == 4 * JUMP_CONFIRM
    assert ingest.latest_stamp == pytest.approx(T0)


def test_absurd_coordinates_and_duplicate_ids_are_cleaned(btypes):
    ingest, sink = _ingest(btypes)
    ingest.handle('object_topics', _objects(btypes, T0, [(1.0, 2.0), (1e300, 0.0), (3.0, -1e30)]), sink)
    ingest.handle('object_topics', _objects(btypes, T0 + 0.1, [(1.0, 2.0), (5.0, 5.0), (6.0, 6.0)],
                                            ids=[7, 7, 8]), sink)
    assert [p.xy.tolist() for p in sink.parts] == [[[1.0, 2.0]], [[1.0, 2.0], [6.0, 6.0]]]
    assert ingest.dropped['out_of_range'] == 1 and ingest.dropped['duplicate_id'] == 1


def test_one_odometry_glitch_does_not_move_the_ego_but_a_relocalisation_does(btypes):
    from intersection_estimator.ingest import JUMP_CONFIRM
    from msg_adapters.odometry import odometry_msg
    ingest, sink = _ingest(btypes)
    ingest.handle('odometry_topic', odometry_msg(btypes, T0, 0.0, 0.0, 0.0, vx=10.0), sink)
    ingest.handle('odometry_topic', odometry_msg(btypes, T0 + 0.1, 500.0, 0.0, 0.0), sink)   # glitch
    ingest.handle('odometry_topic', odometry_msg(btypes, T0 + 0.2, 1e300, 0.0, 0.0), sink)   # absurd
    ingest.handle('odometry_topic', odometry_msg(btypes, T0 + 0.3, 3.0, 0.0, 0.0, vx=float('nan')), sink)
    assert ingest.ego_pose() == (3.0, 0.0, 0.0) and ingest.ego.latest.vx == 0.0   # NaN twist cleaned
    assert ingest.dropped['ego_jump'] == 1 and ingest.dropped['out_of_range'] == 1
    for k in range(JUMP_CONFIRM):          # relocalised: consistent poses 2 km away
        ingest.handle('odometry_topic', odometry_msg(btypes, T0 + 0.4 + 0.1 * k, 2000.0 + k, 0.0, 0.0), sink)
    assert ingest.ego_pose()[0] == 2000.0 + JUMP_CONFIRM - 1
    assert ingest.dropped['ego_jump'] == JUMP_CONFIRM
