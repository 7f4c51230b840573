"""Simulated perception output in the fixed frame (paper §II-A inputs, §IV noise model).

Every sensor runs at ``rate_hz`` on the ego vehicle and sees vehicles within
``sensor_range`` of the sensor (360 deg, no occlusion; per scene raised by
:func:`scene_sensor_range` so that every arm is seen near the stop line). Modes:

* ``'tracked'`` -- one row per vehicle and cycle: position + N(0, position_noise) (white,
  or with ``track_noise_corr`` an AR(1) error along each track, as a tracker's output),
  heading, speed, persistent ``track_id`` (= the vehicle's index), label CAR. False
  detections are short-lived false *tracks*: static points uniform within
  ``clutter_radius`` of the center, random heading, lifetime ``false_track_cycles``
  cycles, ids from :data:`FALSE_TRACK_ID0` up (a tracker confirms clutter, too).
* ``'raw'`` -- radar: ``1 + Poisson(radar_points_per_vehicle)`` points spread over the
  vehicle body, position + N(0, position_noise), ``doppler`` = ego-motion-compensated
  radial velocity (positive = moving away from the sensor), ``rcs``, ``sensor_xy`` =
  radar position (ahead of the moving / stopping ego); clutter uniform within
  ``clutter_radius`` of the center with doppler ~ N(0, doppler_noise) and low rcs.
  No track id, no heading.
* ``'heading'`` -- lidar / camera objects: one row per vehicle and cycle with a noisy
  heading, no identity; false detections with a random heading.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

from ..model import wrap_angle
from ..observations import Detections
from .config import MODES, SimConfig

__all__ = ['FALSE_TRACK_ID0', 'CAR', 'sensor_rng', 'scene_sensor_range', 'simulate_detections']

FALSE_TRACK_ID0 = 1_000_000
CAR = 1  # Autoware label id


def sensor_rng(seed: int, mode: str, offset: int = 0) -> np.random.Generator:
    """Independent generator per (scenario seed, mode, offset)."""
    ss = np.random.SeedSequence(seed, spawn_key=(1 + MODES.index(mode), int(offset)))
    return np.random.default_rng(ss)


def scene_sensor_range(ego, lanelets, cfg: SimConfig) -> float:
    """Sensor range of one scene: ``cfg.sensor_range``, raised (with ``auto_sensor_range``)
    until the ego sensor, where the ego stops, sees the ``observed_zone`` metres next to
    the stop line of every entering and leaving lane plus 5 m, rounded up to 10 m.

    Stop lines of wide 5-arm intersections lie up to ~50 m from the center; from an ego
    stopped before one of them a fixed 100 m misses the far arms entirely.
    """
    if not cfg.auto_sensor_range:
        return float(cfg.sensor_range)
    stop_xy = ego.sensor_xy(cfg.sensor_mount)[-1]
    need = 0.0
    for ll in lanelets:
        if ll.kind not in ('entering', 'leaving'):
            continue
        c = ll.center if ll.kind == 'leaving' else ll.center[::-1]   # from the stop line out
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
        near = c[arc <= cfg.observed_zone]
        need = max(need, float(np.linalg.norm(near - stop_xy, axis=1).max()))
    return max(float(cfg.sensor_range), 10.0 * math.ceil((need + 5.0) / 10.0))


def _truth(tracks, rate):
    """All vehicle states on the cycle grid: cycle, id, xy, yaw, speed."""
    if not tracks:
        z = np.zeros(0)
        return np.zeros(0, int), np.zeros(0, int), np.zeros((0, 2)), z, z
    cyc = np.concatenate([np.rint(tr.t * rate).astype(int) for tr in tracks])
    vid = np.concatenate([np.full(len(tr.t), tr.id) for tr in tracks])
    xy = np.concatenate([tr.xy for tr in tracks])
    yaw = np.concatenate([tr.yaw for tr in tracks])
    sp = np.concatenate([tr.speed for tr in tracks])
    return cyc, vid, xy, yaw, sp


def _disk(rng, n, center, radius):
    r = radius * np.sqrt(rng.uniform(size=n))
    phi = rng.uniform(0.0, 2 * math.pi, size=n)
    return center + np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)


def _visible(xy, cyc, sensor_xy, rng_m):
    return np.linalg.norm(xy - sensor_xy[cyc], axis=1) <= rng_m


def track_error(white: np.ndarray, vid: np.ndarray, cyc: np.ndarray, rho: float) -> np.ndarray:
    """The white draws ``white`` (N(0, sigma) per row) turned into an AR(1) error along each
    vehicle's rows in cycle order, ``e_k = rho e_(k-1) + sqrt(1 - rho^2) w_k``, ``e_0 = w_0``:
    the same sigma per row, correlation ``rho^lag`` between rows of one track (``rho = 0``:
    ``white`` itself)."""
    if rho <= 0.0 or len(white) == 0:
        return white
    order = np.lexsort((cyc, vid))
    w = white[order].copy()
    gain = math.sqrt(1.0 - rho * rho)
    cuts = np.flatnonzero(np.r_[True, vid[order][1:] != vid[order][:-1], True])
    w[cuts[:-1]] /= gain                         # e_0 = w_0: the stationary start
    out = np.empty_like(white)
    for a, b in zip(cuts[:-1], cuts[1:]):
        out[order[a:b]] = lfilter([gain], [1.0, -rho], w[a:b], axis=0)
    return out


def _tracked(rng, truth, sens, center, cfg, n_cyc):  # noqa: ARG001 - common signature
    cyc, vid, xy, yaw, sp = truth
    hn = math.radians(cfg.heading_noise_deg)
    n = len(cyc)
    err = track_error(rng.normal(0, cfg.position_noise, (n, 2)), vid, cyc, cfg.track_noise_corr)
    det = dict(cyc=cyc, xy=xy + err,
               heading=wrap_angle(yaw + rng.normal(0, hn, n)),
               speed=np.maximum(sp + rng.normal(0, cfg.speed_noise, n), 0.0),
               track_id=vid, label=np.full(n, CAR))
    n_false = int(rng.poisson(cfg.false_tracks_per_s * n_cyc / cfg.rate_hz))
    life = rng.integers(cfg.false_track_cycles[0], cfg.false_track_cycles[1] + 1, n_false)
    start = rng.integers(0, n_cyc, n_false)
    pos = _disk(rng, n_false, center, cfg.clutter_radius)
    hdg = rng.uniform(-math.pi, math.pi, n_false)
    fsp = rng.uniform(0.0, 2.0, n_false)
    j = np.repeat(np.arange(n_false), life)
    fc = start[j] + (np.arange(len(j)) - np.repeat(np.cumsum(life) - life, life))
    m = len(j)
    false = dict(cyc=fc, xy=pos[j] + rng.normal(0, cfg.position_noise, (m, 2)),
                 heading=wrap_angle(hdg[j] + rng.normal(0, hn, m)), speed=fsp[j],
                 track_id=FALSE_TRACK_ID0 + j, label=np.zeros(m, int))
    return [det, false]


def _raw(rng, truth, sens, center, cfg, n_cyc):
    cyc, vid, xy, yaw, sp = truth
    k = 1 + rng.poisson(cfg.radar_points_per_vehicle, len(cyc))
    i = np.repeat(np.arange(len(cyc)), k)
    m = len(i)
    c, s = np.cos(yaw[i]), np.sin(yaw[i])
    lo = rng.uniform(-0.5, 0.5, (m, 2)) * np.asarray(cfg.vehicle_size)
    body = xy[i] + np.stack([c * lo[:, 0] - s * lo[:, 1], s * lo[:, 0] + c * lo[:, 1]], axis=1)
    los = body - sens[cyc[i]]
    los /= np.maximum(np.linalg.norm(los, axis=1, keepdims=True), 1e-6)
    dop = sp[i] * (c * los[:, 0] + s * los[:, 1]) + rng.normal(0, cfg.doppler_noise, m)
    det = dict(cyc=cyc[i], xy=body + rng.normal(0, cfg.position_noise, (m, 2)), doppler=dop,
               rcs=rng.normal(*cfg.rcs_vehicle, m), label=np.full(m, CAR))
    n_cl = int(rng.poisson(cfg.radar_clutter_per_cycle * n_cyc))
    clutter = dict(cyc=rng.integers(0, n_cyc, n_cl),
                   xy=_disk(rng, n_cl, center, cfg.clutter_radius),
                   doppler=rng.normal(0, cfg.doppler_noise, n_cl),
                   rcs=rng.normal(*cfg.rcs_clutter, n_cl), label=np.zeros(n_cl, int))
    return [det, clutter]


def _heading(rng, truth, sens, center, cfg, n_cyc):
    cyc, vid, xy, yaw, sp = truth
    n = len(cyc)
    hn = math.radians(cfg.heading_noise_deg)
    det = dict(cyc=cyc, xy=xy + rng.normal(0, cfg.position_noise, (n, 2)),
               heading=wrap_angle(yaw + rng.normal(0, hn, n)), label=np.full(n, CAR))
    n_f = int(rng.poisson(cfg.false_heading_per_cycle * n_cyc))
    false = dict(cyc=rng.integers(0, n_cyc, n_f), xy=_disk(rng, n_f, center, cfg.clutter_radius),
                 heading=rng.uniform(-math.pi, math.pi, n_f), label=np.zeros(n_f, int))
    return [det, false]


_MAKERS = {'tracked': _tracked, 'raw': _raw, 'heading': _heading}


def simulate_detections(rng: np.random.Generator, mode: str, tracks, ego, center,
                        cfg: SimConfig, sensor_range: float | None = None
                        ) -> tuple[Detections, np.ndarray]:
    """All detections of ``mode`` over the scenario, sorted by stamp; also their cycle index.

    Rows outside ``sensor_range`` (default ``cfg.sensor_range``; the scene's value from
    :func:`scene_sensor_range`) of the sensor on the ego at that cycle are dropped.
    """
    rng_m = float(cfg.sensor_range if sensor_range is None else sensor_range)
    if mode not in _MAKERS:
        raise ValueError(f'unknown mode {mode!r}, expected one of {MODES}')
    n_cyc = len(ego.t)
    sens = ego.sensor_xy(cfg.sensor_mount)
    parts = _MAKERS[mode](rng, _truth(tracks, cfg.rate_hz), sens, np.asarray(center), cfg, n_cyc)
    out, cycles = [], []
    for p in parts:
        cyc = np.asarray(p.pop('cyc'), int)
        ok = (cyc >= 0) & (cyc < n_cyc)
        ok[ok] = _visible(p['xy'][ok], cyc[ok], sens, rng_m)
        cols = {k: np.asarray(v)[ok] for k, v in p.items()}
        out.append(Detections.make(cols.pop('xy'), ego.t[cyc[ok]], sensor_xy=sens[cyc[ok]], **cols))
        cycles.append(cyc[ok])
    dets = Detections.concat(out)
    cyc = np.concatenate(cycles) if cycles else np.zeros(0, int)
    if len(dets) == 0:
        return dets, np.zeros(0, int)
    order = np.argsort(cyc, kind='stable')
    return dets.subset(order), cyc[order]
