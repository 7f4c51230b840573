"""Compiled (numba) kernels of the topology MCMC (paper §II-B/C, Algorithm 1).

All compiled code lives in this one module so that numba's on-disk cache (``cache=True``)
is invalidated whenever any kernel changes (numba keys the cache on the defining file
only). The Python modules :mod:`moves`, :mod:`prior`, :mod:`likelihood` and
:mod:`anneal` document the maths and wrap these kernels.

State ``S`` (float64 vector, cheap to copy): ``S[0:2]`` center ``c``, ``S[2]`` number of
arms ``|A|``, then ``STRIDE`` values per arm slot ``k`` starting at ``HDR + k*STRIDE``:
angle, gap, lanes_in, lanes_out, lane_width. Slots ``>= |A|`` are unused. Arms are an
unordered set; the slot order carries no meaning.

Parameter vector ``P``: see the ``P_*`` indices (filled by ``topology.TopologyConfig``).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

MAXA = 8
HDR = 3
STRIDE = 5
ANG, GAP, NIN, NOUT, WID = 0, 1, 2, 3, 4
STATE_LEN = HDR + STRIDE * MAXA

(P_MIN_SEP, P_MIN_ARMS, P_MAX_ARMS, P_MIN_LANES, P_MAX_LANES, P_GAP_MAX, P_W_MIN, P_W_MAX,
 P_ROT, P_SHIFT, P_GAP_STEP, P_W_STEP, P_SPLIT_SPAN,
 P_C_ROT, P_C_SHIFT, P_C_GAP, P_C_ARM, P_C_LANE,
 P_FLOOR, P_TRAFFIC, P_D2_CUT, P_SAMPLE_W, P_W_DEFAULT,
 P_LANE_NORM, P_FINE_P, P_FINE_SCALE, P_LANE_SUM, P_FOCUS, P_FOCUS_P) = range(29)
NPARAM = 29

ROTATE, SHIFT, CHANGE_GAP, ADD_ARM, REMOVE_ARM, LANE, WIDTH = range(7)
MOVE_NAMES = ('rotate', 'shift', 'gap', 'add_arm', 'remove_arm', 'lane', 'width')

TWO_PI = 2.0 * math.pi
LOG_TWO_PI = math.log(TWO_PI)
NEG_INF = -np.inf


@njit(cache=True)
def wrap(a):
    """Wrap to ``[-pi, pi)``."""
    return (a + math.pi) % TWO_PI - math.pi


@njit(cache=True)
def seed_rng(seed):
    """Seed numba's internal RNG (one per thread) from a numpy-Generator draw."""
    np.random.seed(seed)


# ----------------------------------------------------------------------------- geometry

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


# ----------------------------------------------------------------------------- moves

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
    """The arm a move changes: slot ``P_FOCUS`` with probability ``P_FOCUS_P`` (when >= 0),
    otherwise uniform. The choice does not depend on the state, so moves stay symmetric."""
    n = int(S[2])
    if P[P_FOCUS] >= 0.0 and P[P_FOCUS] < n and np.random.random() < P[P_FOCUS_P]:
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
    S2[2] = n + 1
    if not separation_ok(S2, n, ms):
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
    ok, lq, k = move_width(S, S2, P)
    return ok, lq, WIDTH, k


@njit(cache=True)
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
    else:
        ok, lq, k = move_width(S, S2, P)
    return ok, lq, k


# ----------------------------------------------------------------------------- prior

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


# ----------------------------------------------------------------------------- likelihood

@njit(cache=True, fastmath=True, inline='always')
def arm_frame(i, cx, cy, ux, uy, ts, ox, oy, hx, hy, has_o, dcls, isa):
    """Observation ``i`` relative to an arm through (cx, cy) with direction (ux, uy):
    along-arm ``s``, lateral ``t``, direction ``d`` (+1 entering) and angle energy ``e``.
    With an orientation the direction is arm-local (entering iff <o, u_a> < 0) and
    ``e = 2(1 - |cos|) / sigma^2`` (von Mises ~ angle^2); without, the Doppler class, and
    for an unknown class (0) the side of the median decides."""
    px = ox[i] - cx
    py = oy[i] - cy
    s = px * ux + py * uy
    t = py * ux - px * uy
    e = 0.0
    if has_o[i]:
        c = hx[i] * ux + hy[i] * uy
        d = 1.0 if c < 0.0 else -1.0
        e = isa[i] * 2.0 * (1.0 - abs(c))
    else:
        d = dcls[i]
        if d == 0.0:
            d = 1.0 if t * ts > 0.0 else -1.0
    return s, t, d, e


@njit(cache=True, fastmath=True, inline='always')
def _arm_geometry(S, k, P):
    """Arm ``k`` of state ``S`` for the likelihood: center, unit direction, half gap, lane
    counts and width, traffic side, lane-count normalisations (entering, leaving)."""
    i0 = HDR + k * STRIDE
    a = S[i0 + ANG]
    nin = S[i0 + NIN]
    nout = S[i0 + NOUT]
    return (S[0], S[1], math.cos(a), math.sin(a), 0.5 * S[i0 + GAP], nin, nout, S[i0 + WID],
            P[P_TRAFFIC], nin ** -P[P_LANE_NORM], nout ** -P[P_LANE_NORM])


