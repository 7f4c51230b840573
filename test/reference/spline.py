"""Reference of the compiled connector fit (:mod:`intersection_estimator.lanes.spline`):
the scipy / numpy least squares it replaced (design matrix from ``scipy.interpolate``,
the stacked data and smoothness rows solved by ``numpy.linalg.lstsq``), one fit for fixed
parameters and one penalty."""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import BSpline

from intersection_estimator.lanes.spline import second_differences


def solve_reference(Q, u, knots, c0, t0, c1, t1, smooth):
    """Control points of one penalised fit (the numpy ``_solve`` the kernel replaced)."""
    n = len(knots) - 4
    B = BSpline.design_matrix(np.clip(u, 0.0, 1.0), knots, 3).toarray()
    inner = n - 4
    nz = 2 + 2 * inner
    A = np.zeros((n, 2, nz))
    b = np.zeros((n, 2))
    b[0], b[1], b[n - 2], b[n - 1] = c0, c0, c1, c1
    A[1, :, 0] = t0
    A[n - 2, :, 1] = -t1
    for j in range(inner):
        A[2 + j, 0, 2 + 2 * j] = 1.0
        A[2 + j, 1, 3 + 2 * j] = 1.0
    Md = np.einsum('mj,jdz->mdz', B, A).reshape(-1, nz)
    rd = (Q - B @ b).reshape(-1)
    D = second_differences(n)
    w = math.sqrt(smooth * len(Q) / max(n, 1))
    Ms = w * np.einsum('kj,jdz->kdz', D, A).reshape(-1, nz)
    rs = -w * (D @ b).reshape(-1)
    z, *_ = np.linalg.lstsq(np.vstack([Md, Ms]), np.concatenate([rd, rs]), rcond=None)
    return np.einsum('jdz,z->jd', A, z) + b
