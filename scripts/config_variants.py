"""Estimator configuration variants side by side on one bench family (issue 15 measurements).

    .venv/bin/python scripts/config_variants.py --family sumo --n 20 --seed 0 --lane-samples 0 \
        --variant base: --variant r50:topology.max_center_dist=50

Each case is made once (``bench.make_case``) and estimated with every variant's overrides
(``name:section.key=value,...``, a tuple as ``6+7``; sections ``topology`` (TopologyConfig),
``lanes`` (LaneConfig) and ``tracker`` (TrackerConfig, the radar tracker of raw windows));
the pooled metrics of each variant are printed (``evaluate.aggregate``) and, with
``--json``, written with the per-case metrics.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from functools import partial
import json
import sys

from intersection_estimator.bench import BenchOptions, FAMILIES, TURN_SHAPES, _run_estimator, make_case
from intersection_estimator.evaluate import aggregate, evaluate
from intersection_estimator.lanes import LaneConfig
from intersection_estimator.pipeline import estimate
from intersection_estimator.topology import TopologyConfig
from intersection_estimator.tracking import TrackerConfig

KEYS = ('arm_accuracy', 'topology_accuracy', 'topology_observed_accuracy', 'center_error_m_mean',
        'lane_error_cm_mean', 'floor_cm_mean', 'lane_error_cm_mean_entering',
        'lane_error_cm_mean_leaving', 'lane_error_cm_mean_connector', 'lane_recall', 'lane_precision')
SECTIONS = {'topology': TopologyConfig, 'lanes': LaneConfig, 'tracker': TrackerConfig}


def _typed(old, text: str):
    if isinstance(old, bool):
        return text.lower() in ('1', 'true', 'yes')
    if isinstance(old, tuple):                  # labels: 'lanes.skip_labels=6+7', '' = ()
        return tuple(int(v) for v in text.split('+') if v)
    return type(old)(float(text)) if isinstance(old, (int, float)) else text


def variant(text: str) -> tuple[str, dict]:
    """'name:topology.k=v,lanes.k=v' -> (name, {'topology_config': ..., 'lane_config': ...,
    'tracker_config': ...})."""
    name, _, kv = text.partition(':')
    cfgs = {s: cls() for s, cls in SECTIONS.items()}
    for item in filter(None, kv.split(',')):
        key, v = item.split('=')
        section, _, field = key.partition('.')
        if section not in cfgs or not hasattr(cfgs[section], field):
            raise SystemExit(f'config_variants: unknown setting {key!r} (sections: {", ".join(SECTIONS)})')
        cfgs[section] = replace(cfgs[section], **{field: _typed(getattr(cfgs[section], field), v)})
    return name, {'topology_config': cfgs['topology'].validate(), 'lane_config': cfgs['lanes'].validate(),
                  'tracker_config': cfgs['tracker'].validate()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--family', choices=FAMILIES, default='table1')
    ap.add_argument('--n', type=int, default=10)
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--mode', default='tracked')
    ap.add_argument('--lane-samples', type=int, default=20000)
    ap.add_argument('--track-noise-corr', type=float, default=0.0, help='as bench (simulated families)')
    ap.add_argument('--position-noise', type=float, default=1.0, help='as bench (simulated families)')
    ap.add_argument('--turn-shape', choices=TURN_SHAPES, default='arc', help='as bench (table1)')
    ap.add_argument('--variant', action='append', default=[])
    ap.add_argument('--json')
    a = ap.parse_args(argv)
    variants = [variant(v) for v in (a.variant or ['base:'])]
    opts = BenchOptions(n=a.n, seed=a.seed, mode=a.mode, family=a.family, lane_samples=a.lane_samples,
                        track_noise_corr=a.track_noise_corr, position_noise=a.position_noise,
                        turn_shape=a.turn_shape)
    per = {name: [] for name, _ in variants}
    for i in range(a.n):
        try:
            sc, gt = make_case(opts, i)
        except ValueError as e:
            print(f'case {i}: {e}', file=sys.stderr)
            continue
        for name, kw in variants:
            try:
                est = _run_estimator(partial(estimate, **kw), sc, opts)[0]
                per[name].append(evaluate(est, gt, score_lanes=a.lane_samples > 0))
            except ValueError as e:       # no intersection: counted as a failed case
                per[name].append({'ok': False, 'reason': str(e)})
    out = {}
    for name, _ in variants:
        s = aggregate([m for m in per[name] if m.get('ok', True)])
        s['failed'] = sum(1 for m in per[name] if not m.get('ok', True))
        out[name] = s
        print(f'{name:10s} n={s.get("n")} failed={s["failed"]} ' + ' '.join(
            f'{k}={s[k]:.4g}' if isinstance(s.get(k), float) else f'{k}={s.get(k)}' for k in KEYS), flush=True)
    if a.json:
        with open(a.json, 'w') as f:
            json.dump({'args': vars(a), 'summary': out, 'cases': per}, f, indent=1, default=str)
    return 0


if __name__ == '__main__':
    sys.exit(main())
