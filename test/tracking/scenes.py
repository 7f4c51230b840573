"""Synthetic radar scans for the tracker tests: vehicles on given paths, rows over their
bodies with noise, Doppler along the line of sight, optional static clutter."""

from __future__ import annotations

import numpy as np

from intersection_estimator.observations import Detections

RATE = 10.0
SENSOR = np.array([0.0, -30.0])


def straight(p0, v, t0: float, t1: float):
    """A vehicle from ``p0`` with velocity ``v`` between ``t0`` and ``t1``: t -> (xy, v)."""
    p0, v = np.asarray(p0, float), np.asarray(v, float)

    def at(t):
        return (p0 + v * (t - t0), v) if t0 <= t <= t1 else None
    return at


def polyline(points, speed: float, t0: float):
    """A vehicle along the polyline ``points`` at ``speed`` from ``t0`` until its end."""
    p = np.asarray(points, float)
    seg = np.diff(p, axis=0)
    length = np.linalg.norm(seg, axis=1)
    cum = np.r_[0.0, np.cumsum(length)]

    def at(t):
        s = (t - t0) * speed
        if s < 0 or s > cum[-1]:
            return None
        k = min(int(np.searchsorted(cum, s, 'right')) - 1, len(length) - 1)
        u = seg[k] / length[k]
        return p[k] + u * (s - cum[k]), u * speed
    return at


def stop_and_go(p0, v, t_stop: float, t_go: float, t1: float, accel: float = 3.0):
    """Drives along ``v``, brakes at ``accel`` to stand at ``t_stop``, stands until
    ``t_go``, then speeds up at ``accel`` to its old speed, until ``t1``."""
    p0, v = np.asarray(p0, float), np.asarray(v, float)
    v0 = float(np.hypot(*v))
    u = v / v0
    grid = np.arange(0.0, t1 + 1e-9, 0.01)
    brake = np.clip((t_stop - grid) * accel, 0.0, v0)
    go = np.clip((grid - t_go) * accel, 0.0, v0)
    speed = np.where(grid < t_go, brake, go)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * 0.01)])

    def at(t):
        if t > t1:
            return None
        k = int(round(t / 0.01))
        return p0 + u * s[k], u * speed[k]
    return at


def scans(vehicles, t1: float, rng: np.random.Generator, clutter_per_scan: float = 0.0,
          noise: float = 0.5, body=(4.5, 1.8)) -> Detections:
    """Radar rows of ``vehicles`` (callables t -> (xy, v) or None) every 1 / RATE s to ``t1``."""
    xy, t, dop, rcs = [], [], [], []
    for k in range(int(t1 * RATE) + 1):
        tk = k / RATE
        for at in vehicles:
            s = at(tk)
            if s is None:
                continue
            p, v = s
            sp = float(np.hypot(*v))
            u = v / sp if sp > 0 else np.array([1.0, 0.0])
            m = 1 + rng.poisson(2.0)
            lo = rng.uniform(-0.5, 0.5, (m, 2)) * np.asarray(body)
            pts = p + lo[:, :1] * u + lo[:, 1:] * np.array([-u[1], u[0]]) + rng.normal(0, noise, (m, 2))
            los = pts - SENSOR
            los /= np.linalg.norm(los, axis=1, keepdims=True)
            xy.append(pts)
            t.append(np.full(m, tk))
            dop.append(los @ v + rng.normal(0, 0.1, m))
            rcs.append(np.full(m, 10.0))
        n = rng.poisson(clutter_per_scan)
        if n:
            xy.append(rng.uniform(-60, 60, (n, 2)))
            t.append(np.full(n, tk))
            dop.append(rng.normal(0, 0.1, n))
            rcs.append(np.full(n, 10.0))
    if not xy:
        return Detections.empty()
    xy = np.concatenate(xy)
    return Detections.make(xy, np.concatenate(t), doppler=np.concatenate(dop),
                           sensor_xy=np.broadcast_to(SENSOR, xy.shape), rcs=np.concatenate(rcs))
