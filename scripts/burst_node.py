#!/usr/bin/env python3
"""Measure a live burst into the node: peak RSS and how soon its ticks recover (issue 16).

Starts ``intersection_estimator_node`` (console script, shipped parameter file) in its own
process and, from this one, publishes odometry (20 Hz, ego at rest) and small radar clouds
(10 Hz) in data time; after ``--before`` seconds it publishes ``--clouds`` clouds of
``--points`` points, all with ONE stamp, back to back; then the small stream goes on for
``--after`` seconds. The node's RSS is sampled from /proc every 0.1 s (VmHWM at the end),
its ticks come from its own /diagnostics (``tick_ms_last``). Recovery: the time from the
burst's last message to the first of 3 ticks in a row no slower than twice the pre-burst
p95 (at least 2 x budget_ms). DDS stays on this host with its own domain id.

    .venv/bin/python scripts/burst_node.py [--clouds 200] [--points 200000] [--json out.json]
"""

from __future__ import annotations

import argparse
from pathlib import Path
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

from measure_node import BIN, ROOT, emit, ros_env   # scripts/ is sys.path[0]

T0 = 1_700_000_000.0


def _rss_mb(pid: int, key: str = 'VmRSS') -> float:
    try:
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith(key + ':'):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float('nan')


class Sampler(threading.Thread):
    """RSS of a process every ``period`` s, as (monotonic time, MB)."""

    def __init__(self, pid: int, period: float = 0.1):
        super().__init__(daemon=True)
        self.pid, self.period, self.samples, self.stop = pid, period, [], threading.Event()

    def run(self):
        while not self.stop.is_set():
            self.samples.append((time.monotonic(), _rss_mb(self.pid)))
            self.stop.wait(self.period)


class Stream:
    """Publishes the background stream (odometry + small clouds) and the burst."""

    def __init__(self, node, types, rng):
        from msg_adapters.odometry import odometry_msg
        from msg_adapters.pointcloud2 import radar_cloud_msg
        from msg_adapters.types import make_header
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import PointCloud2
        self.types, self.rng, self.make_header = types, rng, make_header
        self.odometry_msg, self.cloud_msg = odometry_msg, radar_cloud_msg
        self.pub_odom = node.create_publisher(Odometry, '/localization/odometry', 50)
        self.pub_cloud = node.create_publisher(PointCloud2, '/perception/radar/points', 10)
        self.t_wall0 = time.monotonic()

    def now(self) -> float:
        return T0 + time.monotonic() - self.t_wall0

    def odom(self) -> None:
        self.pub_odom.publish(self.odometry_msg(self.types, self.now(), 0.0, 0.0, 0.0))

    def cloud(self, n: int, stamp: float | None = None):
        xyz = np.zeros((n, 3))
        xyz[:, :2] = self.rng.uniform(-60.0, 60.0, (n, 2))
        return self.cloud_msg(self.types, self.make_header(self.types, 'radar', self.now() if stamp is None
                                                           else stamp), xyz, self.rng.normal(0.0, 5.0, n))

    def background(self, seconds: float, spin) -> None:
        end, k = time.monotonic() + seconds, 0
        while time.monotonic() < end:
            self.odom()
            if k % 2 == 0:
                self.pub_cloud.publish(self.cloud(2000))
            k += 1
            spin(0.05)


def _diag_values(msg) -> dict:
    return {kv.key: kv.value for kv in msg.status[0].values} if msg.status else {}