@njit(cache=True, fastmath=True)
def arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, out):
    """Unnormalised density of every observation under its best lane of arm ``k``.

    Paper eq. for P(z_i|I): closest lane with the same driving direction, Gaussian in the
    orthogonal distance (or, with ``P_LANE_SUM``, the sum over the lanes of that direction:
    the mixture of paper eq. for P(z_i|I)) and (with orientation) von Mises in the angle (``2(1 - cos)`` in
    place of the squared angle: the circular normal, no ``acos``), divided by (number of
    lanes of that direction) ** ``P_LANE_NORM``. Lanes are rays from the
    center; behind the ray start the Euclidean distance to the start is used. With an
    orientation the direction is arm-local (entering iff <o, u_a> < 0).
    """
    if P[P_LANE_SUM] > 0.0:
        _arm_column_sum(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, out)
        return
    cx, cy, ux, uy, hg, nin, nout, w, ts, inv_n_in, inv_n_out = _arm_geometry(S, k, P)
    n = ox.shape[0]
    energy = np.empty(n)
    # pass 1, branch-free (vectorises): energy of the closest lane and the lane-count
    # normalisation; pass 2: the exponential only below the cut
    for i in range(n):
        px = ox[i] - cx
        py = oy[i] - cy
        s = px * ux + py * uy
        t = py * ux - px * uy
        c = hx[i] * ux + hy[i] * uy
        side = 1.0 if t * ts > 0.0 else -1.0
        dd = dcls[i] if dcls[i] != 0.0 else side
        d = (1.0 if c < 0.0 else -1.0) if has_o[i] else dd
        e = isa[i] * 2.0 * (1.0 - abs(c)) if has_o[i] else 0.0
        nl = nin if d > 0.0 else nout
        q = d * ts * t - hg
        dl = q - (min(max(math.floor(q / w), 0.0), nl - 1.0) + 0.5) * w
        sb = min(s, 0.0)
        energy[i] = e + isp[i] * (sb * sb + dl * dl)
        out[i] = inv_n_in if d > 0.0 else inv_n_out
    cut = P[P_D2_CUT]
    for i in range(n):
        out[i] = out[i] * math.exp(-energy[i]) if energy[i] < cut else 0.0


@njit(cache=True, fastmath=True)
def _arm_column_sum(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, out):
    """:func:`arm_column` with the sum over the lanes of that direction (``P_LANE_SUM``)."""
    cx, cy, ux, uy, hg, nin, nout, w, ts, inv_n_in, inv_n_out = _arm_geometry(S, k, P)
    cut = P[P_D2_CUT]
    for i in range(ox.shape[0]):
        s, t, d, e = arm_frame(i, cx, cy, ux, uy, ts, ox, oy, hx, hy, has_o, dcls, isa)
        if e >= cut:
            out[i] = 0.0
            continue
        nl = nin if d > 0.0 else nout
        q = d * ts * t - hg
        kk = math.floor(q / w)
        if kk < 0.0:
            kk = 0.0
        elif kk > nl - 1.0:
            kk = nl - 1.0
        dl = q - (kk + 0.5) * w
        e0 = e + (isp[i] * s * s if s < 0.0 else 0.0)
        e = e0 + isp[i] * dl * dl
        if e >= cut:
            out[i] = 0.0
            continue
        v = 0.0
        for j in range(int(nl)):
            dj = q - (j + 0.5) * w
            ej = e0 + isp[i] * dj * dj
            if ej < cut:
                v += math.exp(-ej)
        out[i] = v * (inv_n_in if d > 0.0 else inv_n_out)


@njit(cache=True, fastmath=True)
def all_columns(S, P, ox, oy, hx, hy, has_o, dcls, isp, isa, C):
    for k in range(int(S[2])):
        arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, C[k])


@njit(cache=True)
def combine(C, n, skip, newcol, use_new, wts, floor):
    """sum_i w_i log(max_arms density_i + floor): the clutter floor is a uniform mixture."""
    ll = 0.0
    for i in range(wts.shape[0]):
        m = newcol[i] if use_new else 0.0
        for j in range(n):
            if j != skip and C[j, i] > m:
                m = C[j, i]
        ll += wts[i] * math.log(m + floor)
    return ll


@njit(cache=True)
def full_loglik(S, P, ox, oy, hx, hy, has_o, dcls, isp, isa, wts, C):
    all_columns(S, P, ox, oy, hx, hy, has_o, dcls, isp, isa, C)
    return combine(C, int(S[2]), -1, C[0], False, wts, P[P_FLOOR])


# ----------------------------------------------------------------------------- annealing

@njit(cache=True, fastmath=True)
def observation_maxima(C, n, wts, floor, M, AM, Lg):
    """Per observation: best density over arms ``M``, its arm ``AM`` (-1: none) and the
    log-likelihood term ``Lg = w log(M + floor)``; returns their sum."""
    ll = 0.0
    for i in range(wts.shape[0]):
        m = 0.0
        am = -1
        for j in range(n):
            if C[j, i] > m:
                m = C[j, i]
                am = j
        M[i] = m
        AM[i] = am
        Lg[i] = wts[i] * math.log(m + floor)
        ll += Lg[i]
    return ll


@njit(cache=True, fastmath=True)
def rescore_arm(C, n, k, col, has_col, wts, floor, M, AM, Lg, idx, nM, nAM, nLg):
    """Log-likelihood change when arm slot ``k`` gets column ``col`` (``has_col``) or is
    removed (not ``has_col``). Only observations whose best arm could change are
    re-scored: those whose best arm is ``k``, or that ``col`` explains better than their
    current best. Changed rows go to ``idx[:count]`` with new values in ``nM, nAM, nLg``.
    Returns (delta, count).
    """
    delta = 0.0
    cnt = 0
    for i in range(wts.shape[0]):
        c = col[i] if has_col else 0.0
        if AM[i] == k:
            m = c
            am = k if has_col and c > 0.0 else -1
            for j in range(n):
                if j != k and C[j, i] > m:
                    m = C[j, i]
                    am = j
        elif c > M[i]:
            m = c
            am = k
        else:
            continue
        if m == M[i] and am == AM[i]:
            continue
        lg = wts[i] * math.log(m + floor)
        idx[cnt] = i
        nM[cnt] = m
        nAM[cnt] = am
        nLg[cnt] = lg
        delta += lg - Lg[i]
        cnt += 1
    return delta, cnt


