"""Moves of the topology sampler (paper §II-B, Algorithm 1), compiled.

Each move takes the state ``S`` (:mod:`.state`), writes its proposal into a copy ``S2``
and returns ``(valid, log Hastings ratio, changed arm slot or -1)`` where the Hastings
ratio is ``log q(old|new) - log q(new|old)`` -- the sampler only adds it to the posterior
difference (like emcee's moves). Invalid proposals (violating the geometric bounds) are
rejected and still count as samples. :func:`propose` picks the move (omega ~ U[0, 1]
against the cumulative move probabilities). Moves and their default probabilities
(``TopologyConfig.p_*``, normalised to sum 1: 0.40 / 0.20 / 0.10 / 0.15 / 0.15 / 0.10
over 1.10):

============  =====  ====================================================================
rotate        0.36   one arm by U[-6 deg, 6 deg]; symmetric
shift         0.18   center by (dc, phi) ~ U([0, 6 m] x [0, 2 pi]); symmetric
gap           0.09   median gap of one arm by U[-1.8 m, 1.8 m], 0 <= gap <= gap_max;
                     symmetric
add/remove    0.14   1/2 add an arm: angle 1/2 uniform in the feasible part of the largest
arm                  angular gap, 1/2 'split': next to a random arm at U[min_sep,
                     min_sep + split_span] on a random side (a following rotate separates
                     the two halves of a split arm); lane counts from the lane prior,
                     gap U[0, gap_max], width U[w_min, w_max] (or the default width).
                     1/2 remove a random arm. Ratios: the add density (mixture over both
                     variants) against 1/|A'| for the removal.
add/remove    0.14   arm, direction, add/remove with probability 1/2, then a variant
lane                 uniformly: border: count +-1; median: count +-1 and gap -+ lane width
                     (the new lane takes the median strip); rescale (only with a sampled
                     width): count n -> n' = n +- 1 and width w -> w n/n' (same road
                     width). Add and remove of a variant are each other's reverse; ratio
                     0, or the Jacobian log(n/n') for rescale.
width         0.09   (beyond the paper) lane width of one arm by U[-step, step]; symmetric
offset        0      (beyond the paper, :mod:`.arm_offset`; when on) axis offset of one arm
                     by U[-step, step], ``|offset| <= max``; symmetric. Add-arm then also
                     draws the new arm's offset from its prior normal.
bend          0      (beyond the paper, :mod:`.arm_bend`; when on) one arm's bend angle
                     (1/2) or its place along the axis (1/2) by U[-step, step], within
                     their bounds; symmetric. Add-arm then also draws the new arm's bend
                     from its prior.
============  =====  ====================================================================

Continuous moves use ``fine_step_scale`` x their range with probability
``fine_step_prob`` (beyond the paper). Bounds kept by every move: ``min_arms <= |A| <=
max_arms``, angle between any two arms ``>= min_sep``, ``min_lanes <= lanes <=
max_lanes`` per direction (``min_lanes >= 1``: one-way roads are not modelled),
``0 <= gap <= gap_max``, ``w_min <= width <= w_max``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .arm_bend import bend_logq, bend_ok, draw_bend
from .arm_offset import draw_offset, offset_logq, offset_ok
from .state import (ANG, BEND, BENDAT, GAP, HDR, LOG_TWO_PI, MAXA, NEG_INF, NIN, NOUT, OFF,
                    P_BEND_MAX, P_BEND_S_MAX, P_BEND_S_MIN, P_BEND_S_STEP, P_BEND_STEP,
                    P_C_ARM, P_C_GAP, P_C_LANE, P_C_OFFSET, P_C_ROT, P_C_SHIFT, P_C_WIDTH,
                    P_FINE_P, P_FINE_SCALE, P_FOCUS,
                    P_FOCUS_P, P_OFF_MAX, P_OFF_STEP,
                    P_GAP_MAX, P_GAP_STEP, P_MAX_ARMS, P_MAX_LANES, P_MIN_ARMS, P_MIN_LANES,
                    P_MIN_SEP, P_ROT, P_SAMPLE_W, P_SHIFT, P_SPLIT_SPAN, P_W_DEFAULT, P_W_MAX,
                    P_W_MIN, P_W_STEP, STRIDE, TWO_PI, WID, largest_gap, separation_ok, wrap)

__all__ = ['MOVE_NAMES', 'ROTATE', 'SHIFT', 'CHANGE_GAP', 'ADD_ARM', 'REMOVE_ARM', 'LANE',
           'WIDTH', 'OFFSET', 'BEND_MOVE', 'propose', 'remove_arm_at', 'move_rotate', 'move_shift',
           'move_gap', 'move_width', 'move_offset', 'move_bend', 'move_add_arm', 'move_remove_arm', 'move_lane',
           'add_arm_angle_logdensity', 'new_arm_logdensity']

ROTATE, SHIFT, CHANGE_GAP, ADD_ARM, REMOVE_ARM, LANE, WIDTH, OFFSET, BEND_MOVE = range(9)
MOVE_NAMES = ('rotate', 'shift', 'gap', 'add_arm', 'remove_arm', 'lane', 'width', 'offset',
              'bend')


@njit(cache=True)
def _step(P):
    """Step scale of a continuous move: 1, or ``P_FINE_SCALE`` with prob. ``P_FINE_P``.

    A fixed mixture of two symmetric uniform kernels is symmetric (ratio 0); the fine
    scale (beyond the paper) lets the annealed chain settle within the paper's ranges.
    """
    return P[P_FINE_SCALE] if np.random.random() < P[P_FINE_P] else 1.0


@njit(cache=True)
def add_arm_angle_logdensity(S, phi, P):
    """log density of a new arm's angle ``phi`` under the add-arm proposal from ``S``.

    Mixture (Algorithm 1, 'add arm'): 1/2 uniform in the feasible part of the largest
    angular gap; 1/2 'split': an arm ``j ~ U(A)``, a side, and an offset
    ``U[min_sep, min_sep + split_span]`` from it.
    """
    n = int(S[2])
    ms = P[P_MIN_SEP]
    span = P[P_SPLIT_SPAN]
    if n == 0:
        return -LOG_TWO_PI
    dens = 0.0
    start, g = largest_gap(S)
    L = g - 2.0 * ms
    if L > 0.0:
        x = (phi - start - ms) % TWO_PI
        if x <= L:
            dens += 0.5 / L
    if span > 0.0:
        c = 0.25 / (n * span)
        for j in range(n):
            aj = S[HDR + j * STRIDE]
            dp = (phi - aj) % TWO_PI
            if ms <= dp <= ms + span:
                dens += c
            dn = (aj - phi) % TWO_PI
            if ms <= dn <= ms + span:
                dens += c
    if dens <= 0.0:
        return NEG_INF
    return math.log(dens)


@njit(cache=True)
def new_arm_logdensity(S2, k, logqn, P):
    """log density of arm ``k``'s parameters other than its angle under add-arm."""
    lq = logqn[int(S2[HDR + k * STRIDE + NIN])] + logqn[int(S2[HDR + k * STRIDE + NOUT])]
    lq += offset_logq(S2[HDR + k * STRIDE + OFF], P)
    lq += bend_logq(S2[HDR + k * STRIDE + BEND], P)
    lq -= math.log(P[P_GAP_MAX])
    if P[P_SAMPLE_W] > 0.0:
        lq -= math.log(P[P_W_MAX] - P[P_W_MIN])
    return lq


