"""``simulate`` subcommand: one scenario -> ``DIR/gt.json`` (+ ``DIR/bag`` via bagio)."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
import sys

from . import MODES, SimConfig, simulate_scenario

__all__ = ['register', 'run_simulate']


def run_simulate(seed: int, out, sensors=MODES, config: SimConfig = SimConfig()) -> dict:
    """Write gt.json and, if :mod:`intersection_estimator.bagio` is importable, the bag.

    Returns ``{'gt': path, 'bag': path or None, 'bag_note': str}``.
    """
    from ..estimate_io import write_gt
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    sc = replace(simulate_scenario(seed, config), sensors=tuple(sensors))
    res = {'gt': write_gt(out / 'gt.json', sc), 'bag': None, 'bag_note': ''}
    try:
        from .. import bagio
    except ImportError as e:
        res['bag_note'] = f'bag not written: intersection_estimator.bagio unavailable ({e})'
        return res
    res['bag'] = out / 'bag'
    bagio.write_scenario_bag(sc, res['bag'], sensors=tuple(sensors))
    return res


def _cmd(args) -> int:
    cfg = SimConfig(traffic_side=1 if args.traffic_side == 'right' else -1)
    res = run_simulate(args.seed, args.out, args.mode or MODES, cfg)
    print(f"wrote {res['gt']}")
    if res['bag'] is not None:
        print(f"wrote {res['bag']}")
    else:
        print(res['bag_note'], file=sys.stderr)
    return 0


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``simulate`` subcommand."""
    p = subparsers.add_parser('simulate', help='simulate one intersection (paper Table I)',
                              description=__doc__)
    from ..cli import int_at_least
    p.add_argument('--seed', type=int_at_least(0), default=0, help='scenario seed (deterministic)')
    p.add_argument('--out', required=True, help='output folder (gt.json, bag/)')
    p.add_argument('--mode', nargs='+', choices=MODES, default=None,
                   help='detection streams to record in the bag (default: all)')
    p.add_argument('--traffic-side', choices=('right', 'left'), default='right')
    p.set_defaults(func=_cmd)
    return p
