#!/usr/bin/env python3
"""Behaviour guard for refactors: one hash over the estimates of a fixed set of inputs.

The set: Table I scenarios (seeds 0..16) in each input mode -- raw, tracked (topology and
lane course), heading -- i.e. 51 estimates, plus one replay of each bundled bag. Every
estimate is serialised at full float precision (``float.hex``), so the hash changes when
any estimate changes by one ulp; run-time figures (timings, stats) are left out.

    .venv/bin/python scripts/estimate_hash.py            # prints one hash per group and overall
    .venv/bin/python scripts/estimate_hash.py --check H  # exit 1 unless the overall hash is H
    .venv/bin/python scripts/estimate_hash.py --quick    # 3 seeds per mode, no replays
    .venv/bin/python scripts/estimate_hash.py --drop-key offset_m   # hash without a new key

A refactor that claims "no behaviour change" records the hash before its first commit
and shows it unchanged after each one. A change that only adds an output field (e.g. a new
key of estimate.json that is 0 by default) proves the estimates unchanged with
``--drop-key``: the field is removed wherever it occurs before hashing.

The hash is one machine's: the same commit in the same pinned environment hashes
differently on another machine (stop 57: ``4a519dbb...`` on the earlier machine,
``13be3aa6...`` on an AMD EPYC one), most likely because the compiled kernels (built by
numba for the host CPU) and BLAS round differently on another processor. Record the
before-hash on the machine that checks the after-hash.
"""

from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path
import sys

import numpy as np

# Hash this checkout's package, not whatever copy the venv has installed (a stale install
# would report "unchanged" for any edit).
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SEEDS = range(17)
MODES = ('raw', 'tracked', 'heading')
LANE_SAMPLES = {'raw': 0, 'tracked': 4000, 'heading': 0}
TOPOLOGY_SAMPLES = 3000
BAGS = ('tracked', 'radar', 'mixed')


def canonical(x):
    """A JSON-able copy with every float as its exact hex text."""
    if isinstance(x, dict):
        return {str(k): canonical(v) for k, v in sorted(x.items(), key=lambda kv: str(kv[0]))}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [canonical(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x).hex()
    return x


def estimate_doc(intersection, lanelets) -> dict:
    """The geometry of one estimate (no stats), lanelets in id order."""
    from intersection_estimator.estimate_io import estimate_to_dict
    if intersection is None:
        return {'intersection': None}
    d = estimate_to_dict(intersection, lanelets, None, arrays=True)
    d.pop('stats', None)
    return d


def drop_keys(x, keys):
    """A copy of ``x`` without the dict entries named in ``keys`` (at any depth)."""
    if isinstance(x, dict):
        return {k: drop_keys(v, keys) for k, v in x.items() if k not in keys}
    if isinstance(x, (list, tuple)):
        return [drop_keys(v, keys) for v in x]
    return x


def digest(docs) -> str:
    text = json.dumps(canonical(docs), sort_keys=True, separators=(',', ':'))
    return hashlib.sha256(text.encode()).hexdigest()


def scenario_docs(seeds) -> dict[str, list]:
    from intersection_estimator.pipeline import estimate
    from intersection_estimator.sim import simulate_scenario
    out = {}
    for mode in MODES:
        docs = []
        for seed in seeds:
            dets = simulate_scenario(seed).detections(mode)
            res = estimate(dets, mode=mode, topology_samples=TOPOLOGY_SAMPLES,
                           lane_samples=LANE_SAMPLES[mode], seed=seed)
            doc = estimate_doc(res.intersection, res.lanelets)
            doc['log_posterior'] = float(res.log_posterior)
            docs.append(doc)
        out[mode] = docs
    return out


def replay_docs() -> dict[str, list]:
    from intersection_estimator.replay import bundled_bag, replay
    out = {}
    for name in BAGS:
        summary = replay([str(bundled_bag(name))], '/nonexistent', progress=False,
                         write_outputs=False)
        results = getattr(summary, 'results', None) or [summary.result]
        out[f'replay_{name}'] = [estimate_doc(r.intersection, r.lanelets) if r is not None
                                 else {'intersection': None} for r in results]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--check', metavar='HASH', help='exit 1 unless the overall hash equals HASH')
    ap.add_argument('--quick', action='store_true', help='3 seeds per mode and no replays')
    ap.add_argument('--drop-key', action='append', default=[], metavar='KEY',
                    help='leave this key out wherever it occurs (repeatable)')
    args = ap.parse_args(argv)
    import intersection_estimator
    print(f'package: {Path(intersection_estimator.__file__).parent}')
    groups = scenario_docs(range(3) if args.quick else SEEDS)
    if not args.quick:
        groups.update(replay_docs())
    if args.drop_key:
        groups = drop_keys(groups, set(args.drop_key))
    for name, docs in groups.items():
        print(f'{name:16s} {len(docs):3d} estimates  {digest(docs)}')
    overall = digest(groups)
    print(f'overall{" (quick)" if args.quick else ""}: {overall}')
    if args.check and args.check != overall:
        print(f'estimate_hash: MISMATCH, expected {args.check}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