@njit(cache=True, nogil=True)   # inputs are served meanwhile (node.py)
def run_chain(S, C, ll, lp, best_S, best_lpost, P, logPA, logPn, arm_const, logqn, cumqn,
              ox, oy, hx, hy, has_o, dcls, isp, isa, wts, n_steps, temps, seed, stats):
    """Metropolis-Hastings with simulated annealing (paper §II, Algorithm 1).

    Mutates ``S`` (chain state), ``C`` (per-arm density columns of ``S``) and
    ``best_S``; ``temps[t]`` is the temperature of step ``t``. The likelihood is
    incremental: a move of one arm recomputes only that arm's column and re-scores only
    the observations whose best arm could change (see :func:`rescore_arm`); a center
    shift recomputes everything. ``stats[kind*2]`` counts proposals, ``stats[kind*2+1]``
    acceptances. Returns (ll, lp, best_lpost); ``ll`` is re-summed exactly at the end.
    """
    np.random.seed(seed)
    S2 = np.empty_like(S)
    nobs = ox.shape[0]
    floor = P[P_FLOOR]
    col = np.empty(nobs)
    C2 = np.empty_like(C)
    M = np.empty(nobs)
    AM = np.empty(nobs, np.int64)
    Lg = np.empty(nobs)
    M2 = np.empty(nobs)
    AM2 = np.empty(nobs, np.int64)
    Lg2 = np.empty(nobs)
    idx = np.empty(nobs, np.int64)
    nM = np.empty(nobs)
    nAM = np.empty(nobs, np.int64)
    nLg = np.empty(nobs)
    ll = observation_maxima(C, int(S[2]), wts, floor, M, AM, Lg)
    for step in range(n_steps):
        ok, lq, kind, k = propose(S, S2, P, logqn, cumqn)
        stats[2 * kind] += 1
        if not ok:
            continue
        n2 = int(S2[2])
        n = int(S[2])
        cnt = 0
        if kind == SHIFT:
            all_columns(S2, P, ox, oy, hx, hy, has_o, dcls, isp, isa, C2)
            ll2 = observation_maxima(C2, n2, wts, floor, M2, AM2, Lg2)
        elif kind == REMOVE_ARM:
            d, cnt = rescore_arm(C, n, k, col, False, wts, floor, M, AM, Lg, idx, nM, nAM, nLg)
            ll2 = ll + d
        else:
            arm_column(S2, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, col)
            d, cnt = rescore_arm(C, n2, k, col, True, wts, floor, M, AM, Lg, idx, nM, nAM, nLg)
            ll2 = ll + d
        lp2 = log_prior(S2, logPA, logPn, arm_const)
        a = (ll2 + lp2 - ll - lp) / temps[step] + lq
        if a < 0.0 and math.log(np.random.random()) >= a:
            continue
        stats[2 * kind + 1] += 1
        if kind == SHIFT:
            for j in range(n2):
                C[j, :] = C2[j, :]
            M[:] = M2
            AM[:] = AM2
            Lg[:] = Lg2
        else:
            for q in range(cnt):
                i = idx[q]
                M[i] = nM[q]
                AM[i] = nAM[q]
                Lg[i] = nLg[q]
            if kind == REMOVE_ARM:
                if k != n - 1:
                    C[k, :] = C[n - 1, :]
                    for i in range(nobs):
                        if AM[i] == n - 1:
                            AM[i] = k
            else:
                C[k, :] = col
        S[:] = S2
        ll = ll2
        lp = lp2
        if ll + lp > best_lpost:
            best_lpost = ll + lp
            best_S[:] = S
    ll = 0.0
    for i in range(nobs):
        ll += Lg[i]
    return ll, lp, best_lpost


# ----------------------------------------------------------------------------- arm refit

#: Knots per unit of the table of F(x) = log(exp(-x) + floor) that :func:`refit_arm`
#: interpolates (cubic Hermite: |error| < 1e-9, no exp / log in its inner loop).
LOG_FLOOR_INV_STEP = 32.0


@functools.lru_cache(maxsize=16)
def log_floor_table(floor: float, xmax: float) -> np.ndarray:
    """Cubic pieces (rows: knot j, columns: coefficients of u^0..u^3, u in [0, 1)) of
    F(x) = log(exp(-x) + floor) on [0, xmax]: the log-density of an observation at
    energy x plus the clutter floor."""
    h = 1.0 / LOG_FLOOR_INV_STEP
    x = np.arange(int(math.ceil(xmax / h)) + 3) * h
    ex = np.exp(-x)
    f = np.log(ex + floor)
    d = -ex / (ex + floor) * h
    f0, f1, d0, d1 = f[:-1], f[1:], d[:-1], d[1:]
    T = np.stack([f0, d0, 3.0 * (f1 - f0) - 2.0 * d0 - d1, 2.0 * (f0 - f1) + d0 + d1], axis=1)
    T.setflags(write=False)
    return T


#: fastmath without 'nnan' / 'ninf': refit_arm compares with infinite sentinels.
FAST_FINITE = {'nsz', 'arcp', 'contract', 'afn', 'reassoc'}


