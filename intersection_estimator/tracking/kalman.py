"""Constant-velocity Kalman filter and Rauch-Tung-Striebel smoother of the radar tracker.

State ``x = (px, py, vx, vy)``; white acceleration of density ``q`` (Bar-Shalom, Li and
Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001, §6.3.2);
a measurement is the mean position of the rows a track took in one scan and, where they
carry Doppler, their mean Doppler: the velocity along their mean line of sight
(:func:`update_radial`; linear in the state, since the mean of ``<v, los_i>`` is
``<v, mean los_i>``).
"""

from __future__ import annotations

from numba import njit
import numpy as np

__all__ = ['transition', 'predict', 'update', 'update_radial', 'rts']


def transition(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """(F, Q) of the constant-velocity model over ``dt`` seconds."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    a, b, c = dt**3 / 3, dt**2 / 2, dt
    Q = q * np.array([[a, 0, b, 0], [0, a, 0, b], [b, 0, c, 0], [0, b, 0, c]])
    return F, Q


def predict(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray):
    return F @ x, F @ P @ F.T + Q


@njit(cache=True)
def update(x: np.ndarray, P: np.ndarray, z: np.ndarray, r: float):
    """Kalman update with a position measurement ``z`` of covariance ``r`` I (the 2 x 2
    innovation covariance inverted in closed form: one scan's update is a few flops, so
    the call overhead of general routines was most of the tracker's time)."""
    a, b, d = P[0, 0] + r, P[0, 1], P[1, 1] + r
    det = a * d - b * P[1, 0]
    ia, ib, ic, id_ = d / det, -P[0, 1] / det, -P[1, 0] / det, a / det
    K = np.empty((4, 2))
    for i in range(4):
        K[i, 0] = P[i, 0] * ia + P[i, 1] * ic
        K[i, 1] = P[i, 0] * ib + P[i, 1] * id_
    e0, e1 = z[0] - x[0], z[1] - x[1]
    x2 = x + K[:, 0] * e0 + K[:, 1] * e1
    P2 = P - K[:, 0:1] * P[0:1, :] - K[:, 1:2] * P[1:2, :]
    return x2, P2


@njit(cache=True)
def update_radial(x: np.ndarray, P: np.ndarray, los: np.ndarray, dop: float, r: float):
    """Kalman update with a scalar measurement ``dop = <(vx, vy), los> + noise`` of
    variance ``r`` (a radar's Doppler, ego-motion compensated)."""
    ph = P[:, 2] * los[0] + P[:, 3] * los[1]             # P h^T
    s = ph[2] * los[0] + ph[3] * los[1] + r
    K = ph / s
    x2 = x + K * (dop - (x[2] * los[0] + x[3] * los[1]))
    P2 = P - np.outer(K, ph)
    return x2, P2


@njit(cache=True)
def rts(t: np.ndarray, xp: np.ndarray, Pp: np.ndarray, xf: np.ndarray, Pf: np.ndarray,
        q: float) -> np.ndarray:
    """Smoothed states of one track from its predicted (``xp``, ``Pp``) and filtered
    (``xf``, ``Pf``) states at the update times ``t`` (Rauch, Tung and Striebel 1965)."""
    xs, Ps = xf.copy(), Pf.copy()
    F = np.eye(4)
    for k in range(len(t) - 2, -1, -1):
        F[0, 2] = F[1, 3] = t[k + 1] - t[k]
        C = Ps[k] @ F.T @ np.linalg.inv(Pp[k + 1])
        xs[k] = xs[k] + C @ (xs[k + 1] - xp[k + 1])
        Ps[k] = Ps[k] + C @ (Ps[k + 1] - Pp[k + 1]) @ C.T
    return xs
