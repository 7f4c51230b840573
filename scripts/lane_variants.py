"""Lane-course variants side by side on one bench family (issue 15 part 4 measurements).

    .venv/bin/python scripts/lane_variants.py --family sumo --n 12 --seed 0 \
        --variant base: --variant traffic:connector_traffic=1

Each case is made once (``bench.make_case``) and estimated with every variant's
``LaneConfig`` overrides (``name:key=value,key=value``); the pooled metrics of each
variant are printed (``evaluate.aggregate``: lane error vs the traffic-following floor,
per kind, recall, topology).
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from functools import partial
import sys

from intersection_estimator.bench import BenchOptions, FAMILIES, _run_estimator, make_case
from intersection_estimator.evaluate import aggregate, evaluate
from intersection_estimator.lanes import LaneConfig
from intersection_estimator.pipeline import estimate

KEYS = ('arm_accuracy', 'topology_accuracy', 'topology_observed_accuracy', 'lane_error_cm_mean',
        'floor_cm_mean', 'floor_cm_matched_mean', 'lane_error_cm_mean_entering',
        'lane_error_cm_mean_leaving', 'lane_error_cm_mean_connector',
        'floor_cm_mean_connector', 'lane_recall', 'lane_precision')


def _variant(text: str):
    name, _, kv = text.partition(':')
    cfg = LaneConfig()
    for item in filter(None, kv.split(',')):
        k, v = item.split('=')
        cfg = replace(cfg, **{k: type(getattr(cfg, k))(float(v))})
    return name, cfg.validate()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--family', choices=FAMILIES, default='table1')
    ap.add_argument('--n', type=int, default=10)
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--mode', default='tracked')
    ap.add_argument('--variant', action='append', default=[])
    a = ap.parse_args(argv)
    variants = [_variant(v) for v in (a.variant or ['base:'])]
    opts = BenchOptions(n=a.n, seed=a.seed, mode=a.mode, family=a.family)
    per = {name: [] for name, _ in variants}
    for i in range(a.n):
        try:
            sc, gt = make_case(opts, i)
        except ValueError as e:
            print(f'case {i}: {e}', file=sys.stderr)
            break
        for name, cfg in variants:
            est, _ = _run_estimator(partial(estimate, lane_config=cfg), sc, opts)
            per[name].append(evaluate(est, gt))
    for name, _ in variants:
        s = aggregate(per[name])
        print(f'{name:10s} n={s["n"]} ' + ' '.join(
            f'{k}={s[k]:.4g}' if isinstance(s.get(k), float) else f'{k}={s.get(k)}' for k in KEYS))
    return 0


if __name__ == '__main__':
    sys.exit(main())
