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
from test_ingest import Sink

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
        """A real 10^6-point cloud (x, y float32: 8 MB): refused as too large, never processed."""
        self._count('cloud_1e6_points')
        PointField = self.types.get('sensor_msgs/msg/PointField')
        return self.types.get('sensor_msgs/msg/PointCloud2')(
            header=self.header(t, 'radar', p_near=1.0), height=1, width=n, point_step=8, row_step=8 * n,
            fields=[PointField(name=a, offset=4 * i, datatype=7, count=1) for i, a in enumerate('xy')],
            data=self.rng.normal(0.0, 30.0, 2 * n).astype('<f4').view(np.uint8), is_dense=True)

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


# -- over DDS -----------------------------------------------------------------------------------------
N_FUZZ = 10_000           # fuzzed messages the node must have *received* (counted via /diagnostics)
IN_FLIGHT = 120           # sent, not yet counted by the node: inside its input queues (100 per topic)
LOG_PERIOD_S = 5.0        # the node's RateLimitedLog period


class Probe:
    """A test node: publishers on the node's inputs, subscribers on its outputs and /diagnostics."""

    def __init__(self, ctx):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from diagnostic_msgs.msg import DiagnosticArray
        from intersection_estimator_msgs.msg import TrackedObjectArray, Topology
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import PointCloud2
        self.node = rclpy.create_node('ie_reliability_probe', context=ctx)
        deep = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.pub = {RADAR: self.node.create_publisher(PointCloud2, RADAR, deep),
                    OBJECTS: self.node.create_publisher(TrackedObjectArray, OBJECTS, deep),
                    ODOM: self.node.create_publisher(Odometry, ODOM, deep)}
        self.topologies, self.diag, self.received = [], {}, []
        self.node.create_subscription(Topology, NODE + '/topology', self.topologies.append, deep)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, deep)
        self.executor = SingleThreadedExecutor(context=ctx)
        self.executor.add_node(self.node)

    def _on_diag(self, msg):
        for st in msg.status:
            if st.hardware_id == 'intersection_estimator' and st.name.endswith(': estimator'):
                self.diag = {kv.key: kv.value for kv in st.values}
                self.received.append(self.count('received_'))   # one entry per diagnostics message

    def spin(self, t: float = 0.0) -> None:
        self.executor.spin_once(timeout_sec=t)

    def count(self, prefix: str) -> int:
        return sum(int(v) for k, v in self.diag.items() if k.startswith(prefix))

    def matched(self) -> bool:
        return (all(p.get_subscription_count() > 0 for p in self.pub.values())
                and self.node.count_publishers('/diagnostics') > 0)

    def destroy(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()


@pytest.fixture
def probe(ros_context):
    p = Probe(ros_context)
    yield p
    p.destroy()


def _start_node(node_process, *params):
    # ticks of 40 ms every 100 ms: diagnostics at 10 Hz and CPU left for the inputs
    args = [script('intersection_estimator_node'), '--ros-args', '-p', 'timer_period:=0.1',
            '-p', 'budget_ms:=40.0']
    for p in params:
        args += ['-p', p]
    return node_process(args)


_PHRASES = {'beyond': 'out_of_range', 'occurs more than once': 'duplicate_id', 'ego pose jumped': 'ego_relocalised',
            'time base moved': 'time_base_reset', 'tick failed': 'tick_error'}


def _warnings_per_reason(log: str) -> dict[str, int]:
    """Warning lines of the node's log grouped by reason (the adapters' key, else the text)."""
    out: dict[str, int] = {}
    for line in log.splitlines():
        if '[WARN]' not in line:
            continue
        text = line.split(']: ', 1)[-1]
        m = re.search(r'dropped a (?:held-back )?message: (\w+):', text)
        key = m.group(1) if m else next((k for phrase, k in _PHRASES.items() if phrase in text), text[:40])
        out[key] = out.get(key, 0) + 1
    return out


@pytest.mark.dds
def test_node_survives_10000_fuzzed_messages_and_still_estimates(probe, node_process):
    from intersection_estimator.bagio import scenario_messages
    from intersection_estimator.sim import simulate_scenario
    from msg_adapters.types import RclpyTypes
    types = RclpyTypes()
    scenario = simulate_scenario(SEED)
    valid = [(t, topic, m) for t, topic, m in
             scenario_messages(scenario, types, sensors=('tracked',), autoware=False) if topic in probe.pub]
    proc = _start_node(node_process)
    assert wait_for(probe.matched, 120, probe.spin), proc.output()
    t_start = time.monotonic()
    fuzz = Fuzzer(types, seed=8, t_base=valid[0][0])

    # a real 10^6-point cloud (20 MB) first: refused as too large, logged with its size
    huge = fuzz.huge_cloud(valid[0][0])
    for _ in range(8):                     # best effort: an 8 MB sample may be lost in DDS, resend
        probe.pub[RADAR].publish(huge)
        if wait_for(lambda: probe.count('dropped_too_large') > 0, 2.5, probe.spin):
            break
    assert wait_for(lambda: probe.count('dropped_too_large') > 0, 60, probe.spin), proc.output()
    assert wait_for(lambda: '1000000 points > max_points' in proc.output(), 60, probe.spin), proc.output()

    print(f'huge cloud done at {time.monotonic() - t_start:.1f} s')
    # the valid stream, each message followed by a burst of fuzzed ones
    per_valid = 2 * (int(1.06 * N_FUZZ) // len(valid))
    sent, ego, objects = 0, (0.0, 0.0, 0.0), None
    topologies_during = len(probe.topologies)
    for t, topic, msg in valid:
        # flow control on the node's own count: best-effort inputs drop what overflows a queue
        wait_for(lambda: sent - probe.count('received_') < IN_FLIGHT, 10, probe.spin, step=0.02)
        probe.pub[topic].publish(msg)
        sent += 1
        if topic == ODOM:
            p = msg.pose.pose
            ego = (p.position.x, p.position.y, 2.0 * math.atan2(p.orientation.z, p.orientation.w))
        else:
            objects = msg
        for _ in range(int(fuzz.rng.integers(0, per_valid + 1))):
            r = fuzz.rng.random()
            if r < 0.4:
                probe.pub[RADAR].publish(fuzz.cloud(t))
            elif r < 0.8 and objects is not None:
                probe.pub[OBJECTS].publish(fuzz.objects(objects))
            else:
                probe.pub[ODOM].publish(fuzz.odometry(t, ego))
            sent += 1
        probe.spin()
    print(f'published at {time.monotonic() - t_start:.1f} s')
    # the node drains its queues: received counts stop growing. Counted in diagnostics
    # messages, not seconds (on a loaded machine a tick, hence a diagnostics message, may
    # take longer than any fixed pause): unchanged over 3 diagnostics in a row
    start = len(probe.received)

    def settled():
        h = probe.received[start:]
        return len(h) >= 3 and h[-1] == h[-2] == h[-3] > 0 and probe.diag.get('state') != 'NO_DATA'
    wait_for(settled, 180, probe.spin)
    received = probe.count('received_')
    fuzz_received = received - len(valid) - fuzz.kinds['cloud_1e6_points']   # a lower bound
    assert fuzz_received >= N_FUZZ, (sent, received, probe.diag)
    assert len(probe.topologies) > topologies_during, 'the node stopped publishing'

    print(f'drained at {time.monotonic() - t_start:.1f} s')
    # still estimating: the right number of arms for the simulated scenario
    n_arms = len(scenario.gt.arms)
    assert wait_for(lambda: probe.topologies and len(probe.topologies[-1].arms) == n_arms, 180, probe.spin), \
        (len(probe.topologies[-1].arms), probe.diag, [ln for ln in proc.output().splitlines() if 'INFO' in ln])
    assert proc.alive(), proc.output()[-3000:]

    # every drop reason counted, the ones the fuzz must produce among them
    dropped = {k[8:]: int(v) for k, v in probe.diag.items() if k.startswith('dropped_')}
    for reason in ('truncated', 'bad_layout', 'missing_field', 'unknown_datatype', 'field_overflow',
                   'too_large', 'non_finite', 'unknown_frame', 'stamp_jump', 'frame_mismatch',
                   'out_of_range', 'duplicate_id', 'ego_jump'):
        assert dropped.get(reason, 0) > 0, (reason, dropped)
    assert 'internal_error' not in dropped and 'tick_error' not in dropped, (dropped, proc.output()[-3000:])

    # rate limiting: at most one warning per reason and period
    elapsed = time.monotonic() - t_start
    per_reason = _warnings_per_reason(proc.output())
    bound = int(elapsed / LOG_PERIOD_S) + 2
    assert per_reason and max(per_reason.values()) <= bound, (bound, per_reason)
    assert 10 * sum(per_reason.values()) < sum(dropped.values()), per_reason
    print(f'fuzz: sent {sent} ({len(valid)} valid), node received {received}, '
          f'dropped {dropped}, warnings {per_reason}, {elapsed:.0f} s, kinds {fuzz.kinds}')


@pytest.mark.dds
def test_bad_parameters_at_run_time_are_refused_and_the_old_value_kept(probe, node_process):
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    proc = _start_node(node_process, 'lane_share:=0.5')
    client = AsyncParameterClient(probe.node, NODE)
    assert wait_for(lambda: client.services_are_ready(), 120, probe.spin), proc.output()

    def call(future):
        assert wait_for(future.done, 60, probe.spin), 'no answer from the parameter service'
        return future.result()

    bad = [('budget_ms', -5.0, 'budget_ms'), ('lane_share', 0.99, 'lane_share'), ('lane_share', math.nan, 'lane_share'),
           ('window_s', 1e9, 'window_s'), ('topology_samples', 0, 'topology_samples'),
           ('max_observations', 10, 'max_observations'), ('doppler_sign', 3, 'doppler_sign'),
           ('reset_distance', math.inf, 'reset_distance'), ('seed', -1, 'seed'),
           ('mount_x', [1.0, 2.0], 'mount_x'), ('timer_period', 0.5, 'timer_period')]
    for name, value, named in bad:
        results = call(client.set_parameters([Parameter(name, value=value)])).results
        assert len(results) == 1 and not results[0].successful, (name, value)
        reason = results[0].reason
        # the name and what is allowed: rclpy's descriptor check ('out of range Min: .., Max: ..')
        # or the node's own ('must be in [..]', 'must be one of ..', 'read-only at run time')
        assert named in reason and any(w in reason for w in ('Min:', 'must be', 'must have', 'read-only')), reason
    # a wrongly typed value is refused by rclpy itself (the descriptor's type)
    results = call(client.set_parameters([Parameter('budget_ms', value='fast')])).results
    assert not results[0].successful and results[0].reason
    # the running node keeps its old values ...
    values = call(client.get_parameters(['budget_ms', 'lane_share', 'window_s', 'seed'])).values
    assert [v.double_value for v in values[:3]] == [40.0, 0.5, 120.0] and values[3].integer_value == 0
    # ... a good value still applies, and the node keeps publishing
    assert call(client.set_parameters([Parameter('lane_share', value=0.4)])).results[0].successful
    assert call(client.get_parameters(['lane_share'])).values[0].double_value == 0.4
    # array parameters arrive as array('d') through the service: settable live (issue 16)
    assert call(client.set_parameters([Parameter('mount_x', value=[2.5])])).results[0].successful
    assert list(call(client.get_parameters(['mount_x'])).values[0].double_array_value) == [2.5]
    n = len(probe.topologies)
    assert wait_for(lambda: len(probe.topologies) > n + 2, 60, probe.spin), proc.output()
    assert proc.alive(), proc.output()


# -- the ingest guards the fuzz found missing (in-process, fast) ------------------------------------
T0 = 1_700_000_000.0


@pytest.fixture(scope='module')
def btypes():
    from intersection_estimator.bagio import typestore
    from msg_adapters.types import RosbagsTypes
    return RosbagsTypes(typestore())


def _ingest(btypes):
    from intersection_estimator import params as P
    from intersection_estimator.ingest import Ingest
    return Ingest(P.defaults(), btypes), Sink()


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
    assert [p.xy.tolist() for p in sink.parts] == [[[1.0, 2.0]], [[6.0, 6.0]]]
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


def test_nan_points_and_objects_cleaned_by_the_adapters_are_counted(btypes):
    """The readers drop non-finite points and objects; the count reaches Ingest (and so
    /diagnostics as dropped_non_finite) with one rate-limited warning (issue 8)."""
    from msg_adapters.pointcloud2 import radar_cloud_msg
    from msg_adapters.types import make_header
    ingest, sink = _ingest(btypes)
    xyz = np.array([[1.0, 2.0, 0.0], [np.nan, 0.0, 0.0], [np.inf, 1.0, 0.0], [3.0, 4.0, 0.0]])
    ingest.handle('radar_topics', radar_cloud_msg(btypes, make_header(btypes, 'map', T0), xyz, np.zeros(4)), sink)
    ingest.handle('object_topics', _objects(btypes, T0, [(1.0, 2.0), (np.nan, 0.0)]), sink)
    assert sum(len(p) for p in sink.parts) == 3             # cleaned: 2 + 1 finite rows kept
    assert ingest.dropped['non_finite'] == 3, dict(ingest.dropped)   # 2 points + 1 object