@njit(cache=True, nogil=True, fastmath=FAST_FINITE)
def refit_arm(S, k, P, logPn, ox, oy, hx, hy, has_o, dcls, isp, isa, wts, C, gaps, widths, FT,
              fixed_counts=False):
    """Best (gap, width, lanes_in, lanes_out) of arm ``k`` with center and angles fixed
    (with ``fixed_counts``: best gap and width for the lane counts in ``S``).

    Deterministic coordinate ascent on the posterior (initialisation aid, beyond the
    paper): candidates are the grids ``gaps`` x ``widths`` plus the current values; for
    each, the lane counts per direction are chosen independently (the likelihood of
    entering and leaving observations separates given the other arms' columns). Writes
    the best into ``S`` and arm ``k``'s column into ``C``; returns the posterior gain,
    never negative: the choice is scored exactly and kept only if it is no worse. The
    search reads log-densities from ``FT`` (:func:`log_floor_table`), the closest lane
    only; the sum over lanes (``P_LANE_SUM``) takes exact logarithms.
    """
    n = int(S[2])
    nobs = ox.shape[0]
    i0 = HDR + k * STRIDE
    a = S[i0 + ANG]
    ux = math.cos(a)
    uy = math.sin(a)
    cut = P[P_D2_CUT]
    ts = P[P_TRAFFIC]
    beta = P[P_LANE_NORM]
    lane_sum = P[P_LANE_SUM] > 0.0
    floor = P[P_FLOOR]
    lo = int(P[P_MIN_LANES])
    hi = int(P[P_MAX_LANES])
    if FT.shape[0] < (cut + beta * math.log(hi)) * LOG_FLOOR_INV_STEP + 1.0:
        raise ValueError('refit_arm: log_floor_table too short for P_D2_CUT / lanes')
    tl = np.empty(nobs)
    base = np.empty(nobs)
    dd = np.empty(nobs)
    other = np.zeros(nobs)
    for i in range(nobs):
        s, t, d, e = arm_frame(i, S[0], S[1], ux, uy, ts, ox, oy, hx, hy, has_o, dcls, isa)
        dd[i] = d
        tl[i] = d * ts * t
        base[i] = e + (isp[i] * s * s if s < 0.0 else 0.0)
        m = 0.0
        for j in range(n):
            if j != k and C[j, i] > m:
                m = C[j, i]
        other[i] = m
    # observations this arm can explain at all (others add a constant to every candidate),
    # packed per driving direction (side 0 entering) in R[side, :, :nrel[side]]: lateral
    # offset, base energy, 1/(2 sigma^2), weight, the other arms' best density o,
    # log(o + floor), the energy cut (beyond it this arm cannot beat o: the closest
    # lane's density exp(-e) / n**beta <= exp(-e)) and -log(o)
    reach = 0.5 * P[P_GAP_MAX] + P[P_MAX_LANES] * P[P_W_MAX]
    R = np.empty((2, 8, nobs))
    nrel = np.zeros(2, np.int64)
    for i in range(nobs):
        ci = cut
        if other[i] > 0.0 and not lane_sum:
            ci = min(cut, -math.log(other[i]))
        if base[i] < ci and abs(tl[i]) < reach + math.sqrt(ci / isp[i]):
            side = 0 if dd[i] > 0.0 else 1
            r = nrel[side]
            R[side, 0, r] = tl[i]
            R[side, 1, r] = base[i]
            R[side, 2, r] = isp[i]
            R[side, 3, r] = wts[i]
            R[side, 4, r] = other[i]
            R[side, 5, r] = math.log(other[i] + floor)
            R[side, 6, r] = ci
            R[side, 7, r] = -math.log(other[i]) if other[i] > 0.0 else np.inf
            nrel[side] += 1
    acc = np.empty(hi + 1)
    invn = np.empty(hi + 1)
    blog = np.empty(hi + 1)
    for nl in range(1, hi + 1):
        invn[nl] = float(nl) ** -beta
        blog[nl] = beta * math.log(float(nl))
    ng = gaps.shape[0] + 1
    nw = widths.shape[0] + 1
    best = -np.inf
    bg = S[i0 + GAP]
    bw = S[i0 + WID]
    bi = S[i0 + NIN]
    bo = S[i0 + NOUT]
    ni = lo
    no = lo
    for gi in range(ng):
        g = gaps[gi] if gi < ng - 1 else S[i0 + GAP]
        for wi in range(nw):
            w = widths[wi] if wi < nw - 1 else S[i0 + WID]
            tot = 0.0
            for side in range(2):
                sbest = -np.inf
                sn = lo
                n_lo = lo
                n_hi = hi
                if fixed_counts:
                    n_lo = int(S[i0 + NIN]) if side == 0 else int(S[i0 + NOUT])
                    n_hi = n_lo
                for nl in range(n_lo, n_hi + 1):
                    acc[nl] = logPn[nl]
                Rt = R[side, 0]
                Rb = R[side, 1]
                Ri = R[side, 2]
                Rw = R[side, 3]
                Ro = R[side, 4]
                Rl = R[side, 5]
                Rc = R[side, 6]
                Rx = R[side, 7]
                for r in range(nrel[side]):
                    # log-density relative to "no lane of this arm explains it" (the same
                    # for every candidate, so left out): 0 unless this arm beats the others
                    q = Rt[r] - 0.5 * g
                    kf = math.floor(q / w)
                    if kf < 0.0:
                        kf = 0.0
                    if not lane_sum:
                        # closest lane: kf while it exists, else the outermost one, whose
                        # distance grows as lanes are taken away -- count down and stop at
                        # the first lane count that leaves it beyond the cut
                        last = -1.0
                        for nl in range(n_hi, n_lo - 1, -1):
                            kk = kf if kf < nl - 1.0 else nl - 1.0
                            if kk != last:
                                last = kk
                                dl = q - (kk + 0.5) * w
                                e = Rb[r] + Ri[r] * dl * dl
                                if e >= Rc[r]:
                                    break
                            # density exp(-x), x = e + beta log(nl): beats o iff x < -log(o);
                            # its log-density log(exp(-x) + floor) from the table
                            x = e + blog[nl]
                            if x < Rx[r]:
                                tj = x * LOG_FLOOR_INV_STEP
                                j = int(tj)
                                u = tj - j
                                f = FT[j, 0] + u * (FT[j, 1] + u * (FT[j, 2] + u * FT[j, 3]))
                                acc[nl] += Rw[r] * (f - Rl[r])
                        continue
                    # sum over lanes 0..nl-1 (the closest must be within the cut)
                    cs = 0.0
                    for nl in range(n_lo, n_hi + 1):
                        for jl in range(0 if nl == n_lo else nl - 1, nl):   # the new lanes
                            dj = q - (jl + 0.5) * w
                            ej = Rb[r] + Ri[r] * dj * dj
                            if ej < cut:
                                cs += math.exp(-ej)
                        kk = kf if kf < nl - 1.0 else nl - 1.0
                        dl = q - (kk + 0.5) * w
                        if Rb[r] + Ri[r] * dl * dl >= cut:
                            continue
                        v = cs * invn[nl]
                        if v > Ro[r]:
                            acc[nl] += Rw[r] * (math.log(v + floor) - Rl[r])
                for nl in range(n_lo, n_hi + 1):
                    if acc[nl] > sbest:
                        sbest = acc[nl]
                        sn = nl
                tot += sbest
                if side == 0:
                    ni = sn
                else:
                    no = sn
            if tot > best:
                best = tot
                bg = g
                bw = w
                bi = ni
                bo = no
    # posterior of the current arm parameters, for the gain
    old = np.empty(STRIDE)
    for q in range(STRIDE):
        old[q] = S[i0 + q]
    col = np.empty(nobs)
    arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, col)
    cur = combine(C, n, k, col, True, wts, floor) + logPn[int(old[NIN])] + logPn[int(old[NOUT])]
    S[i0 + GAP] = bg
    S[i0 + WID] = bw
    S[i0 + NIN] = bi
    S[i0 + NOUT] = bo
    arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, col)
    new = combine(C, n, k, col, True, wts, floor) + logPn[int(bi)] + logPn[int(bo)]
    if new < cur:
        for q in range(STRIDE):
            S[i0 + q] = old[q]
        arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, col)
        new = cur
    C[k, :] = col
    return new - cur


