"""Fixtures of the fleet tests: simulated cases and their (cached) tracked estimates."""

from __future__ import annotations

import pytest

from intersection_estimator.pipeline import estimate
from intersection_estimator.sim import simulate_scenario

SEEDS = (1, 2, 5)


@pytest.fixture(scope='session')
def cases():
    """seed -> (scenario, estimate of its tracked detections), computed once per run."""
    out = {}
    for s in SEEDS:
        sc = simulate_scenario(s)
        out[s] = (sc, estimate(sc.detections('tracked'), seed=0))
    return out


@pytest.fixture(scope='session')
def fleet_data(tmp_path_factory):
    """Two drives (80 % of the vehicles each) through seed 5's intersection, a corrupt
    bag beside them, and the prior map of seed 5 with one lane moved by 1 m."""
    import numpy as np

    from intersection_estimator.bagio import write_scenario_bag
    from intersection_estimator.export.osm import write_osm
    from intersection_estimator.fleet.edits import apply_edit, drive_variant
    root = tmp_path_factory.mktemp('fleet')
    sc = simulate_scenario(5)
    for d in (1, 2):
        write_scenario_bag(drive_variant(sc, d, 0.8), root / 'bags' / f'drive{d}', sensors=('tracked',),
                           autoware=False)
    (root / 'bags' / 'broken.mcap').write_bytes(b'\x89MCAP0\r\n' + bytes(range(256)) * 4)
    lls, what = apply_edit(sc, 'lane_moved', np.random.default_rng(5))
    write_osm(root / 'map.osm', lls)
    return {'root': root, 'bags': root / 'bags', 'map': root / 'map.osm', 'moved': what['lane']}


def without_edit_lanes(edit: str, what: dict, findings: list) -> list:
    """``findings`` without the ``lane_added`` an ``arm_removed`` edit made true: the lanes
    of other arms that only its turns needed went with the arm (``edits._arm_removed``), one
    per listed direction at most."""
    if edit != 'arm_removed':
        return list(findings)
    extra = [f for f in findings if f.kind == 'lane_added']
    assert len(extra) <= len(what['lanes'])
    assert {f.direction for f in extra} <= {'in' if k == 'entering' else 'out' for _, k in what['lanes']}
    return [f for f in findings if f.kind != 'lane_added']