@njit(cache=True)
def _sample_discrete(cum):
    u = np.random.random() * cum[-1]
    for i in range(len(cum)):
        if u < cum[i]:
            return i
    return len(cum) - 1


@njit(cache=True)
def _pick_arm(S, P):
    """The arm a move changes: slot ``P_FOCUS`` with probability ``P_FOCUS_P`` (the
    descent's focus; 0: none), otherwise uniform. The choice does not depend on the
    state, so moves stay symmetric."""
    n = int(S[2])
    if P[P_FOCUS_P] > 0.0 and P[P_FOCUS] < n and np.random.random() < P[P_FOCUS_P]:
        return int(P[P_FOCUS])
    return int(np.random.random() * n)


@njit(cache=True)
def move_rotate(S, S2, P):
    """Rotate an arm (:func:`_pick_arm`) by U[-rot, rot] (symmetric)."""
    k = _pick_arm(S, P)
    i = HDR + k * STRIDE
    S2[i] = wrap(S[i] + (2.0 * np.random.random() - 1.0) * P[P_ROT] * _step(P))
    return separation_ok(S2, k, P[P_MIN_SEP]), 0.0, k


@njit(cache=True)
def move_shift(S, S2, P):
    """Shift the center by (dc, phi) ~ U([0, shift] x [0, 2pi]) (symmetric)."""
    r = np.random.random() * P[P_SHIFT] * _step(P)
    phi = np.random.random() * TWO_PI
    S2[0] = S[0] + r * math.cos(phi)
    S2[1] = S[1] + r * math.sin(phi)
    return True, 0.0, -1


