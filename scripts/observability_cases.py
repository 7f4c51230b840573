"""Observability on Table I cases and on their straight-road variants (issue 15 part 4).

    .venv/bin/python scripts/observability_cases.py --seed 0 --n 200

For each seed: the full scenario (an intersection: must not be called a road) and, where
the scenario has two nearly opposite arms with the ego on them, the same scenario with
only the through traffic of that road (``test/road_scenes.straight_road``: must be
called a road). Every mode runs through ``pipeline.estimate`` (the verdict does not
depend on the sample counts, so they are small here). Prints the shares per mode.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

from road_scenes import straight_road  # noqa: E402

from intersection_estimator.pipeline import estimate  # noqa: E402
from intersection_estimator.sim import simulate_scenario  # noqa: E402

MODES = ('tracked', 'heading', 'raw')


def _state(sc, mode) -> str:
    res = estimate(sc.detections(mode), mode=mode, topology_samples=200, lane_samples=0,
                   seed=sc.seed)
    return res.observability.state


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--n', type=int, default=200)
    a = ap.parse_args(argv)
    road = {m: [0, 0] for m in MODES}       # [called road, cases]
    inter = {m: [0, 0] for m in MODES}      # [called intersection, cases]
    misses = []
    for seed in range(a.seed, a.seed + a.n):
        sc = simulate_scenario(seed)
        rd = straight_road(seed)
        for m in MODES:
            ok = _state(sc, m) == 'INTERSECTION'
            inter[m][0] += ok
            inter[m][1] += 1
            if not ok:
                misses.append((seed, m, 'intersection called road'))
            if rd is not None:
                ok = _state(rd, m) == 'ROAD'
                road[m][0] += ok
                road[m][1] += 1
                if not ok:
                    misses.append((seed, m, 'road called intersection'))
    for m in MODES:
        print(f'{m:8s} straight road -> ROAD {road[m][0]}/{road[m][1]}   '
              f'intersection -> INTERSECTION {inter[m][0]}/{inter[m][1]}')
    for x in misses:
        print('miss', *x)
    return 0


if __name__ == '__main__':
    sys.exit(main())
