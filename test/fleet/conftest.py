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
