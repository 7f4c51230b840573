#!/usr/bin/env python3
"""The user-level attack runs of issue 16, as a table: what ``intersection-estimator replay``
does with the bags real stacks produce (no odometry, no Doppler, empty/unknown frames, a 1 h
gap, two recordings a day apart, 500 k-point clouds, several bags, a drive through two
intersections). Each row runs the installed console script in its own process with the
built-in defaults (the node's budgets) and reports exit code, wall time, peak RSS and the
last line it printed on stderr (its warning or error; the last stdout line without one).

    .venv/bin/python scripts/attack_runs.py                 # every row (a few minutes)
    .venv/bin/python scripts/attack_runs.py --only gap_1h no_gap
    .venv/bin/python scripts/attack_runs.py --keep /tmp/attack   # keep the bags and outputs

The live burst (a running node flooded with clouds: peak RSS, tick recovery) is
``scripts/burst_node.py``. Exit status 1 when a row crashed (a traceback, a signal) or
timed out.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import os
from pathlib import Path
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = Path(__file__).resolve().parent
TIMEOUT_S = 900


@dataclass
class Row:
    name: str
    code: int | str
    wall_s: float
    rss_mb: float
    last: str

    def crashed(self) -> bool:
        return not isinstance(self.code, int) or self.code < 0 or 'Traceback' in self.last


def _cli() -> str:
    exe = Path(sys.prefix) / 'bin' / 'intersection-estimator'
    return str(exe) if exe.exists() else shutil.which('intersection-estimator') or 'intersection-estimator'


def run_cli(name: str, args: list, timeout: float = TIMEOUT_S) -> Row:
    """One console-script run: exit code, wall time, the child's peak RSS, last line printed."""
    t0 = time.perf_counter()
    with tempfile.TemporaryFile('w+') as out, tempfile.TemporaryFile('w+') as err:
        p = subprocess.Popen([_cli(), *map(str, args)], stdout=out, stderr=err, text=True,
                             env=dict(os.environ, PYTHONWARNINGS='ignore'))
        deadline = time.monotonic() + timeout
        while True:
            pid, status, usage = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if time.monotonic() > deadline:
                p.kill()
                _, status, usage = os.wait4(p.pid, 0)
                return Row(name, 'timeout', time.perf_counter() - t0, usage.ru_maxrss / 1024, '')
            time.sleep(0.05)
        p.returncode = os.waitstatus_to_exitcode(status)
        texts = []
        for f in (err, out):
            f.seek(0)
            texts.append([ln.rstrip() for ln in f.read().replace('\r', '\n').splitlines()
                          if ln.strip() and 'msg/s]' not in ln])      # not the progress bar
    crash = [ln for ln in texts[0] if 'Traceback' in ln or 'Error' in ln[:40]]
    last = (crash or texts[0] or texts[1] or [''])[-1]
    return Row(name, p.returncode, time.perf_counter() - t0, usage.ru_maxrss / 1024, last)


# -- the bags ----------------------------------------------------------------------------------
def _cloud(T, t, frame='radar', n=40, fields=5):
    from msg_adapters.pointcloud2 import radar_cloud_msg
    from msg_adapters.types import make_header
    g = np.random.default_rng(int(t * 10) % 2**32)
    msg = radar_cloud_msg(T, make_header(T, frame, t), g.uniform(-40, 40, (n, 2)), g.normal(0, 5, n))
    msg.fields = msg.fields[:fields]
    return msg


def radar_bag(path: Path, *, odometry=True, radar=True, seconds=20.0, rate=10.0, **cloud) -> Path:
    """Odometry (ego standing at the origin) and radar clouds on the default topics (built once)."""
    from intersection_estimator.bagio import BAG_T0, SCENARIO_TOPICS, BagWriter
    from msg_adapters.odometry import odometry_msg
    if path.exists():
        return path
    with BagWriter(path) as w:
        for k in range(int(seconds * rate)):
            t = BAG_T0 + k / rate
            if odometry:
                w.write(SCENARIO_TOPICS['odometry'], odometry_msg(w.types, t, 0.0, 0.0, 0.0), t)
            if radar:
                w.write(SCENARIO_TOPICS['radar'], _cloud(w.types, t, **cloud), t)
    return path


def _params(root: Path) -> Path:
    p = root / 'params.yaml'
    p.write_text('intersection_estimator:\n  ros__parameters: {}\n')   # the defaults, topics as configured
    return p


