"""Tiny synthetic scenes for the topology tests (independent of the simulator).

Vehicles drive along the model's lane rays (model.py conventions): in on an entering
lane, a straight chord through the intersection box, out on a leaving lane of another
arm; every lane is used. Positions get Gaussian noise.
"""

from __future__ import annotations

import math

import numpy as np

from intersection_estimator.model import ENTERING, LEAVING, Arm, Intersection
from intersection_estimator.observations import Detections
from intersection_estimator.topology import PreprocessConfig, TopologyEstimator
from intersection_estimator.topology.config import Tables
from intersection_estimator.topology.mcmc import Posterior

#: The preprocessing settings these tests were written for (before PreprocessConfig was
#: derived from TopologyConfig, its defaults): 2 m square voxels, unscaled weights, no
#: near-center drop, whole trajectory parts.
LEGACY_PREPROCESS = PreprocessConfig(voxel_size=2.0, weight_scale=1.0, min_center_dist=0.0,
                                     part_outside=0.0)


def easy_intersection(n_arms: int = 4, lanes=((1, 1),) * 4, center=(5.0, -3.0),
                      angles_deg=None, gap: float = 0.0, width: float = 3.5) -> Intersection:
    if angles_deg is None:
        angles_deg = [-180 + 360 * k / n_arms + 10 for k in range(n_arms)]
    arms = [Arm(angle=math.radians(a), gap=gap, lanes_in=li, lanes_out=lo, lane_width=width)
            for a, (li, lo) in zip(angles_deg, lanes)]
    return Intersection(center=np.asarray(center, float), arms=arms)


def _lane_point(inter, arm, direction, k, s):
    off = float(arm.lane_offsets(direction, inter.traffic_side)[k])
    return inter.center + s * arm.direction + off * arm.normal


def trajectories(inter: Intersection, rng: np.random.Generator, per_lane: int = 2,
                 r0: float = 12.0, length: float = 60.0, step: float = 1.0):
    """List of (xy, heading) polylines, every entering and leaving lane covered."""
    arms = inter.arms
    outs = [(b, j) for b, arm in enumerate(arms) for j in range(arm.lanes_out)]
    rng.shuffle(outs)
    paths, oi = [], 0
    for a, arm in enumerate(arms):
        for k in range(arm.lanes_in):
            for _ in range(per_lane):
                b, j = outs[oi % len(outs)]
                oi += 1
                if b == a:
                    b, j = (b + 1) % len(arms), 0
                s_in = np.arange(length, r0, -step)
                p_in = np.array([_lane_point(inter, arm, ENTERING, k, s) for s in s_in])
                p_out = np.array([_lane_point(inter, arms[b], LEAVING, j, s)
                                  for s in np.arange(r0, length, step)])
                n_mid = max(2, int(np.hypot(*(p_out[0] - p_in[-1])) / step))
                f = np.linspace(0, 1, n_mid + 2)[1:-1, None]
                p_mid = p_in[-1] + f * (p_out[0] - p_in[-1])
                xy = np.concatenate([p_in, p_mid, p_out])
                d = np.gradient(xy, axis=0)
                paths.append((xy, np.arctan2(d[:, 1], d[:, 0])))
    return paths


def scene(inter: Intersection, mode: str, seed: int = 0, noise: float = 0.3,
          per_lane: int = 2, clutter: int = 0, speed: float = 10.0) -> Detections:
    """Detections of ``mode`` ('tracked' | 'raw' | 'heading') for ``inter``."""
    rng = np.random.default_rng(seed)
    paths = trajectories(inter, rng, per_lane)
    parts = []
    sensor = inter.center + 30.0 * inter.arms[0].direction + 1.75 * inter.arms[0].normal
    for tid, (xy, hd) in enumerate(paths):
        n = len(xy)
        p = xy + rng.normal(0, noise, (n, 2))
        t = np.arange(n) * 0.1
        if mode == 'tracked':
            parts.append(Detections.make(p, t, heading=hd, track_id=tid))
        elif mode == 'heading':
            parts.append(Detections.make(p, t, heading=hd))
        else:
            los = p - sensor
            los /= np.linalg.norm(los, axis=1, keepdims=True)
            dop = speed * (np.cos(hd) * los[:, 0] + np.sin(hd) * los[:, 1])
            parts.append(Detections.make(p, t, doppler=dop, sensor_xy=sensor, rcs=10.0))
    if clutter:
        r = 70.0 * np.sqrt(rng.uniform(size=clutter))
        phi = rng.uniform(0, 2 * math.pi, clutter)
        xy = inter.center + np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)
        if mode == 'raw':
            parts.append(Detections.make(xy, doppler=rng.normal(0, 0.1, clutter),
                                         sensor_xy=sensor, rcs=-5.0))
        elif mode == 'tracked':
            parts.append(Detections.make(xy, heading=rng.uniform(-math.pi, math.pi, clutter),
                                         track_id=10_000 + np.arange(clutter)))
        else:
            parts.append(Detections.make(xy, heading=rng.uniform(-math.pi, math.pi, clutter)))
    return Detections.concat(parts)


def same_topology(a: Intersection, b: Intersection | None, tol_deg: float = 10.0) -> bool:
    """Same arm count and, arms matched by angle, the same lane counts."""
    if b is None or len(a.arms) != len(b.arms):
        return False
    for x in a.arms:
        d = [abs((x.angle - y.angle + math.pi) % (2 * math.pi) - math.pi) for y in b.arms]
        y = b.arms[int(np.argmin(d))]
        if math.degrees(min(d)) > tol_deg or (x.lanes_in, x.lanes_out) != (y.lanes_in, y.lanes_out):
            return False
    return True


#: Three scenes the estimator, descent and support tests share.
EASY = [
    easy_intersection(4, lanes=((1, 1), (2, 1), (1, 2), (2, 2)), gap=0.5),
    easy_intersection(3, lanes=((1, 1), (2, 2), (1, 1)), angles_deg=[-100, 20, 150],
                      center=(-40.0, 25.0), width=3.25),
    easy_intersection(5, lanes=((1, 1), (1, 1), (2, 1), (1, 1), (1, 2)),
                      angles_deg=[-170, -100, -20, 50, 120]),
]


def tracked_posterior(cfg, gt: Intersection, seed: int = 3, per_lane: int = 2) -> Posterior:
    """The posterior of ``gt``'s tracked scene (``per_lane`` vehicles a lane, 10 clutter
    tracks) on the observations an estimator with ``cfg`` preprocesses around the truth's
    center."""
    est = TopologyEstimator(cfg, seed=0)
    est.set_observations(scene(gt, 'tracked', seed=seed, clutter=10, per_lane=per_lane))
    return Posterior(Tables(cfg), est.observations)
