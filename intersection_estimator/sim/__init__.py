"""ROS-free scenario simulator (paper §IV, Table I).

>>> sc = simulate_scenario(7)
>>> dets = sc.detections('tracked')          # Detections of the whole scenario
>>> for stamp, d in sc.frames('raw'): ...     # one Detections per sensor cycle

``simulate_scenario(seed, config)`` is deterministic: all randomness comes from
``numpy.random.SeedSequence(seed)`` (spawned children for geometry, traffic, ego;
:func:`.sensors.sensor_rng` for each detection stream).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from ..model import Intersection, Lanelet
from ..observations import Detections
from .config import MODES, SimConfig
from .scenario import build_lanelets, random_intersection, stop_distances
from .sensors import FALSE_TRACK_ID0, scene_sensor_range, sensor_rng, simulate_detections
from .traffic import EgoTrajectory, Track, choose_routes, make_ego, make_tracks, n_cover

__all__ = ['SimConfig', 'Scenario', 'simulate_scenario', 'MODES', 'FALSE_TRACK_ID0',
           'Track', 'EgoTrajectory']


@dataclass
class Scenario:
    """Ground truth, true motion and (lazily) simulated sensor data of one intersection."""

    seed: int
    config: SimConfig
    gt: Intersection
    gt_lanelets: list[Lanelet]
    traffic: dict[str, int]          # lanelet id -> trajectories using it
    tracks: list[Track]
    ego: EgoTrajectory
    duration: float
    stop: np.ndarray                 # stop-line distance per arm [m]
    sensor_range: float = 100.0      # this scene's range (see sensors.scene_sensor_range)
    sensors: tuple = MODES           # streams a bag writer should record
    _cache: dict = field(default_factory=dict, repr=False)

    def _stream(self, mode: str, rng_seed_offset: int = 0):
        key = (mode, int(rng_seed_offset))
        if key not in self._cache:
            rng = sensor_rng(self.seed, mode, rng_seed_offset)
            self._cache[key] = simulate_detections(rng, mode, self.tracks, self.ego,
                                                   self.gt.center, self.config,
                                                   self.sensor_range)
        return self._cache[key]

    def detections(self, mode: str, rng_seed_offset: int = 0) -> Detections:
        """All detections of ``mode`` ('tracked' | 'raw' | 'heading'), sorted by stamp."""
        return self._stream(mode, rng_seed_offset)[0]

    def frames(self, sensor: str, rng_seed_offset: int = 0) -> Iterator[tuple[float, Detections]]:
        """``(stamp, Detections)`` per sensor cycle (also empty cycles), same rows as
        :meth:`detections`."""
        dets, cyc = self._stream(sensor, rng_seed_offset)
        bounds = np.searchsorted(cyc, np.arange(len(self.ego.t) + 1))
        for i, stamp in enumerate(self.ego.t):
            yield float(stamp), dets.subset(slice(bounds[i], bounds[i + 1]))


def simulate_scenario(seed: int, config: SimConfig = SimConfig()) -> Scenario:
    """Random intersection, lanelets, traffic and ego for ``seed`` (paper §IV)."""
    g_geo, g_lanes, g_traffic, g_ego = (np.random.default_rng(s)
                                        for s in np.random.SeedSequence(seed).spawn(4))
    inter = random_intersection(g_geo, config)
    stop = stop_distances(g_geo, inter, config)
    lanelets = build_lanelets(g_lanes, inter, config, stop)
    duration = float(g_traffic.uniform(*config.duration))
    ego = make_ego(g_ego, inter, lanelets, config, duration)
    routes, _ = choose_routes(g_traffic, lanelets, config)
    n_obs = (n_cover(routes, lanelets, only_routed=config.empty_lane_prob > 0)
             if config.cover_all_lanes else 0)
    rng_m = scene_sensor_range(ego, lanelets, config)
    tracks = make_tracks(g_traffic, lanelets, routes, config, duration, ego=ego, n_observed=n_obs,
                         sensor_range=rng_m)
    counts = {ll.id: 0 for ll in lanelets}
    for tr in tracks:
        for lid in tr.route:
            counts[lid] += 1
    return Scenario(seed=int(seed), config=config, gt=inter, gt_lanelets=lanelets,
                    traffic=counts, tracks=tracks, ego=ego, duration=duration, stop=stop,
                    sensor_range=rng_m)
