#!/usr/bin/env python3
"""Measure the node live: tick time against its budget, and how soon a full estimate comes.

Starts ``intersection_estimator_node`` (its console script, default parameter file) in its
own process, plays a bag into it with ``intersection-estimator replay --live`` from a second
process, and listens to ``/diagnostics`` and ``~/topology`` from this one. Prints the tick
time (median / p95 / max over the run, from the node's own diagnostics) against
``budget_ms``, and the bag time and estimation time until the first topology with the
ground truth's number of arms. DDS stays on this host with its own domain id.

    .venv/bin/python scripts/measure_node.py bags/tracked [--rate 1.0] [--json out.json]
    .venv/bin/python scripts/measure_node.py --sumo 121      # a SUMO family case as the bag
    .venv/bin/python scripts/measure_node.py --sumo 121 --prior-map   # ... and its map as prior_map
    .venv/bin/python scripts/measure_node.py --sumo 121 --sensor raw  # ... as a radar bag (the radar tracker)

``--sumo SEED`` writes that case of the SUMO family (issue 15: a real junction's size, e.g.
seed 121: 6 arms, 34 lanelets, 28.6k tracked rows over 41 s) as a tracked-objects bag with
its ground truth into a temporary folder and measures on it; ``--sensor raw`` writes its
radar (PointCloud2 with Doppler) instead of the tracked objects.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def ros_env(prefix: str = 'ie_measure_') -> dict:
    """Environment for this host only (own domain id, temporary ROS_HOME, fast discovery),
    also applied to this process (its rclpy listener); returns it for the child processes."""
    home = tempfile.mkdtemp(prefix=prefix)
    env = dict(os.environ, ROS_DOMAIN_ID=str(120 + os.getpid() % 100), ROS_HOME=home,
               ROS_LOG_DIR=os.path.join(home, 'log'), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               FASTRTPS_DEFAULT_PROFILES_FILE=str(ROOT / 'config' / 'fastdds_localhost.xml'),
               AMENT_PREFIX_PATH=os.environ.get('AMENT_PREFIX_PATH') or sys.prefix)
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_HOME', 'ROS_LOG_DIR',
                                            'ROS_AUTOMATIC_DISCOVERY_RANGE', 'FASTRTPS_DEFAULT_PROFILES_FILE')})
    return env


def emit(out: dict, json_path: str | None) -> None:
    """Print the result as JSON (and write it to ``json_path``)."""
    print(json.dumps(out, indent=1))
    if json_path:
        Path(json_path).write_text(json.dumps(out, indent=1))


def _listen(args, env):
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from intersection_estimator_msgs.msg import Topology
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from intersection_estimator.estimate_io import read_gt

    gt_path = Path(str(args.bag).rstrip('/') + '.gt.json')
    n_arms = len(read_gt(gt_path).intersection.arms) if gt_path.exists() else None
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node('ie_measure', context=ctx)
    diags, topos, changes = [], [], []
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_subscription(DiagnosticArray, '/diagnostics',
                             lambda m: diags.append((time.monotonic(), m)), 50)
    node.create_subscription(Topology, '/intersection_estimator/topology',
                             lambda m: topos.append((time.monotonic(), m)), latched)
    if args.prior_map:          # the comparison with the map happened: its messages
        from intersection_estimator_msgs.msg import MapChangeArray
        node.create_subscription(MapChangeArray, '/intersection_estimator/map_changes',
                                 lambda m: changes.append((m.intersection_id, len(m.changes))), latched)
    ex = rclpy.executors.SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    procs = []
    try:
        extra = ['-p', f'prior_map:={args.bag}.osm'] if args.prior_map else []
        procs.append(subprocess.Popen([str(BIN / 'intersection_estimator_node'), '--ros-args',
                                       '--params-file', str(ROOT / 'config' / 'intersection_estimator.yaml')]
                                      + extra,
                                      env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        end = time.monotonic() + 30
        while not topos and time.monotonic() < end:      # bounded wait for discovery
            ex.spin_once(timeout_sec=0.05)
        if not topos:
            sys.exit('measure_node: the node published no topology within 30 s')
        t_play = time.monotonic()
        player = subprocess.Popen([str(BIN / 'intersection-estimator'), 'replay', '--live',
                                   '--rate', str(args.rate), str(args.bag)], env=env,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        procs.append(player)
        while player.poll() is None:
            ex.spin_once(timeout_sec=0.05)
        end = time.monotonic() + 3.0
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
                t_term = time.monotonic()
                try:
                    p.wait(30)
                    if time.monotonic() - t_term > 5.0:
                        print(f'measure_node: {Path(p.args[0]).name} took '
                              f'{time.monotonic() - t_term:.1f} s to stop after SIGTERM',
                              file=sys.stderr)
                except subprocess.TimeoutExpired:     # reported, never left running
                    print(f'measure_node: {Path(p.args[0]).name} still running 30 s after '
                          'SIGTERM: killed', file=sys.stderr)
                    p.kill()
                    p.wait()
        node.destroy_node()
        ctx.try_shutdown()
    return diags, topos, t_play, n_arms, changes


def _pct(x, q):
    x = sorted(x)
    return x[min(int(q * len(x)), len(x) - 1)] if x else float('nan')


def _summary(diags, topos, t_play, n_arms, rate) -> dict:
    vals = [(t, {kv.key: kv.value for kv in d.status[0].values}) for t, d in diags if d.status]
    vals = [(t, v) for t, v in vals if 'tick_ms_p95' in v and v.get('state') != 'NO_DATA']
    first = next((t for t, m in topos if m.state != m.NO_DATA and n_arms is not None
                  and len(m.arms) == n_arms), None)
    last = vals[-1][1] if vals else {}
    est = [float(v.get('topology_ms', 0.0)) + float(v.get('lanes_ms', 0.0)) for _, v in vals]
    out = {'budget_ms': float(last.get('budget_ms', 'nan')),
           'tick_ms_median': float(last.get('tick_ms_median', 'nan')),
           'tick_ms_p95': float(last.get('tick_ms_p95', 'nan')),
           'tick_ms_p95_max': max((float(v['tick_ms_p95']) for _, v in vals), default=float('nan')),
           'overhead_ms_last': float(last.get('overhead_ms', 'nan')),
           'lanes_publish_ms_max': max((float(v.get('lanes_publish_ms', 'nan')) for _, v in vals),
                                       default=float('nan')),
           'map_changes_ms_max': max((float(v.get('map_changes_ms', 'nan')) for _, v in vals),
                                     default=float('nan')),
           'estimation_ms_median': _pct(est, 0.5), 'estimation_ms_p95': _pct(est, 0.95),
           'ticks_with_data': len(vals), 'true_arms': n_arms, 'right_arm_count': first is not None}
    if first is not None:
        out['bag_s_to_right_arm_count'] = round((first - t_play) * rate, 2)
        out['estimation_ms_to_right_arm_count'] = round(sum(
            e for (t, _), e in zip(vals, est) if t <= first), 1)
    return out


def _sumo_bag(seed: int, folder: Path, sensor: str = 'tracked') -> str:
    """Write SUMO family case ``seed`` as a bag of ``sensor`` ('tracked' objects or 'raw'
    radar) + ``<bag>.gt.json`` and its ground truth as a Lanelet2 map ``<bag>.osm`` (a prior
    map for ``--prior-map``) in ``folder``."""
    sys.path.insert(0, str(ROOT))
    from intersection_estimator.bagio.scenario import write_scenario_bag
    from intersection_estimator.bench import BenchOptions, make_case
    from intersection_estimator.estimate_io import dumps
    from intersection_estimator.export.osm import write_osm
    from intersection_estimator.scenarios.sumo_gt import snap_connectors
    sc, gt = make_case(BenchOptions(n=1, seed=0, mode='tracked', family='sumo'), seed)
    bag = folder / f'sumo_{seed}'
    write_scenario_bag(sc, bag, sensors=(sensor,))
    Path(str(bag) + '.gt.json').write_text(dumps(gt))
    snap_connectors(sc.gt_lanelets)
    write_osm(str(bag) + '.osm', sc.gt_lanelets)
    return str(bag)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('bag', nargs='?')
    ap.add_argument('--sumo', type=int, metavar='SEED', help='measure on this SUMO family case')
    ap.add_argument('--prior-map', action='store_true',
                    help='with --sumo: the case\'s ground truth as the node\'s prior_map (map changes live)')
    ap.add_argument('--sensor', choices=('tracked', 'raw'), default='tracked',
                    help='with --sumo: the bag carries tracked objects or radar (raw)')
    ap.add_argument('--rate', type=float, default=1.0)
    ap.add_argument('--json')
    args = ap.parse_args(argv)
    if (args.bag is None) == (args.sumo is None):
        ap.error('give a bag or --sumo SEED')
    if args.prior_map and args.sumo is None:
        ap.error('--prior-map needs --sumo SEED (the case\'s ground truth is the map)')
    if args.sumo is not None:
        tmp = tempfile.TemporaryDirectory(prefix='ie_measure_sumo_')
        args.bag = _sumo_bag(args.sumo, Path(tmp.name), args.sensor)
    if not Path(args.bag).exists():
        print(f'measure_node: no such bag: {args.bag}', file=sys.stderr)
        return 1
    env = ros_env()
    diags, topos, t_play, n_arms, changes = _listen(args, env)
    out = _summary(diags, topos, t_play, n_arms, args.rate)
    if args.prior_map:
        matched = [n for i, n in changes if i]
        out.update(map_change_messages=len(changes), map_change_messages_matched=len(matched),
                   map_changes_last=matched[-1] if matched else None)
    emit(out, args.json)
    return 0


if __name__ == '__main__':
    sys.exit(main())
