"""The packed layouts of the topology sampler (paper §II-B) and the chain container.

State ``S`` (float64 vector, cheap to copy; one intersection ``I = (c, A)``):

==========================  =========================================================
``S[CX], S[CY]``            center ``c`` [m]
``S[NARMS]``                number of arms ``|A|``
``S[HDR + k*STRIDE + f]``   field ``f`` of arm slot ``k``: ``ANG`` angle [rad, wrapped
                            to [-pi, pi)], ``GAP`` median gap [m], ``NIN`` / ``NOUT``
                            entering / leaving lane count, ``WID`` lane width [m],
                            ``OFF`` axis offset [m] (beyond the paper, below),
                            ``BEND`` bend [rad] at ``BENDAT`` [m] out along the axis
                            (beyond the paper, :mod:`.arm_bend`)
==========================  =========================================================

The axis offset (beyond the paper; :mod:`.arm_offset`) moves an arm's axis sideways,
along its left normal ``n``: the arm's lanes are rays from ``c + OFF * n`` instead of from
``c`` (real arms do not meet in one point). It is 0 unless the offset move is on.

Slots ``>= |A|`` are unused. Arms are an unordered set; the slot order carries no meaning.

Kernel parameters ``P`` (float64 vector, filled by :meth:`config.TopologyConfig.kernel_params`):
one named slot ``P_*`` per value, the same convention as the lane course's ``PRM_*``
(:mod:`..lanes.mcmc`). Flags are stored as 1.0 / 0.0 (numba kernels take one flat vector).

The geometry of a packed state (angle wrap, separation, largest angular gap) is compiled
here because every move needs it.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from numba import njit

from ..model import Arm, Intersection, wrap_angle

__all__ = ['MAXA', 'HDR', 'STRIDE', 'STATE_LEN', 'CX', 'CY', 'NARMS', 'ANG', 'GAP', 'NIN',
           'NOUT', 'WID', 'OFF', 'BEND', 'BENDAT', 'NPARAM', 'arm_origin', 'Chain', 'pack_state', 'unpack_state',
           'arm_rows', 'arm_angles', 'wrap', 'separation_ok', 'largest_gap']

MAXA = 8                      # arm slots
CX, CY, NARMS = 0, 1, 2       # header slots
HDR = 3                       # header length
STRIDE = 8                    # values per arm slot
ANG, GAP, NIN, NOUT, WID, OFF, BEND, BENDAT = 0, 1, 2, 3, 4, 5, 6, 7
STATE_LEN = HDR + STRIDE * MAXA

# Kernel parameter slots (see the module docstring; units as in TopologyConfig).
(P_MIN_SEP, P_MIN_ARMS, P_MAX_ARMS, P_MIN_LANES, P_MAX_LANES, P_GAP_MAX, P_W_MIN, P_W_MAX,
 P_ROT, P_SHIFT, P_GAP_STEP, P_W_STEP, P_SPLIT_SPAN,
 P_C_ROT, P_C_SHIFT, P_C_GAP, P_C_ARM, P_C_LANE,
 P_FLOOR, P_TRAFFIC, P_D2_CUT, P_SAMPLE_W, P_W_DEFAULT,
 P_LANE_NORM, P_FINE_P, P_FINE_SCALE, P_LANE_SUM, P_FOCUS, P_FOCUS_P,
 P_C_WIDTH, P_OFF_MAX, P_OFF_STEP, P_OFF_SIGMA, P_OFF_LAPLACE,
 P_C_OFFSET, P_BEND_MAX, P_BEND_STEP, P_BEND_SCALE, P_BEND_S_MIN, P_BEND_S_MAX,
 P_BEND_S_STEP) = range(41)
NPARAM = 41

TWO_PI = 2.0 * math.pi
LOG_TWO_PI = math.log(TWO_PI)
NEG_INF = -np.inf


def pack_state(inter: Intersection) -> np.ndarray:
    """Intersection -> packed state ``S``."""
    S = np.zeros(STATE_LEN)
    S[CX:CY + 1] = inter.center
    S[NARMS] = len(inter.arms)
    if len(inter.arms) > MAXA:
        raise ValueError(f'at most {MAXA} arms supported, got {len(inter.arms)}')
    for k, a in enumerate(inter.arms):
        i = HDR + k * STRIDE
        S[i:i + STRIDE] = (float(wrap_angle(a.angle)), a.gap, a.lanes_in, a.lanes_out,
                           a.lane_width, a.offset, a.bend, a.bend_at)
    return S


def unpack_state(S: np.ndarray, traffic_side: int = 1, confidence=None) -> Intersection:
    """Packed state ``S`` -> Intersection (``confidence`` per arm slot, default 1)."""
    arms = []
    for k in range(int(S[NARMS])):
        i = HDR + k * STRIDE
        arms.append(Arm(angle=float(S[i + ANG]), gap=float(S[i + GAP]),
                        lanes_in=int(S[i + NIN]), lanes_out=int(S[i + NOUT]),
                        lane_width=float(S[i + WID]), offset=float(S[i + OFF]),
                        bend=float(S[i + BEND]), bend_at=float(S[i + BENDAT]),
                        confidence=1.0 if confidence is None else float(confidence[k])))
    return Intersection(center=S[CX:CY + 1].copy(), arms=arms, traffic_side=traffic_side)


def arm_rows(S: np.ndarray) -> np.ndarray:
    """(|A|, STRIDE) view of the arm parameters."""
    n = int(S[NARMS])
    return S[HDR:HDR + n * STRIDE].reshape(n, STRIDE)


def arm_angles(S: np.ndarray) -> np.ndarray:
    """Copy of the arm angles of ``S`` (slot order)."""
    return S[HDR + ANG:HDR + int(S[NARMS]) * STRIDE:STRIDE].copy()


@dataclass(eq=False)
class Chain:
    """One Markov chain: current state ``S`` with its per-arm likelihood columns ``C``
    (``MAXA`` x observations), log likelihood ``ll`` and log prior ``lp`` of ``S``, the
    best (MAP) state so far and its log posterior, steps taken, and per move kind
    (proposed, accepted) counts in ``stats``."""

    __slots__ = ('S', 'C', 'll', 'lp', 'best_S', 'best_lpost', 'step', 'stats')

    S: np.ndarray
    C: np.ndarray
    ll: float
    lp: float
    best_S: np.ndarray
    best_lpost: float
    step: int
    stats: np.ndarray

    @classmethod
    def start(cls, S: np.ndarray, n_obs: int, n_moves: int, ll: float = 0.0, lp: float = 0.0,
              best_lpost: float = -math.inf) -> 'Chain':
        """A chain at step 0 in state ``S`` (copied), columns zero."""
        return cls(S=S.copy(), C=np.zeros((MAXA, n_obs)), ll=ll, lp=lp, best_S=S.copy(),
                   best_lpost=best_lpost, step=0, stats=np.zeros(2 * n_moves, np.int64))


@njit(cache=True, inline='always')
def arm_origin(S, k, ux, uy):
    """Start of arm ``k``'s axis, ``c + OFF * n`` with ``n = (-uy, ux)`` its left normal
    (``(ux, uy)`` the arm's unit direction): the center when the offset is 0."""
    off = S[HDR + k * STRIDE + OFF]
    return S[0] - off * uy, S[1] + off * ux


@njit(cache=True)
def wrap(a):
    """Wrap to ``[-pi, pi)``."""
    return (a + math.pi) % TWO_PI - math.pi


@njit(cache=True)
def separation_ok(S, k, min_sep):
    """Arm ``k`` keeps at least ``min_sep`` to every other arm."""
    n = int(S[2])
    a = S[HDR + k * STRIDE]
    for j in range(n):
        if j != k and abs(wrap(S[HDR + j * STRIDE] - a)) < min_sep:
            return False
    return True


@njit(cache=True)
def largest_gap(S):
    """(start angle, width) of the largest angular gap between adjacent arms."""
    n = int(S[2])
    if n == 0:
        return 0.0, TWO_PI
    ang = np.empty(n)
    for j in range(n):
        ang[j] = S[HDR + j * STRIDE] % TWO_PI
    ang.sort()
    best = -1.0
    start = 0.0
    for j in range(n):
        nxt = ang[j + 1] if j + 1 < n else ang[0] + TWO_PI
        g = nxt - ang[j]
        if g > best:
            best = g
            start = ang[j]
    return start, best