# ----------------------------------------------------------------------------- preprocessing

@njit(cache=True)
def local_pca(x, y, w, radius):
    """Per point: principal direction (angle) and anisotropy of its weighted neighbourhood.

    Anisotropy ``(l1 - l2) / (l1 + l2)`` is ~1 along a single road and small where roads
    cross (the intersection box) or in isolated clutter.
    """
    n = x.shape[0]
    theta = np.zeros(n)
    aniso = np.zeros(n)
    order = np.argsort(x)
    xs = x[order]
    r2 = radius * radius
    for a in range(n):
        i = order[a]
        sw = 0.0
        mx = 0.0
        my = 0.0
        sxx = 0.0
        syy = 0.0
        sxy = 0.0
        lo = np.searchsorted(xs, x[i] - radius)
        hi = np.searchsorted(xs, x[i] + radius, side='right')
        for b in range(lo, hi):
            j = order[b]
            dx = x[j] - x[i]
            dy = y[j] - y[i]
            if dx * dx + dy * dy <= r2:
                sw += w[j]
                mx += w[j] * dx
                my += w[j] * dy
                sxx += w[j] * dx * dx
                syy += w[j] * dy * dy
                sxy += w[j] * dx * dy
        mx /= sw
        my /= sw
        cxx = sxx / sw - mx * mx
        cyy = syy / sw - my * my
        cxy = sxy / sw - mx * my
        tr = cxx + cyy
        theta[i] = 0.5 * math.atan2(2.0 * cxy, cxx - cyy)
        aniso[i] = math.sqrt((cxx - cyy) ** 2 + 4.0 * cxy * cxy) / tr if tr > 1e-12 else 0.0
    return theta, aniso


