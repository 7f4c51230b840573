"""Which radar rows a track takes, and which tracks follow one vehicle.

A vehicle returns 1-4 radar rows per scan spread over its body, so a row is compared with
a track's predicted position under the track's position covariance plus the spread of one
row about the vehicle's center, oriented along the track's velocity (round while it stands).
A row whose Doppler disagrees with the track's predicted radial speed is not its row
(neighbouring vehicles of a queue and of the opposite lane differ there first). Within that
gate, with ``doppler_assoc``, the Doppler innovation counts in the distance too (its
standard deviation ``doppler_tol`` / 3, the gate at 3 sigma): in the box, where the rows of
two vehicles that cross fall in both gates, a row goes to the track whose radial speed it
shows. Position alone let such tracks swap vehicles and draw turns nobody drove, the more
so once the Doppler update ties a track's velocity to the rows it took
(docs/real_junctions.md, "Doppler").
"""

from __future__ import annotations

import numpy as np

from .config import TrackerConfig

__all__ = ['body_cov', 'gate_distance', 'duplicates']

#: ``doppler_tol`` is this many standard deviations of a row's Doppler innovation
#: (``doppler_assoc``: the innovation's weight in the distance)
DOPPLER_TOL_SIGMAS = 3.0


def body_cov(u: np.ndarray, cfg: TrackerConfig) -> np.ndarray:
    """(n, 2, 2) covariance of one row about a vehicle heading along unit ``u`` (a zero
    ``u``: a standing vehicle, heading unknown, round)."""
    sl, sw = cfg.body_along_m, cfg.body_across_m
    along = np.einsum('ni,nj->nij', u, u)
    oriented = sl**2 * along + sw**2 * (np.eye(2)[None] - along)
    round_ = 0.5 * (sl**2 + sw**2) * np.eye(2)[None]
    return np.where((np.linalg.norm(u, axis=1) < 0.5)[:, None, None], round_, oriented)


def _headings(X: np.ndarray) -> np.ndarray:
    v = X[:, 2:]
    sp = np.linalg.norm(v, axis=1, keepdims=True)
    return np.where(sp > 0.5, v / np.maximum(sp, 1e-9), 0.0)


def gate_distance(X: np.ndarray, P: np.ndarray, xy: np.ndarray, cfg: TrackerConfig,
                  doppler: np.ndarray | None = None, los: np.ndarray | None = None) -> np.ndarray:
    """(tracks, rows) Mahalanobis distance of rows ``xy`` from the predicted tracks (states
    ``X``, covariances ``P``) in gates (``gate_sigma``); inf where a row's ``doppler`` is
    more than ``doppler_tol`` from the track's velocity along the row's line of sight ``los``,
    and with ``doppler_assoc`` that difference joins the distance in units of
    ``doppler_tol`` / 3."""
    S = P[:, :2, :2] + body_cov(_headings(X), cfg)
    a, b, c = S[:, 0, 0, None], 0.5 * (S[:, 0, 1] + S[:, 1, 0])[:, None], S[:, 1, 1, None]
    ex = xy[None, :, 0] - X[:, 0, None]
    ey = xy[None, :, 1] - X[:, 1, None]
    # dx' S^-1 dx with the 2 x 2 inverse in closed form
    d = np.sqrt((c * ex * ex - 2.0 * b * ex * ey + a * ey * ey) / (a * c - b * b)) / cfg.gate_sigma
    if doppler is not None:
        e = np.abs(X[:, 2:] @ los.T - doppler[None])
        if cfg.doppler_assoc:               # a row without a Doppler: position alone
            d = np.hypot(d, DOPPLER_TOL_SIGMAS * np.nan_to_num(e) / (cfg.doppler_tol * cfg.gate_sigma))
        d[e > cfg.doppler_tol] = np.inf
    return d


def duplicates(X: np.ndarray, P: np.ndarray, hits: np.ndarray, cfg: TrackerConfig) -> np.ndarray:
    """Indices of tracks that follow a vehicle another track with more updates follows:
    within ``merge_gates`` of it and velocities within ``merge_speed``."""
    if len(X) < 2 or cfg.merge_gates <= 0:
        return np.zeros(0, np.int64)
    d = gate_distance(X, P, X[:, :2], cfg)
    dv = np.linalg.norm(X[:, None, 2:] - X[None, :, 2:], axis=2)
    np.fill_diagonal(d, np.inf)
    gone: set[int] = set()
    for i, j in zip(*np.nonzero((d <= cfg.merge_gates) & (dv <= cfg.merge_speed))):
        if i not in gone and j not in gone:
            gone.add(int(i) if hits[i] < hits[j] else int(j))
    return np.array(sorted(gone), np.int64)
