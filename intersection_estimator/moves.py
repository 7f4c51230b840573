"""Moves of the topology sampler (paper §II-B, Algorithm 1) and the packed chain state.

Each move (compiled in :mod:`_kernels`) takes the state ``S``, writes its proposal into a
copy and returns ``(valid, log Hastings ratio, changed arm)`` where the Hastings ratio is
``log q(old|new) - log q(new|old)`` -- the sampler only adds it to the posterior
difference (like emcee's moves). Invalid proposals (violating the geometric bounds) are
rejected and still count as samples. Moves and their default probabilities:

============  =====  ====================================================================
rotate        0.40   one random arm by U[-6 deg, 6 deg]; symmetric
shift         0.20   center by (dc, phi) ~ U([0, 6 m] x [0, 2 pi]); symmetric
gap           0.10   median gap of one arm by U[-1.8 m, 1.8 m], 0 <= gap <= gap_max;
                     symmetric
add/remove    0.15   1/2 add an arm: angle 1/2 uniform in the feasible part of the largest
arm                  angular gap, 1/2 'split': next to a random arm at U[min_sep,
                     min_sep + split_span] on a random side (a following rotate separates
                     the two halves of a split arm); lane counts from the lane prior,
                     gap U[0, gap_max], width U[w_min, w_max] (or the default width).
                     1/2 remove a random arm. Ratios: the add density (mixture over both
                     variants) against 1/|A'| for the removal.
add/remove    0.15   arm, direction, add/remove with probability 1/2, then a variant
lane                 uniformly: border: count +-1; median: count +-1 and gap -+ lane width
                     (the new lane takes the median strip); rescale (only with a sampled
                     width): count n -> n' = n +- 1 and width w -> w n/n' (same road
                     width). Add and remove of a variant are each other's reverse; ratio
                     0, or the Jacobian log(n/n') for rescale.
width         0.00   (beyond the paper) lane width of one arm by U[-step, step]; symmetric
============  =====  ====================================================================

Bounds kept by every move: ``min_arms <= |A| <= max_arms``, angle between any two arms
``>= min_sep``, ``min_lanes <= lanes <= max_lanes`` per direction (``min_lanes >= 1``: one-way
roads are not modelled), ``0 <= gap <= gap_max``, ``w_min <= width <= w_max``.
"""

from __future__ import annotations

import math

import numpy as np

from . import _kernels as K
from .model import Arm, Intersection, wrap_angle

__all__ = ['MOVE_NAMES', 'pack_state', 'unpack_state', 'propose_move', 'is_valid',
           'proposal_log_density']

MOVE_NAMES = K.MOVE_NAMES


def pack_state(inter: Intersection) -> np.ndarray:
    """Intersection -> flat state vector (see :mod:`_kernels`)."""
    S = np.zeros(K.STATE_LEN)
    S[0:2] = inter.center
    S[2] = len(inter.arms)
    if len(inter.arms) > K.MAXA:
        raise ValueError(f'at most {K.MAXA} arms supported, got {len(inter.arms)}')
    for k, a in enumerate(inter.arms):
        i = K.HDR + k * K.STRIDE
        S[i:i + K.STRIDE] = (float(wrap_angle(a.angle)), a.gap, a.lanes_in, a.lanes_out,
                             a.lane_width)
    return S


def unpack_state(S: np.ndarray, traffic_side: int = 1, confidence=None) -> Intersection:
    """Flat state vector -> Intersection (arms sorted by angle)."""
    arms = []
    for k in range(int(S[2])):
        i = K.HDR + k * K.STRIDE
        arms.append(Arm(angle=float(S[i]), gap=float(S[i + 1]), lanes_in=int(S[i + 2]),
                        lanes_out=int(S[i + 3]), lane_width=float(S[i + 4]),
                        confidence=1.0 if confidence is None else float(confidence[k])))
    return Intersection(center=S[0:2].copy(), arms=arms, traffic_side=traffic_side)


def arm_rows(S: np.ndarray) -> np.ndarray:
    """(|A|, 5) view of the arm parameters."""
    n = int(S[2])
    return S[K.HDR:K.HDR + n * K.STRIDE].reshape(n, K.STRIDE)


