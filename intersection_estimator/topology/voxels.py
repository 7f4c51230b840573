"""Voxelisation of the observations (paper §II-A), compiled where it is hot.

Square voxels (:func:`voxelise`, grouping in :func:`grid_voxel_index`) for data without
arms; arm-aligned voxels (:func:`arm_voxels`: ``voxel_length`` along the nearest arm,
``voxel_width`` across, the straight-run filter and the along-arm merge) once arms are
known; rows on no current arm are voxelised along :data:`RAYS` from the center. Radar rows
get their frame (nearest arm or ray, Doppler direction relative to the center) and their
voxels in one compiled pass (:func:`radar_voxels`). Voxel cells are counted in a dense
table (:data:`DENSE_CELLS`), not sorted. Weights are in vehicle passages
(:func:`passages`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ['RAYS', 'voxelise', 'passages', 'assign_arms', 'arm_voxel_set', 'ray_voxel_set',
           'grid_voxel_index', 'arm_voxels', 'radar_voxels', 'nearest_rays', 'radar_frame']

#: Rays every 10 deg: the frame of rows on no current arm (see :func:`ray_voxel_set`).
RAYS = np.radians(np.arange(-180.0, 180.0, 10.0))


def voxelise(xy: np.ndarray, cls: np.ndarray, size: float, vec: np.ndarray | None = None,
             t: np.ndarray | None = None, gap: float = 1.0):
    """Merge points per (voxel, class): mean position, count (and summed vectors); voxels
    in the order of (x bin, y bin, class), classes in [0, 64) (grouping compiled:
    :func:`grid_voxel_index`).

    With stamps ``t`` the counts are divided by the mean number of detections per vehicle
    passage (see :func:`passages`), i.e. expressed in vehicles."""
    if len(xy) == 0:
        return np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 2))
    if cls.min() < 0 or cls.max() >= 64:
        raise ValueError('voxelise: classes must lie in [0, 64)')
    inv, m = grid_voxel_index(np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
                              np.asarray(cls, np.int64), float(size))
    cnt = np.bincount(inv, minlength=m)
    mx = np.bincount(inv, xy[:, 0], m) / cnt
    my = np.bincount(inv, xy[:, 1], m) / cnt
    first = np.zeros(m, np.int64)
    first[inv[::-1]] = np.arange(len(inv))[::-1]
    sv = np.zeros((m, 2))
    if vec is not None:
        sv = np.stack([np.bincount(inv, vec[:, 0], m), np.bincount(inv, vec[:, 1], m)], axis=1)
    if t is not None and gap > 0:   # counts in vehicle passages (global detections/passage)
        per_pass = len(xy) / max(passages(inv, t, m, gap).sum(), 1.0)
        return np.stack([mx, my], axis=1), cls[first], cnt / per_pass, sv
    return np.stack([mx, my], axis=1), cls[first], cnt.astype(np.float64), sv


def passages(inv: np.ndarray, t: np.ndarray, n: int, gap: float) -> np.ndarray:
    """Per voxel: number of vehicle passages = clusters of its detection stamps separated
    by more than ``gap`` seconds. Detections of one passing vehicle are not independent;
    weights in units of passages give each vehicle (about) one vote per voxel whatever the
    sensor rate or the number of points per vehicle."""
    if len(inv) == 0:
        return np.zeros(n)
    o = np.lexsort((t, inv))
    vi, ts = inv[o], t[o]
    new = np.r_[True, (vi[1:] != vi[:-1]) | (np.diff(ts) > gap)]
    return np.bincount(vi[new], minlength=n).astype(np.float64)


def assign_arms(xy, c, angles):
    """Nearest arm (smallest lateral offset among arms the point lies ahead of), s, t;
    s = 0 where it lies ahead of none (compiled: :func:`nearest_rays`, the rule
    :func:`radar_frame` applies to radar rows)."""
    return nearest_rays(np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
                        float(c[0]), float(c[1]), np.asarray(angles, float))


def arm_voxel_set(xy, cls, arm, s, t, stamp, cfg, vec=None, merge=None):
    """Arm-aligned voxels with the straight-run filter (compiled: :func:`arm_voxels`);
    ``cfg``: a :class:`.preprocess.PreprocessConfig`, ``merge`` overrides its
    ``voxel_merge``. Returns mean position, class, weight in vehicle passages (and summed
    ``vec``)."""
    v = np.zeros((len(xy), 2)) if vec is None else np.asarray(vec, float)
    mx, my, c, w, svx, svy = arm_voxels(
        np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
        np.asarray(cls, np.int64), np.asarray(arm, np.int64), np.asarray(s, float),
        np.asarray(t, float), np.asarray(stamp, float), np.ascontiguousarray(v[:, 0]),
        np.ascontiguousarray(v[:, 1]), float(cfg.voxel_length), float(cfg.voxel_width),
        bool(cfg.straight_run), int(cfg.voxel_merge if merge is None else merge),
        float(cfg.passage_gap))
    mean = np.stack([mx, my], axis=1)
    if vec is not None:
        return mean, c, w, np.stack([svx, svy], axis=1)
    return mean, c, w


def ray_voxel_set(xy, cls, c, stamp, cfg, vec=None, merge=None):
    """Rows on no current arm: voxels aligned with the nearest of :data:`RAYS` from the
    center, with the straight-run filter -- an unfound arm's traffic runs radially and
    survives, isolated clutter and turning traffic do not."""
    arm, s, t = assign_arms(xy, c, RAYS)
    ok = s > 0
    return arm_voxel_set(xy[ok], cls[ok], arm[ok], s[ok], t[ok], stamp[ok], cfg,
                         None if vec is None else vec[ok], merge)


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
def _bins(s, t, arm, cls, length, width):
    """Per row: along-arm bin, lateral bin, voxel key (arm, along bin, lateral bin, class)
    and band key (arm, along bin, class); and the bins' box ``(a0, s0, t0, na, ns, nt)``
    when every bin lies strictly inside its key field (along bins in (-512, 511), lateral
    in (-2048, 2047), classes in [0, 3]: a neighbour bin never spills into the next field),
    else ``na = 0``."""
    n = s.shape[0]
    sb = np.empty(n, np.int64)
    tb = np.empty(n, np.int64)
    key = np.empty(n, np.int64)
    band = np.empty(n, np.int64)
    for i in range(n):
        sb[i] = np.int64(math.floor(s[i] / length))
        tb[i] = np.int64(math.floor(t[i] / width))
        key[i] = ((arm[i] * 1024 + sb[i] + 512) * 4096 + tb[i] + 2048) * 4 + cls[i]
        band[i] = (arm[i] * 1024 + sb[i] + 512) * 4 + cls[i]
    box = np.zeros(6, np.int64)
    if n == 0:
        return sb, tb, key, band, box
    a0, s0, t0 = arm.min(), sb.min(), tb.min()
    a1, s1, t1 = arm.max(), sb.max(), tb.max()
    inside = -511 <= s0 and s1 <= 510 and -2047 <= t0 and t1 <= 2046
    if inside and 0 <= a0 and 0 <= cls.min() and cls.max() <= 3:
        box[0], box[1], box[2] = a0, s0, t0
        box[3], box[4], box[5] = a1 - a0 + 1, s1 - s0 + 1, t1 - t0 + 1
    return sb, tb, key, band, box


@njit(cache=True, nogil=True)
def _per_passage(stamp, band, nb, gap):
    """Detections per vehicle passage: a band's (``band`` in [0, nb)) stamp more than
    ``gap`` s after its last starts a passage; rows taken in time order (stable)."""
    n = stamp.shape[0]
    last = np.full(nb, -np.inf)
    n_pass = 0
    ordered = True
    for i in range(1, n):
        if stamp[i] < stamp[i - 1]:
            ordered = False
            break
    if ordered:
        for i in range(n):
            if stamp[i] - last[band[i]] > gap:
                n_pass += 1
            last[band[i]] = stamp[i]
    else:
        order = np.argsort(stamp, kind='mergesort')
        for r in range(n):
            i = order[r]
            if stamp[i] - last[band[i]] > gap:
                n_pass += 1
            last[band[i]] = stamp[i]
    return n / float(n_pass)


@njit(cache=True, nogil=True)
def _dense_slots(key, arm, sb, tb, cls, box):
    """:func:`_voxel_slots` within the box of :func:`_bins` (dense table, no sort), and per
    voxel its cell code and the table of cell -> voxel (-1 empty), for neighbour look-ups."""
    n = key.shape[0]
    a0, s0, t0, na, ns, nt = box[0], box[1], box[2], box[3], box[4], box[5]
    code = np.empty(n, np.int64)
    rank = np.full(na * ns * nt * 4, -1, np.int64)
    for i in range(n):
        code[i] = (((arm[i] - a0) * ns + sb[i] - s0) * nt + tb[i] - t0) * 4 + cls[i]
        rank[code[i]] = 0
    m = 0
    for c in range(rank.shape[0]):
        if rank[c] == 0:
            rank[c] = m
            m += 1
    slot = np.empty(n, np.int64)
    uk = np.empty(m, np.int64)
    vcode = np.empty(m, np.int64)
    for i in range(n):
        j = rank[code[i]]
        slot[i] = j
        uk[j] = key[i]
        vcode[j] = code[i]
    return uk, slot, vcode, rank


@njit(cache=True, nogil=True)
def _straight_dense(vcode, rank, ns, nt):
    """Straight-run filter on the dense table: a voxel is kept when the cells one along-arm
    bin before and one after (lateral bin +-1, same arm and class) each hold a voxel."""
    m = vcode.shape[0]
    keep = np.zeros(m, np.bool_)
    for j in range(m):
        c = vcode[j]
        ti = (c // 4) % nt
        si = (c // (4 * nt)) % ns
        before = False
        after = False
        for dt in (-1, 0, 1):
            if ti + dt < 0 or ti + dt >= nt:
                continue
            if si > 0 and rank[c - 4 * nt + 4 * dt] >= 0:
                before = True
            if si < ns - 1 and rank[c + 4 * nt + 4 * dt] >= 0:
                after = True
        keep[j] = before and after
    return keep


@njit(cache=True, nogil=True)
def _straight_sorted(uk):
    """Straight-run filter on the sorted keys (binary search): any key layout."""
    step = 4096 * 4
    m = uk.shape[0]
    keep = np.ones(m, np.bool_)
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
    return keep


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

    Bins, bands and neighbours are looked up in dense tables over the rows' box of bins
    (:func:`_bins`, :func:`_dense_slots`, :func:`_straight_dense`); outside it (far-flung
    rows) the keys are sorted and searched (:func:`_voxel_slots`, :func:`_straight_sorted`)
    -- the same voxels either way.
    """
    n = x.shape[0]
    step = 4096 * 4
    sb, tb, key, band, box = _bins(s, t, arm, cls, length, width)
    dense = box[3] > 0 and box[3] * box[4] * box[5] * 4 <= DENSE_CELLS
    # detections per vehicle passage of an along-arm band (all lateral bins together)
    per_pass = 1.0
    if gap > 0.0 and n > 0:
        if dense:   # bands numbered in the box: a small table
            for i in range(n):
                band[i] = ((arm[i] - box[0]) * box[4] + sb[i] - box[1]) * 4 + cls[i]
            per_pass = _per_passage(stamp, band, box[3] * box[4] * 4, gap)
        else:
            b0 = band.min()
            per_pass = _per_passage(stamp, band - b0, band.max() - b0 + 1, gap)
    # unique voxels: count and sums
    if dense:
        uk, slot, vcode, rank = _dense_slots(key, arm, sb, tb, cls, box)
    else:
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
        keep = _straight_dense(vcode, rank, box[4], box[5]) if dense else _straight_sorted(uk)
    return _merged(uk, keep, cnt, sx, sy, svx, svy, merge, per_pass, step)


