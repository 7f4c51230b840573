"""Arms whose axes do not meet in one point: the axis offset (beyond the paper).

Paper §II-B draws every lane as a ray from the one center ``c``. Real junctions seldom
have that shape: an approach meets the box a few metres beside the point where the
other arms' axes cross (skewed crossings, a T whose stem is offset, channelised turns).
With rays from ``c`` such an arm's lanes sit metres beside its traffic, and the chain
either pays for it with a wrong lane count, a wrong gap, a center pulled away from the
box, or drops the arm (issue 15: on SUMO junctions with axes up to 5 m off the center,
the true state scored tens of nats below the estimate under the straight-ray model).

The model here: arm ``k`` carries an axis offset ``o_k`` (state field ``OFF``); its
lanes are rays from ``c + o_k n_k`` (``n_k`` its left normal, :func:`.state.arm_origin`).
Its prior is a normal ``N(0, sigma)`` truncated to ``|o| <= max`` -- arms through the
center stay the default, an offset must be paid for by data (a 2-arm road, where the
center slides along the road, keeps its offsets near 0 instead of trading them against
the center). Compiled here:

* the random-walk move of one arm's offset is :func:`.moves.move_offset` (symmetric,
  with the fine / coarse step of every continuous move);
* :func:`offset_logq` -- the log density of a new arm's offset under the add-arm
  proposal, which draws it from the untruncated normal ``N(0, sigma)``; a draw outside
  ``|o| <= max`` is an invalid proposal (the chain stays), so the Hastings ratio keeps
  only the prior's truncation constant ``-log P(|N(0, sigma)| <= max)``;
* :func:`offset_log_prior` -- the state's sum of ``-o_k^2 / (2 sigma^2)``; the
  normalising constant per arm is in :func:`offset_log_const` (folded into the per-arm
  constant of :func:`.prior.log_prior`).

With ``TopologyConfig.arm_offset_prior = 'laplace'`` the prior is instead a Laplace
density ``exp(-|o| / sigma) / (2 sigma)`` truncated the same way (``sigma`` its scale):
it charges ``|o| / sigma`` nats, so a metre of offset that only fits noise costs much more
than under the normal of the same tail, while an arm several metres off still pays less
than the extra lanes the straight rays would need. The add-arm draw follows the prior's
kind.

Off (``TopologyConfig.arm_offset_max = 0``): every offset stays 0, the move is never
picked, the add-arm move draws nothing for it -- the sampler's random stream and every
estimate are those of the straight-ray model.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .state import HDR, OFF, P_OFF_LAPLACE, P_OFF_MAX, P_OFF_SIGMA, STRIDE

__all__ = ['offset_on', 'offset_ok', 'draw_offset', 'offset_logq', 'offset_arm_log_prior',
           'offset_log_prior', 'offset_log_const']

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


@njit(cache=True)
def offset_on(P) -> bool:
    """Is the axis offset part of the model?"""
    return P[P_OFF_MAX] > 0.0


@njit(cache=True)
def draw_offset(P):
    """A new arm's offset: ``N(0, sigma)`` or ``Laplace(0, sigma)`` (0 when the offset is
    off; nothing drawn)."""
    if not offset_on(P):
        return 0.0
    if P[P_OFF_LAPLACE] > 0.0:
        return np.random.laplace(0.0, P[P_OFF_SIGMA])
    return np.random.normal() * P[P_OFF_SIGMA]


@njit(cache=True)
def offset_logq(o, P):
    """log density of a new arm's offset ``o`` under :func:`draw_offset` (0 when off)."""
    if not offset_on(P):
        return 0.0
    if P[P_OFF_LAPLACE] > 0.0:
        return -abs(o) / P[P_OFF_SIGMA] - math.log(2.0 * P[P_OFF_SIGMA])
    z = o / P[P_OFF_SIGMA]
    return -0.5 * z * z - math.log(P[P_OFF_SIGMA]) - _LOG_SQRT_2PI


@njit(cache=True)
def offset_ok(o, P) -> bool:
    """Within the bound ``|o| <= max`` (only 0 when the offset is off)."""
    return abs(o) <= P[P_OFF_MAX]


@njit(cache=True, inline='always')
def offset_arm_log_prior(o, P):
    """One arm's term of :func:`offset_log_prior`: ``-o^2 / (2 sigma^2)``, or ``-|o| / sigma``
    for the Laplace prior (0 when the offset is off)."""
    if not offset_on(P):
        return 0.0
    if P[P_OFF_LAPLACE] > 0.0:
        return -(1.0 / P[P_OFF_SIGMA]) * abs(o)
    return -(0.5 / (P[P_OFF_SIGMA] * P[P_OFF_SIGMA])) * o * o


@njit(cache=True)
def offset_log_prior(S, P):
    """sum over the arms of :func:`offset_arm_log_prior` (the constant: per arm, in
    :func:`offset_log_const`)."""
    lp = 0.0
    for k in range(int(S[2])):
        lp += offset_arm_log_prior(S[HDR + k * STRIDE + OFF], P)
    return lp


def offset_log_const(sigma: float, max_offset: float, laplace: bool = False) -> float:
    """log normalising constant of the truncated prior of one arm's offset (0 when off):
    normal ``-log(sigma sqrt(2 pi)) - log P(|N(0, sigma)| <= max)``, Laplace
    ``-log(2 sigma) - log(1 - exp(-max / sigma))``."""
    if max_offset <= 0.0:
        return 0.0
    if laplace:
        return -math.log(2.0 * sigma) - math.log(-math.expm1(-max_offset / sigma))
    mass = math.erf(max_offset / (sigma * math.sqrt(2.0)))
    return -math.log(sigma) - _LOG_SQRT_2PI - math.log(mass)
