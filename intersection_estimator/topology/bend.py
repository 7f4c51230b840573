"""Arms that bend: straighten the trajectory rows of a curved approach (beyond the paper).

Paper §II-B models an arm as straight lane rays from the center, and §II-A reduces a
trajectory part to its mean point. On a curved approach the traffic of one lane drifts
sideways along the arm: in the straight arm frame its part means spread over several lane
widths (one lane that bends by 20 deg over 40 m looks like three straight lanes), and the
sampler explains the drift with lanes that do not exist.

This step measures the bend from the traffic itself and undoes it before §II-A's
reduction, so that the straight model sees straight arms:

1. each trajectory part (the rows beyond ``part_outside`` from the center, as §II-A keeps
   them) is given to the arm whose direction is nearest the angle of its innermost kept
   row (:func:`part_arms`);
2. per arm and driving direction, the rows' headings relative to the outward arm
   direction, binned along the arm (``bend_bin`` metres), median per bin over at least two
   vehicles (:func:`bend_profile`): vehicles follow their lanes, so the heading of the
   traffic at distance ``s`` is the road's direction there, whichever lane they use;
3. only when that direction turns by at least ``bend_min_deg`` against the innermost bin:
   the axis curve with that heading profile, started at the innermost bin, and every row
   of the arm's parts moved to the same arc length and signed normal distance along the
   straight line in the innermost direction, its heading turned back by the bend there
   (:func:`unbend`).

No curve family is assumed: the profile is a piecewise-linear interpolation of the
measured medians. Rows inside ``part_outside`` and arms whose traffic does not turn are
left bit-identical (on straight arms the step changes nothing). Reported arm angles are
then the directions of the approaches next to the box.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

__all__ = ['part_arms', 'bend_profile', 'unbend', 'straighten']

#: rows turning by more than this against the arm do not enter the profile (a turn
#: inside the box, a lane change across the view) [rad]
_MAX_REL = math.radians(50.0)
#: a part's rows enter the profile up to where its heading turns faster than this over
#: _SPAN metres [deg/m]: a turn at the junction (90 deg over ~15 m: 6 deg/m) is cut, a road
#: that bends by 35 deg over 30 m or more (~1 deg/m) is kept
_MAX_RATE_DEG = 2.5
_SPAN = 5.0
#: a profile whose neighbouring bins differ by more than this is not one road [rad]
_MAX_JUMP = math.radians(8.0)
#: arc-length step of the axis curve [m]
_STEP = 0.5


@njit(cache=True)
def _turn_start(x, y, h, first, step, n, max_rate, span):
    """Rows ``0..k-1`` (row ``q`` is ``first + step * q``, from the far end) before the
    first row where the heading turns faster than ``max_rate`` [rad/m] over ``span`` metres
    of path: the turn into the box (a vehicle turning at the junction), not the road's
    bend, which is gentler; returns ``k``."""
    for q in range(n - 1):
        i = first + step * q
        dist = 0.0
        for r in range(q + 1, n):
            j = first + step * r
            k = first + step * (r - 1)
            dist += math.hypot(x[j] - x[k], y[j] - y[k])
            if dist >= span:
                dh = abs((h[j] - h[i] + math.pi) % (2.0 * math.pi) - math.pi)
                if dh > max_rate * dist:
                    return q
                break
    return n


@njit(cache=True)
def part_arms(x, y, h, starts, ends, cx, cy, r2_in, angles, tol, max_rate, span):
    """Per row: (arm index or -1, part id or -1, +1 entering / -1 leaving, row enters the
    bend profile).

    Each trajectory is split at its row closest to the center (§II-A); a part's rows are
    the contiguous run from its far end to the first row within ``sqrt(r2_in)`` (as
    :func:`.preprocess._far_portion`), and the part goes to the arm nearest (within
    ``tol`` rad) the angle of its innermost such row. A row in both parts (a vehicle that
    never came closer) keeps the entering one. The profile takes a part's rows from its
    far end up to where it starts to turn (:func:`_turn_start`)."""
    n = x.shape[0]
    prof = np.zeros(n, np.bool_)
    arm = np.full(n, -1, np.int64)
    pid = np.full(n, -1, np.int64)
    dirn = np.zeros(n, np.int64)
    na = angles.shape[0]
    npart = 0
    for t in range(starts.shape[0]):
        a, b = starts[t], ends[t]
        imin, best = a, np.inf
        for i in range(a, b):
            d = (x[i] - cx) ** 2 + (y[i] - cy) ** 2
            if d < best:
                best, imin = d, i
        for part in range(2):
            if part == 0:
                lo, hi = a, imin + 1
                for i in range(a, imin + 1):
                    if (x[i] - cx) ** 2 + (y[i] - cy) ** 2 < r2_in:
                        hi = i
                        break
                inner = hi - 1
            else:
                lo, hi = imin, b
                for i in range(b - 1, imin - 1, -1):
                    if (x[i] - cx) ** 2 + (y[i] - cy) ** 2 < r2_in:
                        lo = i + 1
                        break
                inner = lo
            if hi - lo < 2:
                continue
            th = math.atan2(y[inner] - cy, x[inner] - cx)
            k, dk = -1, tol
            for j in range(na):
                d = abs((th - angles[j] + math.pi) % (2.0 * math.pi) - math.pi)
                if d < dk:
                    k, dk = j, d
            if k < 0:
                continue
            step = 1 if part == 0 else -1
            first = lo if part == 0 else hi - 1
            keep = _turn_start(x, y, h, first, step, hi - lo, max_rate, span)
            for q in range(hi - lo):
                i = first + step * q
                if pid[i] < 0:
                    arm[i], pid[i], dirn[i] = k, npart, 1 if part == 0 else -1
                    prof[i] = q < keep
            npart += 1
    return arm, pid, dirn, prof


def bend_profile(s, phi, pid, s_in: float, bin_m: float, min_parts: int = 2):
    """(bin centres, median relative heading per bin) over the bins from ``s_in`` out that
    hold rows of at least ``min_parts`` trajectory parts; empty when fewer than two such
    bins. ``phi``: row heading minus the outward arm direction [rad], ``|phi|`` below
    ``_MAX_REL``."""
    ok = (s >= s_in) & (np.abs(phi) < _MAX_REL)
    if ok.sum() < 2:
        return np.zeros(0), np.zeros(0)
    b = np.floor((s[ok] - s_in) / bin_m).astype(np.int64)
    ph, pp = phi[ok], pid[ok]
    centres, med = [], []
    for k in np.unique(b):
        m = b == k
        if np.unique(pp[m]).size >= min_parts:
            centres.append(s_in + (k + 0.5) * bin_m)
            med.append(float(np.median(ph[m])))
    if len(centres) < 3:
        return np.zeros(0), np.zeros(0)
    med = np.asarray(med)
    # three-bin running median: one bin of another road's or a turning vehicle's rows
    # does not make a bend
    sm = np.array([np.median(med[max(0, i - 1):i + 2]) for i in range(len(med))])
    if np.max(np.abs(np.diff(sm))) > _MAX_JUMP:
        return np.zeros(0), np.zeros(0)       # not one smooth road direction: no bend
    return np.asarray(centres), sm


def unbend(px, py, ph, q0, beta0, centres, dphi, reach: float):
    """Rows ``(px, py, ph)`` of one arm direction mapped from the bent axis to the straight
    one: the axis starts at ``q0`` in direction ``beta0`` and turns by ``dphi`` (at arc
    lengths ``centres - centres[0]``, linear between, held beyond); each row keeps its arc
    length and signed normal distance to the axis, on the straight line instead, and its
    heading turns back by the axis's turn at its foot point. Rows before ``q0`` stay."""
    tau = np.arange(0.0, reach + _STEP, _STEP)
    turn = np.interp(tau, centres - centres[0], dphi, left=0.0)
    beta = beta0 + turn
    # axis points: cumulative midpoint rule over the heading profile
    bm = np.r_[beta[0], 0.5 * (beta[1:] + beta[:-1])]
    ax = q0[0] + np.cumsum(np.r_[0.0, _STEP * np.cos(bm[1:])])
    ay = q0[1] + np.cumsum(np.r_[0.0, _STEP * np.sin(bm[1:])])
    tx, ty = np.cos(beta), np.sin(beta)
    _, i = cKDTree(np.column_stack([ax, ay])).query(np.column_stack([px, py]))
    dx, dy = px - ax[i], py - ay[i]
    t = tau[i] + dx * tx[i] + dy * ty[i]              # arc length of the foot point
    d = -dx * ty[i] + dy * tx[i]                      # signed normal distance (left +)
    u0, v0 = math.cos(beta0), math.sin(beta0)
    nx = q0[0] + t * u0 - d * v0
    ny = q0[1] + t * v0 + d * u0
    keep = t <= 0.0
    return (np.where(keep, px, nx), np.where(keep, py, ny),
            np.where(keep, ph, ph - turn[i]))


