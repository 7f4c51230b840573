"""Data-driven initialisation of a chain (beyond the paper's random start, §II).

Center where the observed driving lines meet (robust least squares, :func:`initial_center`),
arm angles from a histogram of outward driving directions (:func:`initial_arm_angles`,
completed to ``min_arms`` by :func:`complete_arms`), then per arm lane counts, gap and
width from the lateral spread of the preprocessed observations (:func:`initial_lanes`,
which also refines the center from the arms' median axes). :func:`seed_lines` gives the
driving lines, center-free. The center and the lane guess are compiled
(:func:`irls_center`, :func:`lane_guess`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..model import Arm, Intersection, unit_vectors, wrap_angle
from ..observations import Detections
from .likelihood import ObservationSet
from .preprocess import PreprocessConfig, radar_filter
from .state import pack_state
from .voxels import voxelise

#: [m] the box around the center whose observations do not place the arms' axes
#: (:func:`lane_guess`) and beyond which the axes' meeting point is no refinement
#: (:func:`initial_lanes`)
BOX_M = 8.0

__all__ = ['initial_state', 'seed_lines', 'initial_center', 'initial_arm_angles', 'complete_arms',
           'initial_lanes', 'irls_center', 'lane_guess', 'local_pca']


def seed_lines(dets: Detections, cfg: PreprocessConfig):
    """Driving lines (point, unit direction, weight) for the initial center, center-free.

    Rows with a heading (tracked or not) are voxelised per heading sector; radar rows
    surviving the clutter filter are voxelised and get their direction from a local PCA
    of neighbouring voxels (weighted by its anisotropy).
    """
    dets = dets.finite()
    m = np.isfinite(dets.heading) & ~np.isfinite(dets.doppler)
    pts, dirs, wts = [], [], []
    if m.any():
        h = dets.heading[m]
        sector = np.floor(np.mod(h, 2 * math.pi) / (2 * math.pi) * cfg.heading_sectors)
        vec = np.stack([np.cos(h), np.sin(h)], axis=1)
        vxy, _, cnt, sv = voxelise(dets.xy[m], sector.astype(np.int64), 2.0 * cfg.voxel_size, vec)
        hx, hy, ok = unit_vectors(sv[:, 0], sv[:, 1])
        pts.append(vxy[ok])
        dirs.append(np.stack([hx, hy], axis=1)[ok])
        wts.append(np.sqrt(cnt[ok]))
    r = radar_filter(dets, cfg)
    if r.any():
        vxy, _, cnt, _ = voxelise(dets.xy[r], np.zeros(int(r.sum()), np.int64), 2.0 * cfg.voxel_size)
        if len(vxy) > 1500:
            keep = np.argsort(-cnt, kind='stable')[:1500]
            vxy, cnt = vxy[keep], cnt[keep]
        theta, aniso = local_pca(vxy[:, 0].copy(), vxy[:, 1].copy(), cnt, cfg.pca_radius)
        pts.append(vxy)
        dirs.append(np.stack([np.cos(theta), np.sin(theta)], axis=1))
        wts.append(np.sqrt(cnt) * aniso ** 2)
    if not pts:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    return np.concatenate(pts), np.concatenate(dirs), np.concatenate(wts)


def initial_center(p: np.ndarray, o: np.ndarray, w: np.ndarray, scale: float = 6.0,
                   iters: int = 30) -> np.ndarray | None:
    """Robust point where the driving lines (p_i, o_i) meet (IRLS, Cauchy loss).

    Starts at the weighted median of the points; a small ridge toward it keeps the
    solution defined when all lines are parallel (a single road).
    """
    if len(p) == 0:
        return None
    c0 = (_wmedian(p[:, 0], w), _wmedian(p[:, 1], w))
    c = irls_center(np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]),
                    np.ascontiguousarray(-o[:, 1]), np.ascontiguousarray(o[:, 0]),
                    np.ascontiguousarray(w, dtype=np.float64), c0[0], c0[1], float(scale),
                    int(iters))
    return np.array(c)


def _wmedian(x, w):
    i = np.argsort(x)
    cw = np.cumsum(w[i])
    return float(x[i][np.searchsorted(cw, 0.5 * cw[-1])])


def initial_arm_angles(p: np.ndarray, o: np.ndarray, w: np.ndarray, center, min_sep: float,
                       max_arms: int, min_dist: float = 10.0, peak_frac: float = 0.12,
                       bin_deg: float = 2.0, smooth_deg: float = 4.0) -> list[float]:
    """Arm angles from a histogram of outward driving directions around ``center``.

    Only lines far enough from the center and roughly radial are used; the direction is
    flipped to point away from the center, so every lane of an arm votes for the arm's
    angle regardless of its lateral offset.
    """
    if len(p) == 0:
        return []
    v = p - np.asarray(center, float)
    dist = np.hypot(v[:, 0], v[:, 1])
    with np.errstate(invalid='ignore', divide='ignore'):
        radial = np.sum(o * v, axis=1) / np.maximum(dist, 1e-9)
    use = (dist > min_dist) & (np.abs(radial) > math.cos(math.radians(35.0)))
    if not use.any():
        return []
    out = o[use] * np.sign(radial[use])[:, None]
    ang = np.arctan2(out[:, 1], out[:, 0])
    nb = int(round(360.0 / bin_deg))
    idx = np.floor(np.mod(ang, 2 * math.pi) / (2 * math.pi) * nb).astype(int) % nb
    hist = np.bincount(idx, w[use], nb)
    k = np.arange(-3 * int(smooth_deg / bin_deg) - 1, 3 * int(smooth_deg / bin_deg) + 2)
    ker = np.exp(-0.5 * (k * bin_deg / smooth_deg) ** 2)
    # circular smoothing: row j of the table is ker[j] * roll(hist, k[j]); the rows are
    # summed in order (a reduction over axis 0 adds row by row), as a loop of += would
    sm = (ker[:, None] * hist[(np.arange(nb)[None, :] - k[:, None]) % nb]).sum(axis=0)
    peak = (sm >= np.roll(sm, 1)) & (sm > np.roll(sm, -1))
    peaks = np.flatnonzero(peak)
    peaks = peaks[np.argsort(-sm[peaks], kind='stable')].tolist()
    chosen: list[float] = []
    top = sm.max()
    for i in peaks:
        if sm[i] < peak_frac * top or len(chosen) >= max_arms:
            break
        a = float(wrap_angle((i + 0.5) * 2 * math.pi / nb))
        if all(abs(float(wrap_angle(a - b))) >= min_sep for b in chosen):
            chosen.append(a)
    return chosen


def initial_lanes(obs: ObservationSet, center, angles, lane_width: float, max_lanes: int,
                  gap_max: float, traffic_side: int = 1, iters: int = 3, width_range=None,
                  max_move: float = BOX_M):
    """Refine the center from the arms' median axes and guess gap / lane counts per arm.

    Observations are assigned to the arm whose axis they run along (outside ``BOX_M``,
    roughly parallel when oriented); per arm the median axis lies halfway between the
    innermost entering and the innermost leaving observations; the center is the
    least-squares meeting point of these axes -- kept only within ``max_move`` of
    ``center`` (else ``center`` stays; default ``BOX_M``); lane counts (and, with
    ``width_range``, the lane width)
    follow from the lateral spread. Returns
    (center, [(gap, lanes_in, lanes_out, width), ...]).
    """
    c = np.asarray(center, float).copy()
    params = [(0.0, 1, 1, lane_width)] * len(angles)
    if len(obs) == 0 or len(angles) == 0:
        return c, params
    widths = ((float(width_range[0]), float(width_range[1]), True) if width_range is not None
              else (lane_width, lane_width, False))

    def guess(n_iter):
        return lane_guess(obs.x, obs.y, obs.hx, obs.hy, obs.has_o, obs.d,
                          np.asarray(obs.w, float), float(c[0]), float(c[1]),
                          np.asarray(angles, float), float(lane_width), int(max_lanes),
                          float(gap_max), float(traffic_side), int(n_iter), *widths)

    cx, cy, P = guess(iters)
    if math.hypot(cx - c[0], cy - c[1]) > max_move:
        # The axes meet outside the box whose observations placed them: nearly parallel
        # axes (two arms of one road) or a bent arm's axis extrapolated -- SUMO seed 92's
        # moved 52 m down the road. That is no refinement: keep the driving lines' center
        # and the lanes as seen from it (one pass: its lanes are read before its move).
        _, _, P = guess(1)
        cx, cy = c
    return np.array([cx, cy]), [(float(g), int(ni), int(no), float(wd)) for g, ni, no, wd in P]


def complete_arms(angles, o, w, min_arms: int, min_sep: float) -> list[float]:
    """``angles`` completed to at least ``min_arms`` (data scarce): the first arm along the
    weighted mean driving direction ``o`` (weights ``w``) if none was found, the others
    opposite / evenly spaced, each at least ``min_sep`` [rad] from the rest."""
    if not angles:
        if len(o):
            v = (w[:, None] * o).sum(0)
            a0 = math.atan2(v[1], v[0]) if np.hypot(*v) > 0 else 0.0
        else:
            a0 = 0.0
        angles = [a0]
    base = angles[0]
    k = 1
    while len(angles) < min_arms:
        cand = base + math.pi * k / max(min_arms - 1, 1)
        cand = (cand + math.pi) % (2 * math.pi) - math.pi
        if all(abs((cand - b + math.pi) % (2 * math.pi) - math.pi) >= min_sep for b in angles):
            angles.append(cand)
        k += 1
        if k > 32:
            break
    return angles


def initial_state(dets: Detections, cfg, pcfg: PreprocessConfig, preprocessed):
    """The initial packed state of a chain from the detections ``dets`` (``cfg`` a
    :class:`.config.TopologyConfig`, ``pcfg`` its preprocessing subset), or None without
    driving lines. ``preprocessed(center, angles)`` makes the observation set the lane
    guess reads. Returns ``(S, observations, the center they were made around)``."""
    p, o, w = seed_lines(dets, pcfg)
    c = initial_center(p, o, w)
    if c is None:
        return None
    min_sep = math.radians(cfg.min_sep_deg)
    angles = initial_arm_angles(p, o, w, c, min_sep, cfg.max_arms, peak_frac=cfg.init_peak_frac)
    angles = complete_arms(angles, o, w, cfg.min_arms, min_sep)
    obs = preprocessed(c, angles)
    # With trajectories the driving lines are the vehicles' headings and meet within a few
    # metres of the box: the axes' meeting point refines that only inside it. Radar / heading
    # voxels' lines come from local PCA, ambiguous at the box, and there the axes' point is
    # the better center even farther out (Table I raw, the paper's model: 86.4 % lane-level,
    # 84.9 % with the box; docs/real_junctions.md, "The initial center stays in its box").
    c2, guess = initial_lanes(obs, c, angles, cfg.lane_width, cfg.max_lanes, cfg.gap_max,
                              cfg.traffic_side, width_range=(cfg.lane_width_min,
                                                             cfg.lane_width_max)
                              if cfg.sample_width else None,
                              max_move=BOX_M if dets.has_tracks else math.inf)
    arms = [Arm(angle=a, gap=g, lanes_in=max(ni, cfg.min_lanes),
                lanes_out=max(no, cfg.min_lanes), lane_width=wd)
            for a, (g, ni, no, wd) in zip(angles, guess)]
    return pack_state(Intersection(center=c2, arms=arms)), obs, c


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

    Returns (cx, cy, params) with one row (gap, lanes in, lanes out, width) per angle.

    Length (over 80 lines): one compiled pass per iteration over all observations and arms
    (assignment, robust ranges, normal equations); split into helpers it would allocate per-
    arm arrays in the loop.
    """
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
                ok = sk > BOX_M and abs(tk) < 25.0
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
