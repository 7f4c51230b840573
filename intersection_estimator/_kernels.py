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
 P_INV_SP2, P_INV_SA2, P_FLOOR, P_TRAFFIC, P_D2_CUT, P_SAMPLE_W, P_W_DEFAULT,
 P_LANE_NORM) = range(26)
NPARAM = 26

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
def move_rotate(S, S2, P):
    """Rotate a random arm by U[-rot, rot] (symmetric)."""
    n = int(S[2])
    k = int(np.random.random() * n)
    i = HDR + k * STRIDE
    S2[i] = wrap(S[i] + (2.0 * np.random.random() - 1.0) * P[P_ROT])
    return separation_ok(S2, k, P[P_MIN_SEP]), 0.0, k


@njit(cache=True)
def move_shift(S, S2, P):
    """Shift the center by (dc, phi) ~ U([0, shift] x [0, 2pi]) (symmetric)."""
    r = np.random.random() * P[P_SHIFT]
    phi = np.random.random() * TWO_PI
    S2[0] = S[0] + r * math.cos(phi)
    S2[1] = S[1] + r * math.sin(phi)
    return True, 0.0, -1


@njit(cache=True)
def move_gap(S, S2, P):
    """Change the median gap of a random arm by U[-step, step] (symmetric)."""
    n = int(S[2])
    k = int(np.random.random() * n)
    i = HDR + k * STRIDE + GAP
    g = S[i] + (2.0 * np.random.random() - 1.0) * P[P_GAP_STEP]
    S2[i] = g
    return 0.0 <= g <= P[P_GAP_MAX], 0.0, k


@njit(cache=True)
def move_width(S, S2, P):
    """Change the lane width of a random arm by U[-step, step] (symmetric, beyond paper)."""
    n = int(S[2])
    k = int(np.random.random() * n)
    i = HDR + k * STRIDE + WID
    w = S[i] + (2.0 * np.random.random() - 1.0) * P[P_W_STEP]
    S2[i] = w
    return P[P_W_MIN] <= w <= P[P_W_MAX], 0.0, k


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
    """Add / remove an entering or leaving lane at the border or at the median.

    Border: lane count +-1, gap unchanged. Median: lane count +-1 and the gap shrinks /
    grows by one lane width (the new lane takes the median strip). Each variant is the
    other's reverse with the same selection probability, so the ratio is 0.
    """
    n = int(S[2])
    k = int(np.random.random() * n)
    entering = np.random.random() < 0.5
    add = np.random.random() < 0.5
    median = np.random.random() < 0.5
    i = HDR + k * STRIDE
    j = i + (NIN if entering else NOUT)
    w = S[i + WID]
    if add:
        S2[j] = S[j] + 1.0
        if S2[j] > P[P_MAX_LANES]:
            return False, 0.0, k
        if median:
            S2[i + GAP] = S[i + GAP] - w
            if S2[i + GAP] < 0.0:
                return False, 0.0, k
    else:
        S2[j] = S[j] - 1.0
        if S2[j] < P[P_MIN_LANES]:
            return False, 0.0, k
        if median:
            S2[i + GAP] = S[i + GAP] + w
            if S2[i + GAP] > P[P_GAP_MAX]:
                return False, 0.0, k
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