def rows(root: Path) -> dict:
    """name -> () -> Row; bags are built when the row runs."""
    from intersection_estimator.bagio import write_drive_bag
    b, o = root / 'bags', root / 'out'
    b.mkdir(exist_ok=True)

    def replay(name, bags, *extra):
        return run_cli(name, ['replay', *bags, '--out', o / name, '--quiet', *extra])

    def several():
        """A radar drive split by topic (radar, odometry, tf), an unrelated /chatter bag, the
        radar bag twice."""
        parts = split_by_topic(write_drive_bag(b / 'radar_drive', (3,), gap_s=0.0, sensors=('raw',)), b / 'split')
        return [parts[0], _chatter(b / 'chatter'), *parts[1:], parts[0]]

    return {
        'no_odometry': lambda: replay('no_odometry', [radar_bag(b / 'no_odometry', odometry=False)]),
        'no_doppler_by_type': lambda: replay('no_doppler_by_type', [radar_bag(b / 'no_doppler', fields=3)]),
        'no_doppler_params': lambda: replay('no_doppler_params', [radar_bag(b / 'no_doppler', fields=3)],
                                            '--params', _params(root)),
        'empty_frame_id': lambda: replay('empty_frame_id', [radar_bag(b / 'empty_frame', frame='')]),
        'unknown_frame_id': lambda: replay('unknown_frame_id', [radar_bag(b / 'unknown_frame', frame='lidar_7')]),
        'empty_clouds': lambda: replay('empty_clouds', [radar_bag(b / 'empty_clouds', n=0)]),
        'clouds_500k': lambda: replay('clouds_500k', [radar_bag(b / 'clouds_500k', seconds=1.0, rate=5.0,
                                                                n=500_000)]),
        'no_gap': lambda: replay('no_gap', [write_drive_bag(b / 'no_gap', (3,), gap_s=0.0)]),
        'gap_1h': lambda: replay('gap_1h', [write_drive_bag(b / 'gap_1h', (3, 3), gap_s=3600.0)]),
        'day_apart_2_bags': lambda: replay('day_apart_2_bags', [
            write_drive_bag(b / 'day_a', (3,), gap_s=0.0),
            write_drive_bag(b / 'day_b', (3,), gap_s=0.0, t0=1_700_000_000.0 + 86400.0)]),
        'several_bags': lambda: replay('several_bags', several()),
        'drive_2_intersections': lambda: replay('drive_2_intersections',
                                                [write_drive_bag(b / 'drive', (3, 5))]),
    }


def split_by_topic(bag: Path, root: Path) -> list[Path]:
    """One bag per topic (CDR copied as it is), radar first."""
    from intersection_estimator.bagio import BagWriter, open_bags
    writers = {}
    with open_bags(bag) as src:
        for t_ns, topic, msgtype, data in src.raw_messages():
            if topic not in writers:
                writers[topic] = BagWriter(root / topic.strip('/').replace('/', '_'))
            writers[topic].write_raw(topic, msgtype, bytes(data), t_ns * 1e-9)
    for w in writers.values():
        w.close()
    return sorted((w.path for w in writers.values()), key=lambda p: 'radar' not in p.name)


def _chatter(path: Path) -> Path:
    from intersection_estimator.bagio import BAG_T0, BagWriter
    with BagWriter(path) as w:
        for k in range(5):
            w.write('/chatter', w.types.get('std_msgs/msg/String')(data=f'hello {k}'), BAG_T0 + k)
    return path


def table(results: list[Row]) -> str:
    head = f'{"run":24s} {"exit":>7s} {"wall s":>8s} {"peak MB":>8s}  last line printed'
    body = [f'{r.name:24s} {str(r.code):>7s} {r.wall_s:8.1f} {r.rss_mb:8.0f}  {r.last[:150]}' for r in results]
    return '\n'.join([head, '-' * len(head), *body])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--only', nargs='+', metavar='RUN', help='run these rows only')
    ap.add_argument('--keep', metavar='DIR', help='build bags and outputs here and keep them')
    args = ap.parse_args(argv)
    root = Path(args.keep or tempfile.mkdtemp(prefix='attack_runs_'))
    root.mkdir(parents=True, exist_ok=True)
    try:
        todo = rows(root)
        unknown = sorted(set(args.only or ()) - set(todo))
        if unknown:
            print(f'attack_runs: unknown run(s) {", ".join(unknown)}; have {", ".join(todo)}',
                  file=sys.stderr)
            return 2
        results = []
        for name, fn in todo.items():
            if args.only is None or name in args.only:
                results.append(fn())
                print(table(results[-1:]).splitlines()[-1], file=sys.stderr, flush=True)
        print(table(results))
        return 1 if any(r.crashed() for r in results) else 0
    finally:
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == '__main__':
    sys.exit(main())
