"""Likelihood P(Z|I) = prod_i P(z_i|I)^{w_i} of the topology model (paper §II-C2).

Per observation ``z_i = (p, d)`` or ``(p, o)`` the closest lane of the same driving
direction is found and scored with ``N(d_perp; sigma_perp) * N(d_angle; sigma_angle)``
(the angle term only for observations with an orientation ``o``). Deviations from the
paper's formula, each for a reason:

* the angle term is von Mises, ``exp(-(1 - cos d_angle) / sigma^2)``, the circular normal
  (equal to the normal for small angles, no ``acos`` in the inner loop).

* max over lanes (the paper's text: "we determine the closest lane") or, optionally,
  the paper's sum over lanes (eq. for P(z_i|I)); both with the lane normalisation below.
* robust clutter floor: ``log(density + floor)`` -- a mixture with a uniform outlier
  density, so false detections and turning vehicles inside the intersection box cannot
  dominate. The density is unnormalised (peak 1) so ``floor`` reads as "an outlier is as
  likely as an inlier at ``sqrt(-2 ln floor)`` sigmas".
* an arm's axis may bend once (beyond the paper, :mod:`.arm_bend`): beyond the kink's
  bisector an observation is measured in the outer piece's frame.
* lanes are rays from the center (paper §II-B): an observation behind the ray start
  (``s < 0`` along the arm) is scored with its Euclidean distance to the start, so one arm
  cannot explain traffic on the opposite side of the intersection.
* with an orientation the direction is decided per arm: entering iff ``<o, u_a> < 0``;
  this is independent of the current center estimate.
* lane normalisation (optional, default on): the lane of an arm and direction is a
  uniform choice among its ``n`` lanes, so the density is divided by ``n``. With the max
  alone an empty extra lane costs only its prior; with ``1/n`` it costs every observation
  of that arm and direction ``log((n+1)/n)`` -- lanes must be paid for by data.
* observation weights ``w_i`` (voxel counts, optionally tempered) multiply the log.

Compiled here: :func:`arm_column` (one arm's column of per-observation best densities,
in two passes: a branch-free energy pass that vectorises, then the exponential only below
the cut) and :func:`combine`. The sampler (:mod:`.mcmc`) keeps the columns of the current
state and recomputes only the arm a move changed.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import operator

import numpy as np
from numba import njit

from .arm_bend import unbend
from .state import (ANG, BEND, BENDAT, GAP, HDR, MAXA, NIN, NOUT, P_D2_CUT, P_FLOOR,
                    P_LANE_NORM, P_LANE_SUM, P_TRAFFIC, STRIDE, WID, arm_origin)

__all__ = ['ObservationSet', 'log_likelihood', 'arm_frame', 'arm_column', 'arm_column_into',
           'all_columns', 'all_columns_into', 'combine', 'full_loglik']

FIELDS = ('x', 'y', 'hx', 'hy', 'has_o', 'd', 'w', 'sigma', 'sigma_ang', 'passages')


@dataclass
class ObservationSet:
    """Preprocessed observations (paper §II-A output), struct of arrays.

    x, y: mean position; hx, hy: unit orientation (0 if none); has_o: orientation known;
    d: driving direction relative to the center (+1 entering, -1 leaving), used when
    there is no orientation (0: unknown, e.g. radar seeing a vehicle cross its line of
    sight -- the side of the arm's median then decides); w: weight (voxel count or 1 per trajectory part);
    sigma: orthogonal-distance sigma [m] (a trajectory mean is far more precise than a
    single detection); sigma_ang: angle sigma [rad] (heading of a track vs. a local
    principal direction of radar points); passages: the vehicle passages the observation
    stands for (1 per trajectory part; a voxel's detections per passage; default ``w``),
    the evidence unit of ``TopologyConfig.min_arm_support``.
    """

    x: np.ndarray
    y: np.ndarray
    hx: np.ndarray
    hy: np.ndarray
    has_o: np.ndarray
    d: np.ndarray
    w: np.ndarray
    sigma: np.ndarray
    sigma_ang: np.ndarray
    passages: np.ndarray | None = None

    def __post_init__(self):
        if self.passages is None:
            self.passages = np.array(self.w, dtype=np.float64, copy=True)

    def __len__(self) -> int:
        return len(self.x)

    @classmethod
    def empty(cls) -> 'ObservationSet':
        z = np.zeros(0)
        return cls(z, z, z, z, np.zeros(0, np.bool_), z, z, z, z, z)

    @classmethod
    def concat(cls, parts) -> 'ObservationSet':
        parts = [p for p in parts if p is not None and len(p)]
        if not parts:
            return cls.empty()
        return cls(*[np.ascontiguousarray(np.concatenate([getattr(p, f) for p in parts]))
                     for f in FIELDS])

    @property
    def xy(self) -> np.ndarray:
        return np.stack([self.x, self.y], axis=1)

    def subset(self, keep) -> 'ObservationSet':
        return ObservationSet(*[np.ascontiguousarray(getattr(self, f)[keep]) for f in FIELDS])

    def kernel_args(self):
        """(x, y, hx, hy, has_o, d, 0.5/sigma^2, 0.5/sigma_ang^2, w) for the kernels; made
        once (the sampler asks for them on every call; the arrays are not changed in place)."""
        key = (self.x, self.y, self.hx, self.hy, self.has_o, self.d, self.sigma,
               self.sigma_ang, self.w)
        cached = self.__dict__.get('_args')
        if cached is None or not all(map(operator.is_, cached[0], key)):
            cached = key, key[:6] + (0.5 / self.sigma ** 2, 0.5 / self.sigma_ang ** 2, self.w)
            self.__dict__['_args'] = cached
        return cached[1]


def log_likelihood(S: np.ndarray, obs: ObservationSet, P: np.ndarray) -> float:
    """Compiled log P(Z|I) of the packed state ``S`` (full evaluation)."""
    C = np.zeros((MAXA, len(obs)))
    return float(full_loglik(S, P, *obs.kernel_args(), C))


@njit(cache=True, fastmath=True, inline='always')
def arm_frame(i, cx, cy, ux, uy, ts, ox, oy, hx, hy, has_o, dcls, isa, at, cb, sb):
    """Observation ``i`` relative to an arm through (cx, cy) with direction (ux, uy),
    bent by ``beta`` (``cb, sb = cos, sin``; ``sb = 0``: straight) at ``at``
    (:func:`.arm_bend.unbend`): along-arm ``s``, lateral ``t``, direction ``d`` (+1
    entering) and angle energy ``e``. With an orientation the direction is arm-local
    (entering iff <o, u_a> < 0) and ``e = 2(1 - |cos|) / sigma^2`` (von Mises ~ angle^2);
    without, the Doppler class, and for an unknown class (0) the side of the median
    decides."""
    px = ox[i] - cx
    py = oy[i] - cy
    s = px * ux + py * uy
    t = py * ux - px * uy
    c = hx[i] * ux + hy[i] * uy
    if sb != 0.0:
        s, t, c = unbend(s, t, c, hy[i] * ux - hx[i] * uy, at, cb, sb)
    e = 0.0
    if has_o[i]:
        d = 1.0 if c < 0.0 else -1.0
        e = isa[i] * 2.0 * (1.0 - abs(c))
    else:
        d = dcls[i]
        if d == 0.0:
            d = 1.0 if t * ts > 0.0 else -1.0
    return s, t, d, e


@njit(cache=True, fastmath=True, inline='always')
def _arm_geometry(S, k, P):
    """Arm ``k`` of state ``S`` for the likelihood: axis start (the center, moved by the
    arm's axis offset), unit direction, half gap, lane counts and width, traffic side,
    lane-count normalisations (entering, leaving), the bend's place and cos / sin."""
    i0 = HDR + k * STRIDE
    a = S[i0 + ANG]
    nin = S[i0 + NIN]
    nout = S[i0 + NOUT]
    ux = math.cos(a)
    uy = math.sin(a)
    cx, cy = arm_origin(S, k, ux, uy)
    b = S[i0 + BEND]
    return (cx, cy, ux, uy, 0.5 * S[i0 + GAP], nin, nout, S[i0 + WID],
            P[P_TRAFFIC], nin ** -P[P_LANE_NORM], nout ** -P[P_LANE_NORM],
            S[i0 + BENDAT], math.cos(b), math.sin(b))


@njit(cache=True, fastmath=True)
def arm_column(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, out):
    """Unnormalised density of every observation under its best lane of arm ``k``.

    Paper eq. for P(z_i|I): closest lane with the same driving direction, Gaussian in the
    orthogonal distance (or, with ``P_LANE_SUM``, the sum over the lanes of that direction:
    the mixture of paper eq. for P(z_i|I)) and (with orientation) von Mises in the angle (``2(1 - cos)`` in
    place of the squared angle: the circular normal, no ``acos``), divided by (number of
    lanes of that direction) ** ``P_LANE_NORM``. Lanes are rays from the
    center; behind the ray start the Euclidean distance to the start is used. With an
    orientation the direction is arm-local (entering iff <o, u_a> < 0). Scratch made here
    (:func:`arm_column_into` takes it from the caller).
    """
    n = ox.shape[0]
    arm_column_into(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, out, np.empty(n))


@njit(cache=True, fastmath=True, inline='always')
def _closest_lane(s, t, d, e, hg, nin, nout, w, ts, isp, inv_n_in, inv_n_out):
    """(energy, lane-count normalisation) of an observation at along-arm ``s``, lateral
    ``t``, direction ``d``, angle energy ``e`` under its closest lane of that direction
    (behind the ray start: the distance to the start)."""
    nl = nin if d > 0.0 else nout
    q = d * ts * t - hg
    dl = q - (min(max(math.floor(q / w), 0.0), nl - 1.0) + 0.5) * w
    sn = min(s, 0.0)
    return e + isp * (sn * sn + dl * dl), (inv_n_in if d > 0.0 else inv_n_out)


@njit(cache=True, fastmath=True, inline='always')
def _straight_energies(cx, cy, ux, uy, hg, nin, nout, w, ts, inv_n_in, inv_n_out,
                       ox, oy, hx, hy, has_o, dcls, isp, isa, out, energy):
    """First pass of :func:`arm_column_into` on a straight arm: per observation the energy
    of its closest lane (``energy``) and the lane-count normalisation (``out``)."""
    for i in range(ox.shape[0]):
        px = ox[i] - cx
        py = oy[i] - cy
        s = px * ux + py * uy
        t = py * ux - px * uy
        c = hx[i] * ux + hy[i] * uy
        side = 1.0 if t * ts > 0.0 else -1.0
        dd = dcls[i] if dcls[i] != 0.0 else side
        d = (1.0 if c < 0.0 else -1.0) if has_o[i] else dd
        e = isa[i] * 2.0 * (1.0 - abs(c)) if has_o[i] else 0.0
        energy[i], out[i] = _closest_lane(s, t, d, e, hg, nin, nout, w, ts, isp[i],
                                          inv_n_in, inv_n_out)


@njit(cache=True, fastmath=True, inline='always')
def _bent_energies(cx, cy, ux, uy, hg, nin, nout, w, ts, inv_n_in, inv_n_out, at, cb, sb,
                   ox, oy, hx, hy, has_o, dcls, isp, isa, out, energy):
    """:func:`_straight_energies` on an arm that bends (:func:`.arm_bend.unbend`)."""
    for i in range(ox.shape[0]):
        s, t, d, e = arm_frame(i, cx, cy, ux, uy, ts, ox, oy, hx, hy, has_o, dcls, isa,
                               at, cb, sb)
        energy[i], out[i] = _closest_lane(s, t, d, e, hg, nin, nout, w, ts, isp[i],
                                          inv_n_in, inv_n_out)


@njit(cache=True, fastmath=True)
def arm_column_into(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, out, energy):
    """:func:`arm_column` with the caller's scratch ``energy`` (one per observation): no
    allocation, for the sampler's loop. Two passes: the energy of the closest lane and the
    lane-count normalisation (branch-free, vectorises); the exponential only below the cut."""
    if P[P_LANE_SUM] > 0.0:
        _arm_column_sum(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, out)
        return
    cx, cy, ux, uy, hg, nin, nout, w, ts, inv_n_in, inv_n_out, at, cb, sb = _arm_geometry(S, k, P)
    if sb != 0.0:
        _bent_energies(cx, cy, ux, uy, hg, nin, nout, w, ts, inv_n_in, inv_n_out, at, cb, sb,
                       ox, oy, hx, hy, has_o, dcls, isp, isa, out, energy)
    else:
        _straight_energies(cx, cy, ux, uy, hg, nin, nout, w, ts, inv_n_in, inv_n_out,
                           ox, oy, hx, hy, has_o, dcls, isp, isa, out, energy)
    n = ox.shape[0]
    cut = P[P_D2_CUT]
    for i in range(n):
        out[i] = out[i] * math.exp(-energy[i]) if energy[i] < cut else 0.0


@njit(cache=True, fastmath=True)
def _arm_column_sum(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, out):
    """:func:`arm_column` with the sum over the lanes of that direction (``P_LANE_SUM``)."""
    cx, cy, ux, uy, hg, nin, nout, w, ts, inv_n_in, inv_n_out, at, cb, sb = _arm_geometry(S, k, P)
    cut = P[P_D2_CUT]
    for i in range(ox.shape[0]):
        s, t, d, e = arm_frame(i, cx, cy, ux, uy, ts, ox, oy, hx, hy, has_o, dcls, isa,
                               at, cb, sb)
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
    """Every arm's column of ``S`` into ``C`` (:func:`arm_column`)."""
    n = ox.shape[0]
    all_columns_into(S, P, ox, oy, hx, hy, has_o, dcls, isp, isa, C, np.empty(n))


@njit(cache=True, fastmath=True)
def all_columns_into(S, P, ox, oy, hx, hy, has_o, dcls, isp, isa, C, energy):
    """:func:`all_columns` with the caller's scratch (:func:`arm_column_into`)."""
    for k in range(int(S[2])):
        arm_column_into(S, k, P, ox, oy, hx, hy, has_o, dcls, isp, isa, C[k], energy)


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
