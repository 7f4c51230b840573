"""Estimate <-> mapped intersection by position; arms one-to-one by angle (Hungarian).

The same matching as the evaluation's (DESIGN.md §5: arms matched by angular distance),
with gates so that an estimate far from every mapped intersection, or an arm far from
every mapped arm, stays unmatched instead of being forced onto the nearest one.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..model import wrap_angle

__all__ = ['GATE_M', 'ARM_GATE_DEG', 'match_intersection', 'match_arms']

GATE_M = 15.0        # estimated center within this of the mapped one [m]
ARM_GATE_DEG = 30.0  # matched arms differ by less than this [deg] (Table I: arms >= 45 deg apart)


def match_intersection(center, mapped: list, gate_m: float = GATE_M):
    """The mapped intersection nearest to ``center`` within ``gate_m``, or None."""
    if not mapped:
        return None
    c = np.asarray(center, float)
    d = [float(np.hypot(*(m.center - c))) for m in mapped]
    i = int(np.argmin(d))
    return mapped[i] if d[i] <= gate_m else None


def match_arms(est_angles, map_angles, gate_deg: float = ARM_GATE_DEG) -> dict[int, int]:
    """``{estimated arm index: mapped arm index}``, one-to-one, angular distance < gate."""
    e = np.asarray(est_angles, float).reshape(-1, 1)
    m = np.asarray(map_angles, float).reshape(1, -1)
    if e.size == 0 or m.size == 0:
        return {}
    cost = np.abs(wrap_angle(e - m))
    rows, cols = linear_sum_assignment(cost)
    gate = math.radians(gate_deg)
    return {int(r): int(c) for r, c in zip(rows, cols) if cost[r, c] < gate}