def is_valid(S: np.ndarray, P: np.ndarray) -> bool:
    """All geometric bounds of the model hold."""
    n = int(S[2])
    if not (P[K.P_MIN_ARMS] <= n <= P[K.P_MAX_ARMS]):
        return False
    A = arm_rows(S)
    for k in range(n):
        ang, gap, nin, nout, w = A[k]
        if not (-math.pi <= ang < math.pi) or not (0.0 <= gap <= P[K.P_GAP_MAX]):
            return False
        for c in (nin, nout):
            if c != int(c) or not (P[K.P_MIN_LANES] <= c <= P[K.P_MAX_LANES]):
                return False
        if not (P[K.P_W_MIN] - 1e-12 <= w <= P[K.P_W_MAX] + 1e-12):
            return False
        for j in range(k):
            if abs(float(wrap_angle(A[j, 0] - ang))) < P[K.P_MIN_SEP]:
                return False
    return True


def propose_move(S: np.ndarray, kind: int, P: np.ndarray, logqn: np.ndarray,
                 seed: int) -> tuple[bool, float, np.ndarray]:
    """One move of ``kind`` (index into :data:`MOVE_NAMES`): (valid, log ratio, proposal)."""
    S2 = np.empty_like(S)
    cum = np.cumsum(np.exp(logqn))
    ok, lq, _ = K.propose_kind(S, S2, P, logqn, cum, kind, seed)
    return bool(ok), float(lq), S2


def _move_prob(P: np.ndarray, kind: int) -> float:
    cum = [0.0, P[K.P_C_ROT], P[K.P_C_SHIFT], P[K.P_C_GAP], P[K.P_C_ARM], P[K.P_C_LANE], 1.0]
    group = {K.ROTATE: 0, K.SHIFT: 1, K.CHANGE_GAP: 2, K.ADD_ARM: 3, K.REMOVE_ARM: 3,
             K.LANE: 4, K.WIDTH: 5}[kind]
    p = cum[group + 1] - cum[group]
    return p * (0.5 if kind in (K.ADD_ARM, K.REMOVE_ARM) else 1.0)


def _add_angle_density(rows: np.ndarray, phi: float, P: np.ndarray) -> float:
    """Density of the add-arm angle (reference, written from the docstring)."""
    n = len(rows)
    ms, span = P[K.P_MIN_SEP], P[K.P_SPLIT_SPAN]
    if n == 0:
        return 1.0 / (2 * math.pi)
    ang = np.sort(rows[:, 0] % (2 * math.pi))
    gaps = np.diff(np.append(ang, ang[0] + 2 * math.pi))
    j = int(np.argmax(gaps))
    L = gaps[j] - 2 * ms
    dens = 0.0
    if L > 0 and (phi - ang[j] - ms) % (2 * math.pi) <= L:
        dens += 0.5 / L
    if span > 0:
        for a in rows[:, 0]:
            for delta in ((phi - a) % (2 * math.pi), (a - phi) % (2 * math.pi)):
                if ms <= delta <= ms + span:
                    dens += 0.5 * (1.0 / n) * 0.5 / span
    return dens


def proposal_log_density(S_from: np.ndarray, S_to: np.ndarray, kind: int, P: np.ndarray,
                         logqn: np.ndarray) -> float:
    """log q(S_to | S_from) of the full kernel restricted to move ``kind`` (reference).

    Continuous moves are given as densities in their own coordinates; for add/remove arm
    the density is over (angle, gap, width) of the new arm. Used by the tests to check
    the ratios the compiled moves return.
    """
    a, b = arm_rows(S_from), arm_rows(S_to)
    n = len(a)
    pm = _move_prob(P, kind)
    if kind == K.ROTATE:
        return math.log(pm / n / (2 * P[K.P_ROT]))
    if kind == K.SHIFT:
        r = float(np.hypot(*(S_to[:2] - S_from[:2])))
        return math.log(pm / (2 * math.pi * r * P[K.P_SHIFT])) if r > 0 else math.inf
    if kind == K.CHANGE_GAP:
        return math.log(pm / n / (2 * P[K.P_GAP_STEP]))
    if kind == K.WIDTH:
        return math.log(pm / n / (2 * P[K.P_W_STEP]))
    if kind == K.LANE:
        nvar = 3 if P[K.P_SAMPLE_W] > 0 else 2
        return math.log(pm / n / (4.0 * nvar))
    if kind == K.ADD_ARM:
        new = b[-1]
        lq = math.log(_add_angle_density(a, new[0], P)) + logqn[int(new[2])] + logqn[int(new[3])]
        lq -= math.log(P[K.P_GAP_MAX])
        if P[K.P_SAMPLE_W] > 0:
            lq -= math.log(P[K.P_W_MAX] - P[K.P_W_MIN])
        return math.log(pm) + lq
    if kind == K.REMOVE_ARM:
        return math.log(pm / n)
    raise ValueError(kind)
