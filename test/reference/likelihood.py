"""Reference of the compiled topology likelihood (paper §II-C2)."""

from __future__ import annotations

import math

import numpy as np

from intersection_estimator.topology.likelihood import ObservationSet
from intersection_estimator.topology.state import (HDR, P_D2_CUT, P_FLOOR, P_LANE_NORM,
                                                   P_LANE_SUM, P_TRAFFIC, STRIDE)


def log_likelihood_reference(S: np.ndarray, obs: ObservationSet, P: np.ndarray) -> float:
    """Plain numpy log P(Z|I), written independently of the kernels (for tests)."""
    n = int(S[2])
    if len(obs) == 0:
        return 0.0
    p = np.stack([obs.x - S[0], obs.y - S[1]], axis=1)
    best = np.zeros(len(obs))
    for k in range(n):
        ang, gap, nin, nout, w, off, bend, at = S[HDR + k * STRIDE: HDR + (k + 1) * STRIDE]
        u = np.array([math.cos(ang), math.sin(ang)])
        nrm = np.array([-u[1], u[0]])
        s = p @ u
        t = p @ nrm - off        # lateral position from the arm's (offset) axis
        o = np.stack([obs.hx, obs.hy], axis=1)
        dot = o @ u
        if bend != 0.0:          # beyond the kink's bisector: the outer piece's frame
            rot = np.array([[math.cos(bend), -math.sin(bend)], [math.sin(bend), math.cos(bend)]])
            u2, n2 = rot @ u, rot @ nrm
            q = p - (off * nrm + at * u)
            out = q @ (u + u2) > 0
            s = np.where(out, at + q @ u2, s)
            t = np.where(out, q @ n2, t)
            dot = np.where(out, o @ u2, dot)
        d_side = np.where(t * P[P_TRAFFIC] > 0, 1.0, -1.0)    # unknown direction (d == 0)
        d = np.where(obs.has_o, np.where(dot < 0, 1.0, -1.0), np.where(obs.d == 0, d_side, obs.d))
        ang2 = np.where(obs.has_o, 2.0 * (1.0 - np.abs(dot)), 0.0)    # von Mises
        dens = np.zeros(len(obs))
        for direction, nl in ((1.0, int(nin)), (-1.0, int(nout))):
            offs = direction * P[P_TRAFFIC] * (0.5 * gap + (np.arange(nl) + 0.5) * w)
            dls = np.abs(t[:, None] - offs[None, :])
            ea = 0.5 * ang2 / obs.sigma_ang ** 2 + 0.5 * np.where(s < 0, s ** 2, 0.0) / obs.sigma ** 2
            e_all = ea[:, None] + 0.5 * dls ** 2 / obs.sigma[:, None] ** 2
            e = e_all.min(axis=1)
            if P[P_LANE_SUM] > 0:
                parts = np.where(e_all < P[P_D2_CUT], np.exp(-e_all), 0.0).sum(axis=1)
                val = np.where(e < P[P_D2_CUT], parts, 0.0)
            else:
                val = np.where(e < P[P_D2_CUT], np.exp(-e), 0.0)
            val = val / float(nl) ** P[P_LANE_NORM]
            dens = np.where(d == direction, val, dens)
        best = np.maximum(best, dens)
    return float(np.sum(obs.w * np.log(best + P[P_FLOOR])))