@njit(cache=True)
def _perturb_arm(S, S2, P, field, step, lo, hi):
    """Change ``field`` of an arm (:func:`_pick_arm`) by U[-step, step] (symmetric); valid
    in [lo, hi]."""
    k = _pick_arm(S, P)
    i = HDR + k * STRIDE + field
    v = S[i] + (2.0 * np.random.random() - 1.0) * step * _step(P)
    S2[i] = v
    return lo <= v <= hi, 0.0, k


@njit(cache=True)
def move_gap(S, S2, P):
    """Change the median gap of a random arm (paper Algorithm 1)."""
    return _perturb_arm(S, S2, P, GAP, P[P_GAP_STEP], 0.0, P[P_GAP_MAX])


@njit(cache=True)
def move_width(S, S2, P):
    """Change the lane width of a random arm (beyond the paper)."""
    return _perturb_arm(S, S2, P, WID, P[P_W_STEP], P[P_W_MIN], P[P_W_MAX])


@njit(cache=True)
def move_offset(S, S2, P):
    """Change the axis offset of an arm (beyond the paper, :mod:`.arm_offset`)."""
    return _perturb_arm(S, S2, P, OFF, P[P_OFF_STEP], -P[P_OFF_MAX], P[P_OFF_MAX])


@njit(cache=True)
def move_bend(S, S2, P):
    """Change the bend angle or the bend's place of an arm (beyond the paper,
    :mod:`.arm_bend`)."""
    if np.random.random() < 0.5:
        return _perturb_arm(S, S2, P, BEND, P[P_BEND_STEP], -P[P_BEND_MAX], P[P_BEND_MAX])
    return _perturb_arm(S, S2, P, BENDAT, P[P_BEND_S_STEP], P[P_BEND_S_MIN], P[P_BEND_S_MAX])


@njit(cache=True)
def move_add_arm(S, S2, P, logqn, cumqn):
    """Add an arm (largest gap or next to an arm); reverse: remove that arm."""
    n = int(S[2])
    if n >= int(P[P_MAX_ARMS]) or n >= MAXA:
        return False, 0.0, -1
    ms = P[P_MIN_SEP]
    if np.random.random() < 0.5 or n == 0:
        start, g = largest_gap(S)
        L = g - 2.0 * ms if n > 0 else TWO_PI
        if L <= 0.0:
            return False, 0.0, -1
        phi = start + ms + np.random.random() * L if n > 0 else np.random.random() * TWO_PI
    else:
        if P[P_SPLIT_SPAN] <= 0.0:
            return False, 0.0, -1
        j = int(np.random.random() * n)
        side = 1.0 if np.random.random() < 0.5 else -1.0
        phi = S[HDR + j * STRIDE] + side * (ms + np.random.random() * P[P_SPLIT_SPAN])
    phi = wrap(phi)
    i = HDR + n * STRIDE
    S2[i + ANG] = phi
    S2[i + GAP] = np.random.random() * P[P_GAP_MAX]
    S2[i + NIN] = _sample_discrete(cumqn)
    S2[i + NOUT] = _sample_discrete(cumqn)
    if P[P_SAMPLE_W] > 0.0:
        S2[i + WID] = P[P_W_MIN] + np.random.random() * (P[P_W_MAX] - P[P_W_MIN])
    else:
        S2[i + WID] = P[P_W_DEFAULT]
    S2[i + OFF] = draw_offset(P)
    S2[i + BEND], S2[i + BENDAT] = draw_bend(P)
    S2[2] = n + 1
    if (not separation_ok(S2, n, ms) or not offset_ok(S2[i + OFF], P)
            or not bend_ok(S2[i + BEND], S2[i + BENDAT], P)):
        return False, 0.0, n
    lq_fwd = add_arm_angle_logdensity(S, phi, P) + new_arm_logdensity(S2, n, logqn, P)
    lq_rev = -math.log(n + 1.0)
    return True, lq_rev - lq_fwd, n


@njit(cache=True)
def move_remove_arm(S, S2, P, logqn):
    """Remove a random arm; reverse: add-arm proposing exactly that arm."""
    n = int(S[2])
    if n - 1 < int(P[P_MIN_ARMS]):
        return False, 0.0, -1
    k = int(np.random.random() * n)
    return remove_arm_at(S, S2, P, logqn, k)


