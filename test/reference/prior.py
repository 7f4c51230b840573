"""Reference of :func:`intersection_estimator.topology.prior.log_prior`."""

from __future__ import annotations

import math


def log_prior_reference(n_lanes_in, n_lanes_out, log_pa, log_pn, arm_const) -> float:
    """Plain-Python log P(I) (paper §II-C1)."""
    n = len(n_lanes_in)
    lp = log_pa[n] + math.lgamma(n + 1.0) + n * arm_const
    for a, b in zip(n_lanes_in, n_lanes_out):
        lp += log_pn[int(a)] + log_pn[int(b)]
    return float(lp)
