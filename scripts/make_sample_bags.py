#!/usr/bin/env python3
"""Regenerate the sample bags in bags/ (deterministic: same seeds -> same bytes).

bags/tracked  our TrackedObjectArray + odometry                (tracked objects)
bags/radar    radar PointCloud2 (x, y, z, doppler, rcs) + odometry + tf_static   (radar only)
bags/mixed    radar + PoseArray detections + Autoware TrackedObjects + our objects + odometry
Each has its ground truth beside it as bags/<name>.gt.json.

Usage: .venv/bin/python scripts/make_sample_bags.py [--out bags]
"""

from __future__ import annotations

import argparse
from pathlib import Path
import shutil

from intersection_estimator.bagio import write_scenario_bag
from intersection_estimator.estimate_io import write_gt
from intersection_estimator.sim import simulate_scenario

SAMPLES = {
    'tracked': dict(seed=3, sensors=('tracked',), autoware=False),
    'radar': dict(seed=7, sensors=('raw',), autoware=False),
    'mixed': dict(seed=12, sensors=('raw', 'heading', 'tracked'), autoware=True),
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--out', default=str(Path(__file__).resolve().parents[1] / 'bags'))
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, spec in SAMPLES.items():
        sc = simulate_scenario(spec['seed'])
        shutil.rmtree(out / name, ignore_errors=True)
        info = write_scenario_bag(sc, out / name, sensors=spec['sensors'], autoware=spec['autoware'])
        write_gt(out / f'{name}.gt.json', sc)
        print(f'{name}: seed {spec["seed"]}, {len(sc.gt.arms)} arms, {info.size / 1e6:.2f} MB, '
              f'{sum(info.counts.values())} messages')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
