#!/usr/bin/env python3
"""Run the DDS tests N times while busy loops load every core (issue 16, flaky DDS test).

Starts one busy Python loop per core (``os.cpu_count()``, or ``--load``), runs
``pytest -m dds`` ``--runs`` times in a row (each run its own process, so its own
ROS_DOMAIN_ID and ROS_HOME, see test/conftest.py), stops the loops whatever happens, and
prints one line per run (exit code, wall time, pytest's summary) and the tally. Exit code
0 only when every run passed.

    .venv/bin/python scripts/dds_under_load.py [--runs 10] [--load N] [--json out.json] [-- PYTEST_ARGS]
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import re
import subprocess
import sys
import tempfile
import time

ROOT = Path(__file__).resolve().parents[1]
BUSY = 'while True:\n    pass\n'


def _start_load(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, '-c', BUSY], stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, start_new_session=True) for _ in range(n)]


def _stop_load(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            p.kill()
    for p in procs:
        p.wait(10)


def _one_run(i: int, pytest_args: list[str]) -> dict:
    env = dict(os.environ, ROS_HOME=tempfile.mkdtemp(prefix=f'ie_load_{i}_'))
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, '-m', 'pytest', 'test', '-m', 'dds', '-q',
                           *pytest_args], cwd=ROOT, env=env, capture_output=True, text=True)
    lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
    summary = next((ln.strip('= ') for ln in reversed(lines) if re.search(r'\d+ (passed|failed|error)', ln)),
                   lines[-1] if lines else proc.stderr.strip()[-200:])
    failed = [ln for ln in lines if ln.startswith(('FAILED', 'ERROR'))]
    return {'run': i, 'exit': proc.returncode, 'wall_s': round(time.monotonic() - t0, 1),
            'summary': summary, 'failed': failed}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    extra = argv[argv.index('--') + 1:] if '--' in argv else []
    argv = argv[:argv.index('--')] if '--' in argv else argv
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--runs', type=int, default=10)
    ap.add_argument('--load', type=int, default=os.cpu_count() or 2, help='busy loops (default: one per core)')
    ap.add_argument('--json')
    args = ap.parse_args(argv)
    if args.runs < 1 or args.load < 0:
        print('dds_under_load: --runs must be >= 1 and --load >= 0', file=sys.stderr)
        return 2
    load = _start_load(args.load)
    results = []
    try:
        print(f'dds_under_load: {args.load} busy loop(s) started (pids {[p.pid for p in load]})', flush=True)
        for i in range(1, args.runs + 1):
            r = _one_run(i, extra)
            results.append(r)
            print(f"run {i:2d}: exit {r['exit']}  {r['wall_s']:7.1f} s  {r['summary']}", flush=True)
            for ln in r['failed']:
                print(f'         {ln}', flush=True)
    finally:
        _stop_load(load)
    passed = sum(r['exit'] == 0 for r in results)
    print(f'dds_under_load: {passed}/{len(results)} runs passed with {args.load} busy loop(s) on '
          f'{os.cpu_count()} core(s); busy loops stopped')
    if args.json:
        Path(args.json).write_text(json.dumps({'load': args.load, 'runs': results, 'passed': passed}, indent=1))
    return 0 if passed == len(results) else 1


if __name__ == '__main__':
    sys.exit(main())
