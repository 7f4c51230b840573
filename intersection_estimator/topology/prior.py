"""Intersection prior P(I) = P(|A|) * P(|L|) (paper §II-C1).

How the count distributions were "learned" (the paper learns them but does not publish
them), and why they are not the benchmark's generator distribution:

* Arms: the paper's survey of real intersections around Karlsruhe gives a mean of 2.5
  arms and at most 5; a distribution with that mean on {2..5} is
  ``(0.60, 0.30, 0.08, 0.02)``. The synthetic benchmark (Table I) draws uniformly from
  {3, 4, 5}. The default is the 50/50 mixture of both, plus a small floor (1e-3) on
  every other count up to ``MAXA`` so no arm count is impossible a priori.
* Lanes per driving direction: real roads mostly have one lane per direction ("at least
  20 % of the intersections have more than 3 lanes in total"); we use
  ``(0.70, 0.22, 0.06, 0.02)`` for 1..4 lanes and mix it 50/50 with the benchmark's
  uniform 1..4, again with a small floor beyond. ``P(|L|)`` factorises over arms and
  directions (independent lane counts).

The mixture keeps real-world plausibility (fewer arms / lanes are more likely) without
tailoring the prior to the benchmark generator; both tables are configurable
(``TopologyConfig.arm_count_prior``, ``lane_count_prior``). Angle, gap, lane width and
center get non-informative (uniform) priors; their densities enter as a per-arm constant
so that add/remove-arm moves are dimensionally consistent. The set of arms is unordered,
hence the ``log |A|!`` term (density of a set with respect to the symmetric measure).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .state import HDR, MAXA, NIN, NOUT, STRIDE

__all__ = ['ARM_COUNT_PRIOR', 'LANE_COUNT_PRIOR', 'count_log_table', 'arm_log_const',
           'log_prior']

_REAL_ARMS = {2: 0.60, 3: 0.30, 4: 0.08, 5: 0.02}
_SIM_ARMS = {3: 1 / 3, 4: 1 / 3, 5: 1 / 3}
_REAL_LANES = {1: 0.70, 2: 0.22, 3: 0.06, 4: 0.02}
_SIM_LANES = {1: 0.25, 2: 0.25, 3: 0.25, 4: 0.25}
_FLOOR = 1e-3


def _mix(a: dict, b: dict, n: int, lo: int) -> tuple[float, ...]:
    p = [0.0 if i < lo else 0.5 * a.get(i, 0.0) + 0.5 * b.get(i, 0.0) + _FLOOR
         for i in range(n)]
    s = sum(p)
    return tuple(round(x / s, 6) for x in p)


#: P(|A| = i) for i = 0..MAXA (default of ``TopologyConfig.arm_count_prior``).
ARM_COUNT_PRIOR = _mix(_REAL_ARMS, _SIM_ARMS, MAXA + 1, 1)
#: P(lanes per direction = i) for i = 0..6 (default of ``TopologyConfig.lane_count_prior``).
LANE_COUNT_PRIOR = _mix(_REAL_LANES, _SIM_LANES, 7, 1)


def count_log_table(probs, lo: int, hi: int, size: int) -> np.ndarray:
    """log of ``probs`` renormalised on ``[lo, hi]``, ``-inf`` elsewhere, length ``size``."""
    p = np.zeros(size)
    for i in range(lo, min(hi, len(probs) - 1) + 1):
        p[i] = probs[i]
    s = p.sum()
    with np.errstate(divide='ignore'):
        return np.log(p / s) if s > 0 else np.full(size, -np.inf)


def arm_log_const(gap_max: float, w_min: float, w_max: float, sample_width: bool) -> float:
    """log of the uniform densities of one arm's angle, gap (and lane width)."""
    c = -math.log(2 * math.pi) - math.log(gap_max)
    if sample_width:
        c -= math.log(w_max - w_min)
    return c


@njit(cache=True)
def log_prior(S, logPA, logPn, arm_const):
    """log P(I) = log P(|A|) + log |A|! + sum_arms [log P(n_in) + log P(n_out) + const].

    ``|A|!`` makes it the density of the unordered arm set; ``arm_const`` holds the
    uniform (non-informative) densities of angle, gap and lane width (paper §II-C1).
    """
    n = int(S[2])
    lp = logPA[n] + math.lgamma(n + 1.0) + n * arm_const
    for k in range(n):
        i = HDR + k * STRIDE
        lp += logPn[int(S[i + NIN])] + logPn[int(S[i + NOUT])]
    return lp
