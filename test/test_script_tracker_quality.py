"""scripts/tracker_quality.py: the radar tracker scored against the simulator's vehicles."""

import importlib.util
from pathlib import Path

from intersection_estimator.bench import BenchOptions, make_case
from intersection_estimator.tracking import TrackerConfig

_PATH = Path(__file__).resolve().parents[1] / 'scripts' / 'tracker_quality.py'
_spec = importlib.util.spec_from_file_location('tracker_quality', _PATH)
tq = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tq)


def test_quality_of_the_default_tracker_and_of_a_broken_one():
    """The default tracker covers the vehicles the radar saw, one track per vehicle or
    nearly; gates of a third of a sigma break the tracks into pieces and lose rows."""
    sc, _ = make_case(BenchOptions(n=1, seed=3, mode='raw'), 0)
    good = tq.case_quality(sc, TrackerConfig())
    bad = tq.case_quality(sc, TrackerConfig(gate_sigma=0.3))
    cover = lambda q: q['covered'] / q['truth_moving']
    assert cover(good) > 0.9 and good['off'] < 0.1 * good['rows']
    assert 1.0 <= good['pairs'] / good['vehicles'] < 1.6
    assert 1.0 <= good['pairs'] / good['tracks'] < 1.4
    assert cover(bad) < cover(good) - 0.1
