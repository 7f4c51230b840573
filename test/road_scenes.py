"""Straight-road cases from the Table I simulator (observability tests and
``scripts/observability_cases.py``).

A scenario's traffic is restricted to the routes between two arms that are within
``tol_deg`` of opposite (the through traffic of one road), the ego driving on one of
them; the detections of every mode are then simulated from those tracks only (same
sensor models, noise, clutter and false tracks as the full scenario). The data show a
straight road; the intersection around it carries no traffic.
"""

from __future__ import annotations

from dataclasses import replace
import math
import re

import numpy as np

from intersection_estimator.sim import Scenario, simulate_scenario

_CONNECTOR = re.compile(r'c_a(\d+)i\d+_a(\d+)o\d+')     # sim/scenario.connector_id


def _road_arms(sc: Scenario, tol_deg: float):
    """The pair of arms closest to opposite (within ``tol_deg``) that holds the ego, or None."""
    arms = sc.gt.arms
    best = None
    for a in range(len(arms)):
        for b in range(a + 1, len(arms)):
            d = abs(abs(math.degrees(float(np.angle(np.exp(1j * (arms[a].angle - arms[b].angle))))))
                    - 180.0)
            if d <= tol_deg and sc.ego.arm in (a, b) and (best is None or d < best[0]):
                best = (d, a, b)
    return None if best is None else best[1:]


def straight_road(seed: int, tol_deg: float = 15.0, min_tracks: int = 2) -> Scenario | None:
    """The scenario of ``seed`` with only the through traffic of one road, or None when
    it has no such road (or fewer than ``min_tracks`` vehicles on it)."""
    sc = simulate_scenario(seed)
    pair = _road_arms(sc, tol_deg)
    if pair is None:
        return None
    a, b = pair
    keep = []
    for tr in sc.tracks:
        m = [_CONNECTOR.fullmatch(r) for r in tr.route]
        arms = [(int(x.group(1)), int(x.group(2))) for x in m if x]
        if arms and set(arms[0]) == {a, b}:
            keep.append(tr)
    if len(keep) < min_tracks:
        return None
    return replace(sc, tracks=keep, _cache={})