@njit(cache=True)
def split_tracks(x, y, h, starts, ends, cx, cy, min_pts, min_len, tol, win):
    """Paper §II-A for tracked objects: split each trajectory at its point closest to the
    center ``(cx, cy)`` and reduce each part to its mean point and mean direction.

    Rows are sorted by (track, time); ``h`` is the heading per row. With ``tol > 0`` a part
    is first cut to its straight run from the far end (moving average of ``win`` heading
    deviations from the far-end direction below ``tol``): the turn inside the intersection
    box would bias the mean point and direction. Returns (mx, my, vx, vy) per kept part.
    """
    nt = starts.shape[0]
    out = np.empty((2 * nt, 4))
    m = 0
    for t in range(nt):
        a = starts[t]
        b = ends[t]
        best = np.inf
        imin = a
        for i in range(a, b):
            d = (x[i] - cx) ** 2 + (y[i] - cy) ** 2
            if d < best:
                best = d
                imin = i
        for part in range(2):
            lo = a if part == 0 else imin
            hi = imin + 1 if part == 0 else b
            n = hi - lo
            if n < min_pts:
                continue
            x0 = x[lo]
            x1 = x[lo]
            y0 = y[lo]
            y1 = y[lo]
            for i in range(lo, hi):
                x0 = min(x0, x[i])
                x1 = max(x1, x[i])
                y0 = min(y0, y[i])
                y1 = max(y1, y[i])
            if math.hypot(x1 - x0, y1 - y0) < min_len:
                continue
            # far end first: entering part (0) starts far, leaving part (1) ends far
            step = 1 if part == 0 else -1
            first = lo if part == 0 else hi - 1
            keep = n
            if tol > 0.0:
                k = max(3, n // 5)
                sx = 0.0
                sy = 0.0
                for q in range(k):
                    sx += math.cos(h[first + step * q])
                    sy += math.sin(h[first + step * q])
                ref = math.atan2(sy, sx)
                dev = np.empty(n)
                for q in range(n):
                    dev[q] = abs(wrap(h[first + step * q] - ref))
                half = win // 2
                keep = n
                for q in range(n):
                    acc = 0.0
                    for r in range(q - half, q - half + win):
                        if 0 <= r < n:
                            acc += dev[r]
                    if acc / win > tol:
                        keep = q
                        break
                keep = max(keep, min(n, 3))
            mx = 0.0
            my = 0.0
            vx = 0.0
            vy = 0.0
            for q in range(keep):
                i = first + step * q
                mx += x[i]
                my += y[i]
                vx += math.cos(h[i])
                vy += math.sin(h[i])
            out[m, 0] = mx / keep
            out[m, 1] = my / keep
            out[m, 2] = vx
            out[m, 3] = vy
            m += 1
    return out[:m]


#: Largest box of voxel cells counted in a dense table (:func:`_group_codes`); larger
#: extents (far-flung rows) fall back to sorting.
DENSE_CELLS = 1 << 22


@njit(cache=True, nogil=True)
def _group_codes(code, cells):
    """Each row's group index, groups numbered in increasing ``code`` (cell codes in
    [0, cells)), and the group count: within ``DENSE_CELLS`` counted in a dense table (no
    sort), otherwise by sorting the codes."""
    n = code.shape[0]
    slot = np.empty(n, np.int64)
    if cells <= DENSE_CELLS:
        rank = np.full(cells, -1, np.int64)
        for i in range(n):
            rank[code[i]] = 0
        m = 0
        for c in range(cells):
            if rank[c] == 0:
                rank[c] = m
                m += 1
        for i in range(n):
            slot[i] = rank[code[i]]
        return slot, m
    o = np.argsort(code)
    m = -1
    for q in range(n):
        if m < 0 or code[o[q]] != code[o[q - 1]]:
            m += 1
        slot[o[q]] = m
    return slot, m + 1


@njit(cache=True, nogil=True)
def grid_voxel_index(x, y, cls, size):
    """Square voxels (edge ``size``) per class: each row's voxel index, voxels numbered in
    the order of (x bin, y bin, class) -- the sorted unique keys of ``preprocess.voxelise``
    -- and the voxel count. Counted in a dense table within a small extent, else sorted."""
    n = x.shape[0]
    if n == 0:
        return np.empty(0, np.int64), 0
    ib = np.empty(n, np.int64)
    jb = np.empty(n, np.int64)
    for r in range(n):
        ib[r] = np.int64(math.floor(x[r] / size))
        jb[r] = np.int64(math.floor(y[r] / size))
    i0, j0, nc = ib.min(), jb.min(), cls.max() + 1
    nj = jb.max() - j0 + 1
    code = np.empty(n, np.int64)
    for r in range(n):
        code[r] = ((ib[r] - i0) * nj + jb[r] - j0) * nc + cls[r]
    return _group_codes(code, (ib.max() - i0 + 1) * nj * nc)


@njit(cache=True, nogil=True, inline='always')
def _ridge_solve2(a11, a12, a22, b1, b2, px, py):
    """(A + lam I) x = b + lam p for the symmetric 2x2 ``A``, lam = 1e-3 trace(A) (at
    least 1e-12): the least-squares point, pulled toward ``p`` where A is degenerate."""
    lam = 1e-3 * max(a11 + a22, 1e-9)
    a11 += lam
    a22 += lam
    b1 += lam * px
    b2 += lam * py
    det = a11 * a22 - a12 * a12
    return (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det


@njit(cache=True, nogil=True)
def irls_center(px, py, nx, ny, w, c0x, c0y, scale, iters):
    """Robust meeting point of the lines <n_i, x> = <n_i, p_i> (IRLS, Cauchy loss of scale
    ``scale``, ridge 1e-3 x trace toward (c0x, c0y)); see ``preprocess.initial_center``."""
    n = px.shape[0]
    d = np.empty(n)
    for i in range(n):
        d[i] = nx[i] * px[i] + ny[i] * py[i]
    cx = c0x
    cy = c0y
    for _ in range(iters):
        mxx = 0.0
        mxy = 0.0
        myy = 0.0
        bx = 0.0
        by = 0.0
        for i in range(n):
            rr = (nx[i] * cx + ny[i] * cy - d[i]) / scale
            wi = w[i] / (1.0 + rr * rr)
            mxx += wi * nx[i] * nx[i]
            mxy += wi * nx[i] * ny[i]
            myy += wi * ny[i] * ny[i]
            bx += wi * d[i] * nx[i]
            by += wi * d[i] * ny[i]
        nx_, ny_ = _ridge_solve2(mxx, mxy, myy, bx, by, c0x, c0y)
        done = math.hypot(nx_ - cx, ny_ - cy) < 1e-3
        cx = nx_
        cy = ny_
        if done:
            break
    return cx, cy


@njit(cache=True, nogil=True)
def _robust_range(x, w, tail):
    """Weighted (tail, 1 - tail) quantiles of ``x``: ignores light outliers at either end."""
    o = np.argsort(x)
    cw = np.cumsum(w[o])
    lo = min(np.searchsorted(cw, tail * cw[-1], side='right'), x.shape[0] - 1)
    hi = min(np.searchsorted(cw, (1.0 - tail) * cw[-1], side='left'), x.shape[0] - 1)
    return x[o[lo]], x[o[hi]]


@njit(cache=True, nogil=True)
def lane_guess(x, y, hx, hy, has_o, dcls, w, cx, cy, angles, lane_width, max_lanes, gap_max,
               ts, iters, wmin, wmax, fit_width):
    """Center from the arms' median axes and per arm (gap, lanes in, lanes out, width) from
    the lateral spread of its observations (``preprocess.initial_lanes``).

    Returns (cx, cy, params) with one row (gap, lanes in, lanes out, width) per angle."""
    n = x.shape[0]
    na = angles.shape[0]
    ux = np.cos(angles)
    uy = np.sin(angles)
    cos20 = math.cos(math.radians(20.0))
    P = np.empty((na, 4))
    arm = np.empty(n, np.int64)
    tt = np.empty(n)
    ent = np.empty(n, np.bool_)
    for _ in range(iters):
        for k in range(na):
            P[k, 0] = 0.0
            P[k, 1] = 1.0
            P[k, 2] = 1.0
            P[k, 3] = lane_width
        for i in range(n):   # the arm whose axis the observation runs along (smallest |t|)
            px = x[i] - cx
            py = y[i] - cy
            arm[i] = -1
            best = np.inf
            for k in range(na):
                sk = px * ux[k] + py * uy[k]
                tk = py * ux[k] - px * uy[k]
                ok = sk > 8.0 and abs(tk) < 25.0
                if ok and has_o[i]:
                    ok = abs(hx[i] * ux[k] + hy[i] * uy[k]) > cos20
                if ok and abs(tk) < best:
                    best = abs(tk)
                    arm[i] = k
                    tt[i] = tk
            if arm[i] >= 0:   # entering: heading against the arm, else the Doppler class
                k = arm[i]
                ent[i] = (hx[i] * ux[k] + hy[i] * uy[k] < 0.0) if has_o[i] else dcls[i] > 0.0
        a11 = 0.0
        a12 = 0.0
        a22 = 0.0
        b1 = 0.0
        b2 = 0.0
        for k in range(na):
            ni_ = 0
            no_ = 0
            for i in range(n):
                if arm[i] == k:
                    if ent[i]:
                        ni_ += 1
                    else:
                        no_ += 1
            if ni_ == 0 or no_ == 0:
                continue
            ti = np.empty(ni_)
            wi = np.empty(ni_)
            to = np.empty(no_)
            wo = np.empty(no_)
            ni_ = 0
            no_ = 0
            for i in range(n):
                if arm[i] == k:
                    if ent[i]:
                        ti[ni_] = tt[i] * ts
                        wi[ni_] = w[i]
                        ni_ += 1
                    else:
                        to[no_] = -tt[i] * ts
                        wo[no_] = w[i]
                        no_ += 1
            lo_i, hi_i = _robust_range(ti, wi, 0.03)
            lo_o, hi_o = _robust_range(to, wo, 0.03)
            axis = 0.5 * (lo_i - lo_o) * ts        # lateral offset of the median axis
            inner = 0.5 * (lo_i + lo_o)            # gap/2 + w/2
            nin = min(max(round((hi_i - lo_i) / lane_width) + 1, 1), max_lanes)
            nout = min(max(round((hi_o - lo_o) / lane_width) + 1, 1), max_lanes)
            wd = lane_width
            if fit_width and nin + nout > 2:
                wd = min(max(((hi_i - lo_i) + (hi_o - lo_o)) / (nin + nout - 2), wmin), wmax)
            P[k, 0] = min(max(2.0 * (inner - 0.5 * wd), 0.0), gap_max)
            P[k, 1] = nin
            P[k, 2] = nout
            P[k, 3] = wd
            wk = float(min(ni_, no_))
            nx = -uy[k]
            ny = ux[k]
            off = nx * cx + ny * cy + axis
            a11 += wk * nx * nx
            a12 += wk * nx * ny
            a22 += wk * ny * ny
            b1 += wk * nx * off
            b2 += wk * ny * off
        cx, cy = _ridge_solve2(a11, a12, a22, b1, b2, cx, cy)
    return cx, cy, P


@njit(cache=True, nogil=True)
def _voxel_slots(key, arm, sb, tb, cls):
    """Sorted unique ``key`` values and each row's index into them. Keys order rows by
    (arm, along bin, lateral bin, class), as the cell codes :func:`_group_codes` groups."""
    n = key.shape[0]
    if n == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    a0, s0, t0 = arm.min(), sb.min(), tb.min()
    ns = sb.max() - s0 + 1
    nt = tb.max() - t0 + 1
    code = np.empty(n, np.int64)
    for i in range(n):
        code[i] = (((arm[i] - a0) * ns + sb[i] - s0) * nt + tb[i] - t0) * 4 + cls[i]
    slot, m = _group_codes(code, (arm.max() - a0 + 1) * ns * nt * 4)
    uk = np.empty(m, np.int64)
    for i in range(n):
        uk[slot[i]] = key[i]
    return uk, slot


@njit(cache=True, nogil=True)
def arm_voxels(x, y, cls, arm, s, t, stamp, vx, vy, length, width, straight, merge, gap):
    """Arm-aligned voxels of radar / heading rows (paper §II-A voxelisation; see
    ``preprocess._arm_voxels``): key (arm, along-arm bin, lateral bin, class); with
    ``straight`` only voxels with an occupied voxel (lateral band +-1) before and after
    along the arm; then ``merge`` along-arm bins joined. Counts are divided by the mean
    number of detections per vehicle passage (stamp clusters > ``gap`` s apart per
    along-arm band; ``gap`` <= 0: raw counts).

    Returns mean x, mean y, class, count in passages, summed vx, summed vy (sorted by
    the merged key).
    """
    n = x.shape[0]
    step = 4096 * 4
    key = np.empty(n, np.int64)
    band = np.empty(n, np.int64)
    sb = np.empty(n, np.int64)
    tb = np.empty(n, np.int64)
    for i in range(n):
        sb[i] = np.int64(math.floor(s[i] / length))
        tb[i] = np.int64(math.floor(t[i] / width))
        key[i] = ((arm[i] * 1024 + sb[i] + 512) * 4096 + tb[i] + 2048) * 4 + cls[i]
        band[i] = (arm[i] * 1024 + sb[i] + 512) * 4 + cls[i]
    # detections per vehicle passage of an along-arm band (all lateral bins together)
    per_pass = 1.0
    if gap > 0.0 and n > 0:   # rows in time order; a band's stamp more than gap after its last
        order = np.arange(n)
        for i in range(1, n):
            if stamp[i] < stamp[i - 1]:
                order = np.argsort(stamp, kind='mergesort')
                break
        b0 = band.min()
        last = np.full(band.max() - b0 + 1, -np.inf)
        n_pass = 0
        for r in range(n):
            i = order[r]
            if stamp[i] - last[band[i] - b0] > gap:
                n_pass += 1
            last[band[i] - b0] = stamp[i]
        per_pass = n / float(n_pass)
    # unique voxels: count and sums
    uk, slot = _voxel_slots(key, arm, sb, tb, cls)
    m = uk.shape[0]
    cnt = np.zeros(m)
    sx = np.zeros(m)
    sy = np.zeros(m)
    svx = np.zeros(m)
    svy = np.zeros(m)
    for i in range(n):
        j = slot[i]
        cnt[j] += 1.0
        sx[j] += x[i]
        sy[j] += y[i]
        svx[j] += vx[i]
        svy[j] += vy[i]
    keep = np.ones(m, np.bool_)
    if straight:
        for j in range(m):
            before = False
            after = False
            for dt in (-4, 0, 4):
                q = uk[j] - step + dt
                p = np.searchsorted(uk, q)
                if p < m and uk[p] == q:
                    before = True
                q = uk[j] + step + dt
                p = np.searchsorted(uk, q)
                if p < m and uk[p] == q:
                    after = True
            keep[j] = before and after
    idx = np.flatnonzero(keep)
    mk = idx.shape[0]
    key2 = np.empty(mk, np.int64)
    for r in range(mk):
        u = uk[idx[r]]
        if merge > 1:
            si_k = (u // step) % 1024
            arm_k = u // (step * 1024)
            key2[r] = (arm_k * 1024 + si_k // merge) * step + u % step
        else:
            key2[r] = u
    o2 = np.argsort(key2)
    ox = np.zeros(mk)
    oy = np.zeros(mk)
    oc = np.zeros(mk, np.int64)
    ow = np.zeros(mk)
    ovx = np.zeros(mk)
    ovy = np.zeros(mk)
    g = -1
    last = np.int64(0)
    for r in range(mk):
        j = idx[o2[r]]
        if g < 0 or key2[o2[r]] != last:
            g += 1
            last = key2[o2[r]]
            oc[g] = last % 4
        ow[g] += cnt[j]
        ox[g] += sx[j]
        oy[g] += sy[j]
        ovx[g] += svx[j]
        ovy[g] += svy[j]
    g += 1
    for r in range(g):
        ox[r] /= ow[r]
        oy[r] /= ow[r]
        ow[r] /= per_pass
    return ox[:g], oy[:g], oc[:g], ow[:g], ovx[:g], ovy[:g]


@njit(cache=True, nogil=True)
def radar_voxels(x, y, stamp, dop, sx, sy, cx, cy, angles, reach, min_cos, min_dop,
                 keep_unknown, rays, length, width, straight, merge, gap, min_dist):
    """Radar rows -> arm-aligned voxels in one compiled pass (``preprocess.radar_observations``
    with arms known): :func:`radar_frame`, then :func:`arm_voxels` of the rows on an arm
    and of those along ``rays``, then voxels closer than ``min_dist`` to the center dropped.

    Returns mean x, mean y, direction (+1 entering, -1 leaving, 0 unknown), count in
    passages."""
    arm, s, t, group, cls = radar_frame(x, y, dop, sx, sy, cx, cy, angles, reach, min_cos,
                                        min_dop, keep_unknown, rays)
    ia = np.flatnonzero(group == 1)
    ib = np.flatnonzero(group == 2)
    za = np.zeros(ia.shape[0])
    zb = np.zeros(ib.shape[0])
    ax, ay, ac, aw, _, _ = arm_voxels(x[ia], y[ia], cls[ia], arm[ia], s[ia], t[ia], stamp[ia],
                                      za, za, length, width, straight, merge, gap)
    bx, by, bc, bw, _, _ = arm_voxels(x[ib], y[ib], cls[ib], arm[ib], s[ib], t[ib], stamp[ib],
                                      zb, zb, length, width, straight, merge, gap)
    mx = np.concatenate((ax, bx))
    my = np.concatenate((ay, by))
    mc = np.concatenate((ac, bc))
    mw = np.concatenate((aw, bw))
    m = 0
    for j in range(mx.shape[0]):
        if min_dist <= 0.0 or math.hypot(mx[j] - cx, my[j] - cy) >= min_dist:
            mx[m] = mx[j]
            my[m] = my[j]
            mw[m] = mw[j]
            mc[m] = 1 if mc[j] == 1 else (-1 if mc[j] == 0 else 0)
            m += 1
    return mx[:m], my[:m], mc[:m].astype(np.float64), mw[:m]


@njit(cache=True, nogil=True, inline='always')
def _nearest_ray(px, py, ux, uy):
    """Among the rays (from the origin, unit directions ``ux, uy``) that ``(px, py)`` lies
    ahead of, the one with the smallest lateral offset: (index, s, t); -1 if none."""
    best = -1
    bs = 0.0
    bt = np.inf
    for k in range(ux.shape[0]):
        s = px * ux[k] + py * uy[k]
        if s <= 0.0:
            continue
        t = py * ux[k] - px * uy[k]
        if abs(t) < abs(bt):
            best = k
            bs = s
            bt = t
    return best, bs, bt


@njit(cache=True, nogil=True)
def nearest_rays(x, y, cx, cy, angles):
    """Per point: nearest of the rays from ``(cx, cy)`` at ``angles`` that it lies ahead
    of (:func:`_nearest_ray`), its s and t; (0, 0, 0) where it lies ahead of none."""
    n = x.shape[0]
    ux = np.cos(angles)
    uy = np.sin(angles)
    arm = np.zeros(n, np.int64)
    s_out = np.zeros(n)
    t_out = np.zeros(n)
    for i in range(n):
        k, s, t = _nearest_ray(x[i] - cx, y[i] - cy, ux, uy)
        if k >= 0:
            arm[i] = k
            s_out[i] = s
            t_out[i] = t
    return arm, s_out, t_out


@njit(cache=True, nogil=True)
def radar_frame(x, y, dop, sx, sy, cx, cy, angles, reach, min_cos, min_dop, keep_unknown, rays):
    """Per radar row (paper §II-A, see ``preprocess.radar_observations``): nearest arm (or
    ray), s, t, group (0 dropped, 1 on an arm, 2 on no arm: along ``rays``, or square
    voxels if ``rays`` is empty) and direction class (0 leaving, 1 entering, 2 unknown)
    from the Doppler sign and the line of sight (from the sensor, or the center if the
    sensor position is NaN) projected on the arm direction (radial off the arms)."""
    n = x.shape[0]
    aux = np.cos(angles)
    auy = np.sin(angles)
    rux = np.cos(rays)
    ruy = np.sin(rays)
    arm = np.zeros(n, np.int64)
    s_out = np.zeros(n)
    t_out = np.zeros(n)
    group = np.zeros(n, np.int8)
    cls = np.zeros(n, np.int64)
    for i in range(n):
        px = x[i] - cx
        py = y[i] - cy
        r2 = px * px + py * py
        sensor = math.isfinite(sx[i]) and math.isfinite(sy[i])
        lx = x[i] - (sx[i] if sensor else cx)
        ly = y[i] - (sy[i] if sensor else cy)
        l2 = lx * lx + ly * ly
        if r2 <= 1e-18 or l2 <= 1e-18:
            continue
        k, s, t = _nearest_ray(px, py, aux, auy)
        on = k >= 0 and abs(t) <= reach
        if on:   # on an arm the lane direction is the arm's, not the radial direction
            proj = (aux[k] * lx + auy[k] * ly) / math.sqrt(l2)
        else:
            proj = (px * lx + py * ly) / math.sqrt(r2 * l2)
        unknown = abs(proj) < min_cos or abs(dop[i]) < min_dop
        if unknown and not keep_unknown:
            continue
        cls[i] = 2 if unknown else (0 if dop[i] * proj > 0.0 else 1)
        if on:
            group[i] = 1
            arm[i] = k
            s_out[i] = s
            t_out[i] = t
        elif rays.shape[0] == 0:
            group[i] = 2
        else:
            k, s, t = _nearest_ray(px, py, rux, ruy)
            if k >= 0:
                group[i] = 2
                arm[i] = k
                s_out[i] = s
                t_out[i] = t
    return arm, s_out, t_out, group, cls
