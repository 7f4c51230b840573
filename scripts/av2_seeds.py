#!/usr/bin/env python3
"""The three Argoverse 2 scenarios over several estimator seeds, pooled (issue 15 figures).

One estimator seed says little on three short clips (one scenario's lane error moves by
tens of centimetres from seed to seed), so the README's AV2 lane figures beside the bench
run come from this: every scenario estimated with seeds ``sc.seed + 1000 k`` for k < --seeds
(tracked, full sample budgets), all estimates scored and pooled with ``evaluate.aggregate``.

    PYTHONPATH=. .venv/bin/python scripts/av2_seeds.py [--seeds 8] [--variant name:lanes.key=value,...]

``--variant``: the estimator's configuration overridden as in ``scripts/config_variants.py``.
"""

from __future__ import annotations

import argparse
import json

from intersection_estimator.bench import BenchOptions, make_case
from intersection_estimator.estimate_io import estimate_to_dict
from intersection_estimator.evaluate import aggregate, evaluate
from intersection_estimator.pipeline import estimate

from config_variants import variant      # the sibling script (sys.path[0] is scripts/)

KEYS = ('lane_error_cm_mean', 'floor_cm_matched_mean', 'lane_error_cm_mean_entering',
        'lane_error_cm_mean_leaving', 'lane_error_cm_mean_connector', 'lane_recall',
        'lane_precision', 'arm_observed_accuracy', 'topology_observed_accuracy')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seeds', type=int, default=8, help='estimator seeds per scenario')
    ap.add_argument('--variant', default='default:', help="'name:section.key=value,...'")
    args = ap.parse_args(argv)
    _, cfg = variant(args.variant)
    opts = BenchOptions(n=3, mode='tracked', family='av2', seed=0)
    metrics = []
    for i in range(3):
        sc, gt = make_case(opts, i)
        dets = sc.detections('tracked')
        for k in range(args.seeds):
            r = estimate(dets, mode='tracked', seed=sc.seed + 1000 * k, **cfg)
            metrics.append(evaluate(estimate_to_dict(r.intersection, list(r.lanelets or []), {},
                                                     arrays=True), gt))
    pooled = aggregate(metrics)
    print(json.dumps({k: pooled.get(k) for k in KEYS} | {'estimates': len(metrics)}, indent=1))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