def straighten(x, y, hd, starts, ends, center, angles, r_in: float, reach: float,
               bin_m: float, min_deg: float):
    """The rows with every bent arm direction straightened (module docstring); returns
    ``(x, y, hd, bent)``, the inputs themselves when nothing bends (``bent`` = count of
    arm directions straightened). ``angles``: the current arm angles [rad]."""
    angles = np.asarray(angles, float)
    if min_deg <= 0 or angles.size == 0 or len(x) == 0:
        return x, y, hd, 0
    cx, cy = float(center[0]), float(center[1])
    arm, pid, dirn, prof = part_arms(x, y, hd, starts, ends, cx, cy, r_in * r_in, angles,
                                     math.radians(30.0), math.radians(_MAX_RATE_DEG), _SPAN)
    out = None
    bent = 0
    for k, a in enumerate(angles):
        for dr in (1, -1):
            sel = np.flatnonzero((arm == k) & (dirn == dr))
            if sel.size < 4:
                continue
            u = np.array([math.cos(a), math.sin(a)])
            s = (x[sel] - cx) * u[0] + (y[sel] - cy) * u[1]
            outward = hd[sel] + (math.pi if dr == 1 else 0.0)
            phi = (outward - a + math.pi) % (2 * math.pi) - math.pi
            p = prof[sel]
            centres, med = bend_profile(s[p], phi[p], pid[sel][p], r_in, bin_m)
            if centres.size == 0:
                continue
            dphi = med - med[0]
            if np.max(np.abs(dphi)) < math.radians(min_deg):
                continue
            if out is None:
                out = x.copy(), y.copy(), hd.copy()
            q0 = (cx + centres[0] * u[0], cy + centres[0] * u[1])
            # an entering row's heading points inward: the turn of the outward axis applies
            # with the same sign to the heading either way
            nx, ny, nh = unbend(x[sel], y[sel], hd[sel], q0, a + med[0], centres, dphi, reach)
            out[0][sel], out[1][sel], out[2][sel] = nx, ny, nh
            bent += 1
    if out is None:
        return x, y, hd, 0
    return out[0], out[1], out[2], bent
