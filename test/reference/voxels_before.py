"""The compiled arm-aligned voxelisation as it was before issue 18's rewrite
(``voxels.arm_voxels`` at 99ef205, verbatim but for the names): the product kernel must
give the same arrays, bit for bit (test/topology/test_voxels.py)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _group_codes_before(code, cells):
    """Each row's group index, groups numbered in increasing ``code`` (cell codes in
    [0, cells)), and the group count: within ``(1 << 22)`` counted in a dense table (no
    sort), otherwise by sorting the codes."""
    n = code.shape[0]
    slot = np.empty(n, np.int64)
    if cells <= (1 << 22):
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
def _voxel_slots_before(key, arm, sb, tb, cls):
    """Sorted unique ``key`` values and each row's index into them. Keys order rows by
    (arm, along bin, lateral bin, class), as the cell codes :func:`_group_codes_before` groups."""
    n = key.shape[0]
    if n == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    a0, s0, t0 = arm.min(), sb.min(), tb.min()
    ns = sb.max() - s0 + 1
    nt = tb.max() - t0 + 1
    code = np.empty(n, np.int64)
    for i in range(n):
        code[i] = (((arm[i] - a0) * ns + sb[i] - s0) * nt + tb[i] - t0) * 4 + cls[i]
    slot, m = _group_codes_before(code, (arm.max() - a0 + 1) * ns * nt * 4)
    uk = np.empty(m, np.int64)
    for i in range(n):
        uk[slot[i]] = key[i]
    return uk, slot


@njit(cache=True, nogil=True)
def arm_voxels_before(x, y, cls, arm, s, t, stamp, vx, vy, length, width, straight, merge, gap):
    """Arm-aligned voxels of radar / heading rows (paper §II-A voxelisation; see
    ``preprocess._arm_voxels``): key (arm, along-arm bin, lateral bin, class); with
    ``straight`` only voxels with an occupied voxel (lateral band +-1) before and after
    along the arm; then ``merge`` along-arm bins joined. Counts are divided by the mean
    number of detections per vehicle passage (stamp clusters > ``gap`` s apart per
    along-arm band; ``gap`` <= 0: raw counts).

    Returns mean x, mean y, class, count in passages, summed vx, summed vy (sorted by
    the merged key).

    Length (over 80 lines): one fused pass (cell codes, grouping, straight-run filter,
    along-arm merge, passage counts) over the same scratch arrays, the preprocessing hot
    path.
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
    uk, slot = _voxel_slots_before(key, arm, sb, tb, cls)
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


