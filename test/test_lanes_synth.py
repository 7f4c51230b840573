"""Small synthetic intersections for the lane-course tests (until/besides the simulator).

``synth_case(seed)`` builds a topology, ground-truth center lines (straight lanes from
the stop line outward, cubic Hermite connectors between them) and noisy tracked
trajectories along them. Its own tests check the generator is sane.
"""

from __future__ import annotations

import math

import numpy as np

from intersection_estimator.lanes.config import LaneConfig
from intersection_estimator.lanes.init import stop_distances
from intersection_estimator.model import ENTERING, LEAVING, Arm, Intersection
from intersection_estimator.observations import Detections


def hermite(p0, t0, p1, t1, n=40):
    s = np.linspace(0, 1, n)[:, None]
    k = np.linalg.norm(p1 - p0)
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * p0 + h10 * k * t0 + h01 * p1 + h11 * k * t1


def synth_case(seed=0, n_arms=4, lanes=(2, 2), per_lane=4, noise=1.0, length=50.0, step=1.5):
    rng = np.random.default_rng(seed)
    base = rng.uniform(-math.pi, math.pi)
    angles = base + np.arange(n_arms) * 2 * math.pi / n_arms + rng.uniform(-0.2, 0.2, n_arms)
    arms = [Arm(angle=float((a + math.pi) % (2 * math.pi) - math.pi), gap=float(rng.uniform(0, 2)),
                lanes_in=lanes[0], lanes_out=lanes[1], lane_width=3.5) for a in angles]
    topo = Intersection(center=rng.uniform(-5, 5, 2), arms=arms)
    stops = stop_distances(topo, LaneConfig())
    gt = {}
    for ai, a in enumerate(topo.arms):
        for d in (ENTERING, LEAVING):
            for k, off in enumerate(a.lane_offsets(d)):
                s = np.linspace(stops[ai], stops[ai] + length, 30)
                if d == ENTERING:
                    s = s[::-1]
                gt[(ai, d, k)] = topo.center + s[:, None] * a.direction + off * a.normal
    pts, ids, ts = [], [], []
    tid = 0
    conns = {}
    for (ai, d, k), line in list(gt.items()):
        if d != ENTERING:
            continue
        for _ in range(per_lane):
            bj = int(rng.integers(len(topo.arms)))
            if bj == ai:
                bj = (ai + 1) % len(topo.arms)
            j = int(rng.integers(topo.arms[bj].lanes_out))
            out = gt[(bj, LEAVING, j)]
            t0 = line[-1] - line[-2]
            t1 = out[1] - out[0]
            conn = hermite(line[-1], t0 / np.linalg.norm(t0), out[0], t1 / np.linalg.norm(t1))
            conns[(ai, k, bj, j)] = conn
            path = np.concatenate([line, conn[1:], out[1:]])
            seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
            s = np.concatenate([[0], np.cumsum(seg)])
            q = np.arange(rng.uniform(0, step), s[-1], step)
            xy = np.stack([np.interp(q, s, path[:, 0]), np.interp(q, s, path[:, 1])], 1)
            xy += rng.normal(0, noise, xy.shape)
            pts.append(xy)
            ids.append(np.full(len(xy), tid))
            ts.append(q / 10.0)
            tid += 1
    clutter = topo.center + rng.uniform(-60, 60, (50, 2))
    dets = Detections.make(np.concatenate(pts + [clutter]), np.concatenate(ts + [np.zeros(50)]),
                           track_id=np.concatenate(ids + [np.full(50, -1)]))
    return topo, gt, conns, dets


def test_synth_case_has_tracks_and_clutter():
    topo, gt, conns, dets = synth_case(1)
    assert dets.has_tracks and (dets.track_id == -1).sum() == 50
    assert len(gt) == topo.n_lanes and conns