@njit(cache=True, nogil=True)
def _merged(uk, keep, cnt, sx, sy, svx, svy, merge, per_pass, step):
    """The kept voxels with ``merge`` along-arm bins joined (sorted by the merged key):
    mean x, mean y, class, count in passages, summed vx, summed vy."""
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
def _group_rows(group, g, rows):
    """The rows with ``group == g`` of each column of ``rows`` (x, y, cls, arm, s, t,
    stamp), in row order: one pass for all seven columns, no index array."""
    n = group.shape[0]
    m = 0
    for i in range(n):
        if group[i] == g:
            m += 1
    x, y, cls, arm, s, t, stamp = rows
    ox = np.empty(m, x.dtype)
    oy = np.empty(m, y.dtype)
    oc = np.empty(m, cls.dtype)
    oa = np.empty(m, arm.dtype)
    os_ = np.empty(m, s.dtype)
    ot = np.empty(m, t.dtype)
    ost = np.empty(m, stamp.dtype)
    q = 0
    for i in range(n):
        if group[i] == g:
            ox[q] = x[i]
            oy[q] = y[i]
            oc[q] = cls[i]
            oa[q] = arm[i]
            os_[q] = s[i]
            ot[q] = t[i]
            ost[q] = stamp[i]
            q += 1
    return ox, oy, oc, oa, os_, ot, ost


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
    rows = (x, y, cls, arm, s, t, stamp)
    a = _group_rows(group, 1, rows)
    b = _group_rows(group, 2, rows)
    za = np.zeros(a[0].shape[0])
    zb = np.zeros(b[0].shape[0])
    ax, ay, ac, aw, _, _ = arm_voxels(a[0], a[1], a[2], a[3], a[4], a[5], a[6], za, za,
                                      length, width, straight, merge, gap)
    bx, by, bc, bw, _, _ = arm_voxels(b[0], b[1], b[2], b[3], b[4], b[5], b[6], zb, zb,
                                      length, width, straight, merge, gap)
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
