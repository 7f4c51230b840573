"""References of the topology moves (paper §II-B, Algorithm 1): bounds, one move of a
given kind, the proposal densities the compiled moves' Hastings ratios must match."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from intersection_estimator.model import wrap_angle
from intersection_estimator.topology.moves import (ADD_ARM, BEND_MOVE, CHANGE_GAP, LANE, OFFSET,
                                                   REMOVE_ARM, ROTATE, SHIFT, WIDTH, move_add_arm,
                                                   move_bend, move_gap, move_lane, move_offset,
                                                   move_remove_arm, move_rotate, move_shift,
                                                   move_width)
from intersection_estimator.topology.state import (P_BEND_MAX, P_BEND_S_MAX, P_BEND_S_MIN,
                                                   P_BEND_S_STEP, P_BEND_SCALE, P_BEND_STEP,
                                                   P_C_ARM, P_C_GAP, P_C_LANE, P_C_OFFSET, P_C_ROT,
                                                   P_C_SHIFT, P_C_WIDTH, P_GAP_MAX, P_GAP_STEP,
                                                   P_MAX_ARMS, P_MAX_LANES, P_MIN_ARMS,
                                                   P_MIN_LANES, P_MIN_SEP, P_OFF_MAX,
                                                   P_OFF_LAPLACE, P_OFF_SIGMA, P_OFF_STEP, P_ROT, P_SAMPLE_W,
                                                   P_SHIFT, P_SPLIT_SPAN, P_W_MAX, P_W_MIN,
                                                   P_W_STEP, arm_rows)


@njit(cache=False)   # test-only: not cached in the test tree
def propose_kind(S, S2, P, logqn, cumqn, kind, seed):
    """Apply one move of a given kind (testing / introspection); seeds the RNG."""
    np.random.seed(seed)
    S2[:] = S
    if kind == ROTATE:
        ok, lq, k = move_rotate(S, S2, P)
    elif kind == SHIFT:
        ok, lq, k = move_shift(S, S2, P)
    elif kind == CHANGE_GAP:
        ok, lq, k = move_gap(S, S2, P)
    elif kind == ADD_ARM:
        ok, lq, k = move_add_arm(S, S2, P, logqn, cumqn)
    elif kind == REMOVE_ARM:
        ok, lq, k = move_remove_arm(S, S2, P, logqn)
    elif kind == LANE:
        ok, lq, k = move_lane(S, S2, P)
    elif kind == WIDTH:
        ok, lq, k = move_width(S, S2, P)
    elif kind == OFFSET:
        ok, lq, k = move_offset(S, S2, P)
    else:
        ok, lq, k = move_bend(S, S2, P)
    return ok, lq, k


def is_valid(S: np.ndarray, P: np.ndarray) -> bool:
    """All geometric bounds of the model hold."""
    n = int(S[2])
    if not (P[P_MIN_ARMS] <= n <= P[P_MAX_ARMS]):
        return False
    A = arm_rows(S)
    for k in range(n):
        ang, gap, nin, nout, w, off, bend, at = A[k]
        if not (-math.pi <= ang < math.pi) or not (0.0 <= gap <= P[P_GAP_MAX]):
            return False
        if abs(off) > P[P_OFF_MAX] or abs(bend) > P[P_BEND_MAX]:
            return False
        if bend != 0.0 and not (P[P_BEND_S_MIN] <= at <= P[P_BEND_S_MAX]):
            return False
        for c in (nin, nout):
            if c != int(c) or not (P[P_MIN_LANES] <= c <= P[P_MAX_LANES]):
                return False
        if not (P[P_W_MIN] - 1e-12 <= w <= P[P_W_MAX] + 1e-12):
            return False
        for j in range(k):
            if abs(float(wrap_angle(A[j, 0] - ang))) < P[P_MIN_SEP]:
                return False
    return True


def propose_move(S: np.ndarray, kind: int, P: np.ndarray, logqn: np.ndarray,
                 seed: int) -> tuple[bool, float, np.ndarray]:
    """One move of ``kind`` (index into :data:`MOVE_NAMES`): (valid, log ratio, proposal)."""
    S2 = np.empty_like(S)
    cum = np.cumsum(np.exp(logqn))
    ok, lq, _ = propose_kind(S, S2, P, logqn, cum, kind, seed)
    return bool(ok), float(lq), S2


def _move_prob(P: np.ndarray, kind: int) -> float:
    cum = [0.0, P[P_C_ROT], P[P_C_SHIFT], P[P_C_GAP], P[P_C_ARM], P[P_C_LANE], P[P_C_WIDTH],
           P[P_C_OFFSET], 1.0]
    group = {ROTATE: 0, SHIFT: 1, CHANGE_GAP: 2, ADD_ARM: 3, REMOVE_ARM: 3,
             LANE: 4, WIDTH: 5, OFFSET: 6, BEND_MOVE: 7}[kind]
    p = cum[group + 1] - cum[group]
    return p * (0.5 if kind in (ADD_ARM, REMOVE_ARM) else 1.0)


def _add_angle_density(rows: np.ndarray, phi: float, P: np.ndarray) -> float:
    """Density of the add-arm angle (reference, written from the docstring)."""
    n = len(rows)
    ms, span = P[P_MIN_SEP], P[P_SPLIT_SPAN]
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
    the density is over (angle, gap, width, offset) of the new arm. Used by the tests to check
    the ratios the compiled moves return.
    """
    a, b = arm_rows(S_from), arm_rows(S_to)
    n = len(a)
    pm = _move_prob(P, kind)
    if kind == ROTATE:
        return math.log(pm / n / (2 * P[P_ROT]))
    if kind == SHIFT:
        r = float(np.hypot(*(S_to[:2] - S_from[:2])))
        return math.log(pm / (2 * math.pi * r * P[P_SHIFT])) if r > 0 else math.inf
    if kind == CHANGE_GAP:
        return math.log(pm / n / (2 * P[P_GAP_STEP]))
    if kind == WIDTH:
        return math.log(pm / n / (2 * P[P_W_STEP]))
    if kind == OFFSET:
        return math.log(pm / n / (2 * P[P_OFF_STEP]))
    if kind == BEND_MOVE:        # the angle or the place, 1/2 each
        step = P[P_BEND_STEP] if b[:, 6].tolist() != a[:, 6].tolist() else P[P_BEND_S_STEP]
        return math.log(0.5 * pm / n / (2 * step))
    if kind == LANE:
        nvar = 3 if P[P_SAMPLE_W] > 0 else 2
        return math.log(pm / n / (4.0 * nvar))
    if kind == ADD_ARM:
        new = b[-1]
        lq = math.log(_add_angle_density(a, new[0], P)) + logqn[int(new[2])] + logqn[int(new[3])]
        lq -= math.log(P[P_GAP_MAX])
        if P[P_SAMPLE_W] > 0:
            lq -= math.log(P[P_W_MAX] - P[P_W_MIN])
        if P[P_BEND_MAX] > 0:      # bend from Laplace(0, scale), its place uniform
            sc = P[P_BEND_SCALE]
            lq += (-abs(new[6]) / sc - math.log(2 * sc)
                   - math.log(P[P_BEND_S_MAX] - P[P_BEND_S_MIN]))
        if P[P_OFF_MAX] > 0 and P[P_OFF_LAPLACE] > 0:   # offset from Laplace(0, b)
            b = P[P_OFF_SIGMA]
            lq += -abs(new[5]) / b - math.log(2 * b)
        elif P[P_OFF_MAX] > 0:     # the new arm's offset, drawn from N(0, sigma)
            sig = P[P_OFF_SIGMA]
            lq += -0.5 * (new[5] / sig) ** 2 - math.log(sig * math.sqrt(2 * math.pi))
        return math.log(pm) + lq
    if kind == REMOVE_ARM:
        return math.log(pm / n)
    raise ValueError(kind)
