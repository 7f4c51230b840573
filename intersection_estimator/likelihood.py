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

Compiled kernels: :func:`_kernels.arm_column` (one arm's column of per-observation best
densities) and :func:`_kernels.combine`. The sampler keeps the columns of the current
state and recomputes only the arm a move changed.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import operator

import numpy as np

from . import _kernels as K

__all__ = ['ObservationSet', 'log_likelihood', 'log_likelihood_reference']

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
    C = np.zeros((K.MAXA, len(obs)))
    return float(K.full_loglik(S, P, *obs.kernel_args(), C))


def log_likelihood_reference(S: np.ndarray, obs: ObservationSet, P: np.ndarray) -> float:
    """Plain numpy log P(Z|I), written independently of the kernels (for tests)."""
    n = int(S[2])
    if len(obs) == 0:
        return 0.0
    p = np.stack([obs.x - S[0], obs.y - S[1]], axis=1)
    best = np.zeros(len(obs))
    for k in range(n):
        ang, gap, nin, nout, w = S[K.HDR + k * K.STRIDE: K.HDR + (k + 1) * K.STRIDE]
        u = np.array([math.cos(ang), math.sin(ang)])
        nrm = np.array([-u[1], u[0]])
        s = p @ u
        t = p @ nrm
        dot = obs.hx * u[0] + obs.hy * u[1]
        d_side = np.where(t * P[K.P_TRAFFIC] > 0, 1.0, -1.0)    # unknown direction (d == 0)
        d = np.where(obs.has_o, np.where(dot < 0, 1.0, -1.0), np.where(obs.d == 0, d_side, obs.d))
        ang2 = np.where(obs.has_o, 2.0 * (1.0 - np.abs(dot)), 0.0)    # von Mises
        dens = np.zeros(len(obs))
        for direction, nl in ((1.0, int(nin)), (-1.0, int(nout))):
            offs = direction * P[K.P_TRAFFIC] * (0.5 * gap + (np.arange(nl) + 0.5) * w)
            dls = np.abs(t[:, None] - offs[None, :])
            ea = 0.5 * ang2 / obs.sigma_ang ** 2 + 0.5 * np.where(s < 0, s ** 2, 0.0) / obs.sigma ** 2
            e_all = ea[:, None] + 0.5 * dls ** 2 / obs.sigma[:, None] ** 2
            e = e_all.min(axis=1)
            if P[K.P_LANE_SUM] > 0:
                parts = np.where(e_all < P[K.P_D2_CUT], np.exp(-e_all), 0.0).sum(axis=1)
                val = np.where(e < P[K.P_D2_CUT], parts, 0.0)
            else:
                val = np.where(e < P[K.P_D2_CUT], np.exp(-e), 0.0)
            val = val / float(nl) ** P[K.P_LANE_NORM]
            dens = np.where(d == direction, val, dens)
        best = np.maximum(best, dens)
    return float(np.sum(obs.w * np.log(best + P[K.P_FLOOR])))
