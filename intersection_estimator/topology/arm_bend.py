"""Arms that bend: one kink in an arm's axis (beyond the paper).

Paper §II-B draws every lane as a straight ray from the center. Real approaches curve:
the SUMO family's bend by up to 35 deg from 10-40 m out, and on a bent approach the
part means of §II-A lie metres beside the straight ray the farther out they are. The
chain then pays with a center moved down the curved road (both bent arms line up with
their traffic again), with lanes that are not there, or by dropping an arm (issue 15:
SUMO dev seeds with the approaches left straight gain 5 points of arm accuracy and 32
of topology_observed, ``docs/real_junctions.md``).

The model here: arm ``k`` carries a bend ``beta_k`` (state field ``BEND``, rad, left
positive) at ``s_k`` metres out along its axis (``BENDAT``). Up to the kink the axis is
the straight ray of §II-B (from the axis origin, :func:`.state.arm_origin`); beyond it
the axis turns by ``beta`` and runs straight again, and the lanes keep their lateral
places along it. An observation belongs to the outer piece when it lies beyond the
bisector of the kink (lanes offset from a kinked axis meet exactly there) and is then
measured in that piece's frame (:func:`unbend`): its along-arm distance, lateral offset
and the cosine of its heading against the piece's direction. Nothing in it knows a
simulator's curve family: a kink is the simplest bent line, its place and angle come
from the data.

Prior: the factor ``exp(-|beta| / b)`` (``b`` = ``arm_bend_scale_deg``) on ``|beta| <=
max`` and a flat place on ``[s_min, s_max]``, left unnormalised: a straight arm scores
exactly as in the straight model (a normalised Laplace x uniform charged every arm ~3
nats, straight or not, and cost arms), a bend pays ``|beta| / b`` nats. Moves: :func:`.moves.move_bend` (a random
walk of one arm's angle or place, symmetric); add-arm draws a new arm's bend from the
prior (:func:`draw_bend`, its density :func:`bend_logq` in the Hastings ratio; a draw
beyond the bound is an invalid proposal). Off (``arm_bend_max_deg = 0``): nothing is
drawn, the move is never picked, every estimate is that of the straight model.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .state import (BEND, BENDAT, HDR, P_BEND_MAX, P_BEND_SCALE, P_BEND_S_MAX, P_BEND_S_MIN,
                    STRIDE)

__all__ = ['bend_on', 'draw_bend', 'bend_logq', 'bend_ok', 'bend_log_prior', 'unbend']


@njit(cache=True)
def bend_on(P) -> bool:
    """Is the bend part of the model?"""
    return P[P_BEND_MAX] > 0.0


@njit(cache=True)
def draw_bend(P):
    """A new arm's (bend, place): Laplace(0, b) and U[s_min, s_max]; (0, 0) when off,
    nothing drawn."""
    if not bend_on(P):
        return 0.0, 0.0
    beta = np.random.laplace(0.0, P[P_BEND_SCALE])
    s = P[P_BEND_S_MIN] + np.random.random() * (P[P_BEND_S_MAX] - P[P_BEND_S_MIN])
    return beta, s


@njit(cache=True)
def bend_logq(beta, P):
    """log density of a new arm's bend under :func:`draw_bend` (0 when off)."""
    if not bend_on(P):
        return 0.0
    return (-abs(beta) / P[P_BEND_SCALE] - math.log(2.0 * P[P_BEND_SCALE])
            - math.log(P[P_BEND_S_MAX] - P[P_BEND_S_MIN]))


@njit(cache=True)
def bend_ok(beta, s, P) -> bool:
    """Within ``|beta| <= max`` and ``s_min <= s <= s_max`` (only 0 when off)."""
    if not bend_on(P):
        return beta == 0.0
    return abs(beta) <= P[P_BEND_MAX] and P[P_BEND_S_MIN] <= s <= P[P_BEND_S_MAX]


@njit(cache=True)
def bend_log_prior(S, P):
    """sum over the arms of ``-|beta_k| / b`` (module doc: no normalising constant)."""
    if not bend_on(P):
        return 0.0
    ib = 1.0 / P[P_BEND_SCALE]
    lp = 0.0
    for k in range(int(S[2])):
        lp -= ib * abs(S[HDR + k * STRIDE + BEND])
    return lp


@njit(cache=True, fastmath=True, inline='always')
def unbend(s, t, c, cn, at, cb, sb):
    """An observation at along-arm ``s``, lateral ``t`` (left +), heading cosines ``c``
    (against the axis) and ``cn`` (against its left normal), measured on an axis that
    turns by ``beta`` (``cb, sb = cos, sin beta``) at ``at``: unchanged before the
    kink's bisector, in the outer piece's frame beyond it. Returns ``(s, t, c)``."""
    dx = s - at
    if dx * (1.0 + cb) + t * sb <= 0.0:
        return s, t, c
    return at + dx * cb + t * sb, t * cb - dx * sb, c * cb + cn * sb