@njit(cache=True)
def remove_arm_at(S, S2, P, logqn, k):
    """Remove arm ``k`` (slot ``n-1`` moves into ``k``) and give the log Hastings ratio."""
    n = int(S[2])
    ik = HDR + k * STRIDE
    il = HDR + (n - 1) * STRIDE
    phi = S[ik + ANG]
    lq_new = new_arm_logdensity(S, k, logqn, P)
    for q in range(STRIDE):
        S2[ik + q] = S[il + q]
    S2[2] = n - 1
    lq_rev = add_arm_angle_logdensity(S2, phi, P) + lq_new
    lq_fwd = -math.log(float(n))
    ok = lq_rev > NEG_INF
    return ok, lq_rev - lq_fwd, k


@njit(cache=True)
def move_lane(S, S2, P):
    """Add / remove an entering or leaving lane at the border, at the median, or by
    re-dividing the same road width.

    Border: lane count +-1, gap unchanged. Median: lane count +-1 and the gap shrinks /
    grows by one lane width (the new lane takes the median strip). Rescale (only when the
    lane width is sampled): lane count ``n -> n' = n +- 1`` and the arm's lane width
    ``w -> w n / n'``, so the road width of that direction stays -- 3 lanes of 3.0 m and 2
    of 4.5 m explain the same spread of traffic, and without this variant the chain has to
    cross a low-posterior valley (count first, width later) to switch between them. Each
    variant is its own reverse (remove <-> add) with the same selection probability; the
    ratio is 0 for border/median and the Jacobian ``log(n / n')`` of ``w' = w n / n'`` for
    rescale.
    """
    n = int(S[2])
    k = int(np.random.random() * n)
    entering = np.random.random() < 0.5
    add = np.random.random() < 0.5
    nvar = 3 if P[P_SAMPLE_W] > 0.0 else 2
    variant = int(np.random.random() * nvar)
    i = HDR + k * STRIDE
    j = i + (NIN if entering else NOUT)
    w = S[i + WID]
    S2[j] = S[j] + 1.0 if add else S[j] - 1.0
    if S2[j] > P[P_MAX_LANES] or S2[j] < P[P_MIN_LANES]:
        return False, 0.0, k
    if variant == 1:
        S2[i + GAP] = S[i + GAP] - w if add else S[i + GAP] + w
        if S2[i + GAP] < 0.0 or S2[i + GAP] > P[P_GAP_MAX]:
            return False, 0.0, k
    elif variant == 2:
        w2 = w * S[j] / S2[j]
        S2[i + WID] = w2
        if w2 < P[P_W_MIN] or w2 > P[P_W_MAX]:
            return False, 0.0, k
        return True, math.log(S[j] / S2[j]), k
    return True, 0.0, k


@njit(cache=True)
def propose(S, S2, P, logqn, cumqn):
    """Algorithm 1: pick a move by omega ~ U[0,1] and apply it to a copy ``S2`` of ``S``.

    Returns (valid, log Hastings ratio, move kind, changed arm slot or -1).
    """
    S2[:] = S
    w = np.random.random()
    if w < P[P_C_ROT]:
        ok, lq, k = move_rotate(S, S2, P)
        return ok, lq, ROTATE, k
    if w < P[P_C_SHIFT]:
        ok, lq, k = move_shift(S, S2, P)
        return ok, lq, SHIFT, k
    if w < P[P_C_GAP]:
        ok, lq, k = move_gap(S, S2, P)
        return ok, lq, CHANGE_GAP, k
    if w < P[P_C_ARM]:
        if np.random.random() < 0.5:
            ok, lq, k = move_add_arm(S, S2, P, logqn, cumqn)
            return ok, lq, ADD_ARM, k
        ok, lq, k = move_remove_arm(S, S2, P, logqn)
        return ok, lq, REMOVE_ARM, k
    if w < P[P_C_LANE]:
        ok, lq, k = move_lane(S, S2, P)
        return ok, lq, LANE, k
    if w < P[P_C_WIDTH]:
        ok, lq, k = move_width(S, S2, P)
        return ok, lq, WIDTH, k
    if w < P[P_C_OFFSET]:
        ok, lq, k = move_offset(S, S2, P)
        return ok, lq, OFFSET, k
    ok, lq, k = move_bend(S, S2, P)
    return ok, lq, BEND_MOVE, k
