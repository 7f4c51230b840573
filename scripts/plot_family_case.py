#!/usr/bin/env python3
"""Plot one case of a bench family: today's estimate over the ground truth (issue 15).

    .venv/bin/python scripts/plot_family_case.py --family sumo --seed 3 --out sumo_case.png
    .venv/bin/python scripts/plot_family_case.py --family av2 --seed 2 --out av2_case.png

``--seed`` is the case index for ``av2`` (0..2), the scenario seed otherwise; the
metrics of the case (evaluate) go into the title and are printed.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from intersection_estimator.bench import FAMILIES, BenchOptions, _run_estimator, make_case  # noqa: E402
from intersection_estimator.estimate_io import parse_estimate  # noqa: E402
from intersection_estimator.evaluate import evaluate  # noqa: E402
from intersection_estimator.export.plot import plot_estimate  # noqa: E402
from intersection_estimator.pipeline import estimate  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--family', choices=FAMILIES, default='sumo')
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--mode', default='tracked')
    ap.add_argument('--out', required=True)
    args = ap.parse_args(argv)
    opts = BenchOptions(n=1, mode=args.mode, family=args.family, seed=0)
    sc, gt = make_case(opts, args.seed)
    est, _, _ = _run_estimator(estimate, sc, opts)
    m = evaluate(est, gt)
    inter, lanes, _ = parse_estimate(est)
    title = (f"{args.family} {args.seed} ({args.mode}): arms {m['n_arms_est']}/{m['n_arms_true']}, "
             f"topology_observed {m['topology_observed_correct']}, lanes "
             f"{m['lane_error_cm'] or float('nan'):.0f} cm vs floor {m['floor_cm'] or float('nan'):.0f} cm")
    plot_estimate(args.out, inter, lanes, sc.detections(args.mode), sc.gt_lanelets, title=title,
                  view_radius=80.0)
    print(title)
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
