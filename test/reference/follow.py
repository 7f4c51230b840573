"""Reference of the compiled normal equations of :func:`intersection_estimator.lanes.follow.fit_offset`:
the scipy design matrix and dense products it replaced (now ``spline._data``)."""

from __future__ import annotations

import numpy as np
from scipy.interpolate import BSpline


def normal_reference(s, r, w, lo, hi, knots):
    """``(B'WB, B'Wr)`` from ``BSpline.design_matrix`` (the code before the kernel)."""
    B = BSpline.design_matrix(np.clip(s, lo, hi), knots, 3).toarray()
    return B.T @ (w[:, None] * B), B.T @ (w * r)