def _run(args, env) -> dict:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from msg_adapters.types import RclpyTypes
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node('ie_burst', context=ctx)
    diags = []
    node.create_subscription(DiagnosticArray, '/diagnostics', lambda m: diags.append((time.monotonic(), m)), 200)
    ex = rclpy.executors.SingleThreadedExecutor(context=ctx)
    ex.add_node(node)

    def spin(t):
        end = time.monotonic() + t
        while True:
            ex.spin_once(timeout_sec=max(end - time.monotonic(), 0.0))
            if time.monotonic() >= end:
                return
    log = tempfile.NamedTemporaryFile(prefix='ie_burst_node_', suffix='.log', delete=False)
    proc = subprocess.Popen([str(BIN / 'intersection_estimator_node'), '--ros-args', '--params-file',
                             str(ROOT / 'config' / 'intersection_estimator.yaml')],
                            env=env, stdout=log, stderr=subprocess.STDOUT)
    sampler = Sampler(proc.pid)
    sampler.start()
    stream = Stream(node, RclpyTypes(), np.random.default_rng(args.seed))
    try:
        end = time.monotonic() + 120
        while not diags and time.monotonic() < end and proc.poll() is None:    # bounded: node up
            stream.odom()
            spin(0.1)
        if not diags:
            raise SystemExit(f'burst_node: no diagnostics from the node within 120 s (log: {log.name})')
        stream.background(args.before, spin)
        rss_before = _rss_mb(proc.pid)
        big = stream.cloud(args.points, stamp=stream.now())       # one message, one stamp
        t_burst = time.monotonic()
        for i in range(args.clouds):
            stream.pub_cloud.publish(big)
            if i % 10 == 0:
                stream.odom()
                spin(0.0)
        t_end = time.monotonic()
        stream.background(args.after, spin)
    finally:
        sampler.stop.set()
        peak = _rss_mb(proc.pid, 'VmHWM')
        proc.terminate()
        proc.wait(60)
        node.destroy_node()
        ctx.try_shutdown()
    return _summary(args, diags, sampler.samples, rss_before, peak, t_burst, t_end, log.name)


def _summary(args, diags, samples, rss_before, peak, t_burst, t_end, log) -> dict:
    ticks = [(t, _diag_values(m)) for t, m in diags]
    ticks = [(t, v) for t, v in ticks if 'tick_ms_last' in v]
    pre = [float(v['tick_ms_last']) for t, v in ticks if t < t_burst]
    budget = float(ticks[-1][1]['budget_ms']) if ticks else float('nan')
    limit = max(2.0 * float(np.percentile(pre, 95)) if pre else 0.0, 2.0 * budget)
    post = [(t, float(v['tick_ms_last'])) for t, v in ticks if t >= t_end]
    recovered = next((t for i, (t, _) in enumerate(post)
                      if len(post[i:i + 3]) == 3 and all(ms <= limit for _, ms in post[i:i + 3])), None)
    during = [float(v['tick_ms_last']) for t, v in ticks if t_burst <= t]
    last = ticks[-1][1] if ticks else {}
    return {
        'clouds': args.clouds, 'points_per_cloud': args.points,
        'burst_publish_s': round(t_end - t_burst, 2),
        'rss_mb_before': round(rss_before, 1),
        'rss_mb_peak_sampled': round(max((mb for t, mb in samples if t >= t_burst), default=float('nan')), 1),
        'rss_mb_hwm': round(peak, 1), 'rss_mb_end': round(samples[-1][1], 1) if samples else None,
        'tick_ms_before_median': round(float(np.median(pre)), 1) if pre else None,
        'tick_ms_max_after_burst_start': round(max(during, default=float('nan')), 1),
        'recovery_limit_ms': round(limit, 1),
        'recovery_s_after_burst': None if recovered is None else round(recovered - t_end, 2),
        'observations_end': int(last.get('observations', 0)),
        'received_radar': int(last.get('received_radar_topics', 0)),
        'dropped_window_full': int(last.get('dropped_window_full', 0)),
        'dropped_too_large': int(last.get('dropped_too_large', 0)),
        'diagnostics': len(ticks), 'node_log': log,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--clouds', type=int, default=200)
    ap.add_argument('--points', type=int, default=200_000)
    ap.add_argument('--before', type=float, default=8.0, help='seconds of small stream before [s]')
    ap.add_argument('--after', type=float, default=30.0, help='seconds of small stream after [s]')
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--json')
    args = ap.parse_args(argv)
    if args.clouds < 1 or args.points < 1 or args.seed < 0:
        print('burst_node: --clouds, --points must be >= 1 and --seed >= 0', file=sys.stderr)
        return 2
    emit(_run(args, ros_env('ie_burst_')), args.json)
    return 0


if __name__ == '__main__':
    sys.exit(main())