@njit(cache=True)
def arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, out):
    """Unnormalised density of every observation under its best lane of arm ``k``.

    Paper eq. for P(z_i|I): closest lane with the same driving direction, Gaussian in the
    orthogonal distance and (with orientation) in the angle, divided by (number of
    lanes of that direction) ** ``P_LANE_NORM``. Lanes are rays from the
    center; behind the ray start the Euclidean distance to the start is used. With an
    orientation the direction is arm-local (entering iff <o, u_a> < 0).
    """
    cx = S[0]
    cy = S[1]
    i0 = HDR + k * STRIDE
    a = S[i0 + ANG]
    hg = 0.5 * S[i0 + GAP]
    nin = S[i0 + NIN]
    nout = S[i0 + NOUT]
    w = S[i0 + WID]
    ux = math.cos(a)
    uy = math.sin(a)
    isp = 0.5 * P[P_INV_SP2]
    isa = 0.5 * P[P_INV_SA2]
    cut = P[P_D2_CUT]
    ts = P[P_TRAFFIC]
    inv_n_in = nin ** -P[P_LANE_NORM]
    inv_n_out = nout ** -P[P_LANE_NORM]
    for i in range(ox.shape[0]):
        px = ox[i] - cx
        py = oy[i] - cy
        s = px * ux + py * uy
        t = py * ux - px * uy
        e = 0.0
        if has_o[i]:
            c = hx[i] * ux + hy[i] * uy
            d = 1.0 if c < 0.0 else -1.0
            ca = abs(c)
            if ca > 1.0:
                ca = 1.0
            ang = math.acos(ca)
            e = isa * ang * ang
        else:
            d = dcls[i]
        nl = nin if d > 0.0 else nout
        q = d * ts * t - hg
        kk = math.floor(q / w)
        if kk < 0.0:
            kk = 0.0
        elif kk > nl - 1.0:
            kk = nl - 1.0
        dl = q - (kk + 0.5) * w
        d2 = dl * dl
        if s < 0.0:
            d2 += s * s
        e += isp * d2
        out[i] = math.exp(-e) * (inv_n_in if d > 0.0 else inv_n_out) if e < cut else 0.0


@njit(cache=True)
def all_columns(S, P, ox, oy, hx, hy, has_o, dcls, C):
    for k in range(int(S[2])):
        arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, C[k])


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
def full_loglik(S, P, ox, oy, hx, hy, has_o, dcls, wts, C):
    all_columns(S, P, ox, oy, hx, hy, has_o, dcls, C)
    return combine(C, int(S[2]), -1, C[0], False, wts, P[P_FLOOR])


# ----------------------------------------------------------------------------- annealing

@njit(cache=True)
def run_chain(S, C, ll, lp, best_S, best_lpost, P, logPA, logPn, arm_const, logqn, cumqn,
              ox, oy, hx, hy, has_o, dcls, wts, n_steps, temps, seed, stats):
    """Metropolis-Hastings with simulated annealing (paper §II, Algorithm 1).

    Mutates ``S`` (chain state), ``C`` (per-arm density columns of ``S``) and
    ``best_S``; ``temps[t]`` is the temperature of step ``t``. The likelihood is
    incremental: moves touching one arm recompute only that arm's column, a center shift
    recomputes all. ``stats[kind*2]`` counts proposals, ``stats[kind*2+1]`` acceptances.
    Returns (ll, lp, best_lpost).
    """
    np.random.seed(seed)
    S2 = np.empty_like(S)
    nobs = ox.shape[0]
    col = np.empty(nobs)
    C2 = np.empty_like(C)
    floor = P[P_FLOOR]
    for step in range(n_steps):
        ok, lq, kind, k = propose(S, S2, P, logqn, cumqn)
        stats[2 * kind] += 1
        if not ok:
            continue
        n2 = int(S2[2])
        n = int(S[2])
        if kind == SHIFT:
            all_columns(S2, P, ox, oy, hx, hy, has_o, dcls, C2)
            ll2 = combine(C2, n2, -1, col, False, wts, floor)
        elif kind == REMOVE_ARM:
            ll2 = combine(C, n, k, col, False, wts, floor)
        elif kind == ADD_ARM:
            arm_column(S2, k, P, ox, oy, hx, hy, has_o, dcls, col)
            ll2 = combine(C, n, -1, col, True, wts, floor)
        else:
            arm_column(S2, k, P, ox, oy, hx, hy, has_o, dcls, col)
            ll2 = combine(C, n, k, col, True, wts, floor)
        lp2 = log_prior(S2, logPA, logPn, arm_const)
        a = (ll2 + lp2 - ll - lp) / temps[step] + lq
        if a < 0.0 and math.log(np.random.random()) >= a:
            continue
        stats[2 * kind + 1] += 1
        if kind == SHIFT:
            for j in range(n2):
                C[j, :] = C2[j, :]
        elif kind == REMOVE_ARM:
            if k != n - 1:
                C[k, :] = C[n - 1, :]
        else:
            C[k, :] = col
        S[:] = S2
        ll = ll2
        lp = lp2
        if ll + lp > best_lpost:
            best_lpost = ll + lp
            best_S[:] = S
    return ll, lp, best_lpost
