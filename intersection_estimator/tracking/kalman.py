"""Constant-velocity Kalman filter and Rauch-Tung-Striebel smoother of the radar tracker.

State ``x = (px, py, vx, vy)``; white acceleration of density ``q`` (Bar-Shalom, Li and
Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001, §6.3.2);
a measurement is the mean position of the rows a track took in one scan.
"""

from __future__ import annotations

import numpy as np

__all__ = ['transition', 'predict', 'update', 'rts']

_H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])


def transition(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """(F, Q) of the constant-velocity model over ``dt`` seconds."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    a, b, c = dt**3 / 3, dt**2 / 2, dt
    Q = q * np.array([[a, 0, b, 0], [0, a, 0, b], [b, 0, c, 0], [0, b, 0, c]])
    return F, Q


def predict(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray):
    return F @ x, F @ P @ F.T + Q


def update(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray):
    """Kalman update with a position measurement ``z`` of covariance ``R``."""
    K = P[:, :2] @ np.linalg.inv(P[:2, :2] + R)
    return x + K @ (z - x[:2]), (np.eye(4) - K @ _H) @ P


def rts(t: np.ndarray, xp: np.ndarray, Pp: np.ndarray, xf: np.ndarray, Pf: np.ndarray,
        q: float) -> np.ndarray:
    """Smoothed states of one track from its predicted (``xp``, ``Pp``) and filtered
    (``xf``, ``Pf``) states at the update times ``t`` (Rauch, Tung and Striebel 1965)."""
    xs, Ps = xf.copy(), Pf.copy()
    for k in range(len(t) - 2, -1, -1):
        F, _ = transition(t[k + 1] - t[k], q)
        C = Ps[k] @ F.T @ np.linalg.inv(Pp[k + 1])
        xs[k] = xs[k] + C @ (xs[k + 1] - xp[k + 1])
        Ps[k] = Ps[k] + C @ (Ps[k + 1] - Pp[k + 1]) @ C.T
    return xs
