"""Traffic along the ground-truth lanelets (paper §IV) and the ego vehicle.

Vehicles follow routes entering lane -> connector -> leaving lane along the true
center lines (as in the paper), with at most ``max_traj_per_lane`` trajectories on any
lanelet of the route. Speeds: cruise on approach, slowed by curvature in the turn
(``v^2 * kappa <= max_lat_acc``), limited acceleration / deceleration. Vehicles do not
interact (no car following, no traffic lights); the ego vehicle approaches on one arm's
entering lane and stops a few metres before the stop line.
All positions are sampled on the common sensor grid ``t = i / rate_hz``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model import Intersection, Lanelet
from .config import SimConfig

__all__ = ['Track', 'EgoTrajectory', 'choose_routes', 'n_cover', 'make_tracks', 'make_ego']


@dataclass
class Track:
    """True trajectory of one vehicle, sampled at the sensor rate."""

    id: int
    t: np.ndarray       # (M,) [s]
    xy: np.ndarray      # (M, 2) [m]
    yaw: np.ndarray     # (M,) [rad]
    speed: np.ndarray   # (M,) [m/s]
    route: tuple        # lanelet ids: (entering, connector, leaving)


@dataclass
class EgoTrajectory:
    """Ego pose over the whole scenario (same time grid as the sensors)."""

    t: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    arm: int
    lane_index: int

    def sensor_xy(self, mount: float) -> np.ndarray:
        """Position of a sensor ``mount`` metres ahead of the ego origin, per stamp."""
        return self.xy + mount * np.stack([np.cos(self.yaw), np.sin(self.yaw)], axis=1)


def _routes(lanelets: list[Lanelet]) -> list[tuple[str, str, str]]:
    by_id = {ll.id: ll for ll in lanelets}
    return [(ll.id, c, by_id[c].successors[0])
            for ll in lanelets if ll.kind == 'entering' for c in ll.successors]


def choose_routes(rng: np.random.Generator, lanelets: list[Lanelet], cfg: SimConfig):
    """Random routes with <= ``max_traj_per_lane`` on every lanelet; returns (routes, counts).

    With ``cover_all_lanes`` every entering and leaving lane first gets one route (where
    capacity allows), then random routes are added until the target count is reached.
    The covering routes come first in ``routes``; :func:`make_tracks` schedules the
    first ``n_cover(routes, lanelets)`` of them so that the sensors observe them.
    """
    routes = _drop_empty(rng, _routes(lanelets), lanelets, cfg.empty_lane_prob)
    cap = cfg.max_traj_per_lane
    count = {ll.id: 0 for ll in lanelets}
    chosen: list[tuple[str, str, str]] = []

    def fits(r):
        return all(count[x] < cap for x in r)

    def take(r):
        chosen.append(r)
        for x in r:
            count[x] += 1

    if cfg.cover_all_lanes and cap > 0:
        order = rng.permutation(len(routes))
        for pos in (0, 2):  # entering lanes, then leaving lanes
            for i in order:
                r = routes[i]
                if count[r[pos]] == 0 and fits(r):
                    take(r)
    n_in = sum(ll.kind == 'entering' for ll in lanelets)
    target = int(round(n_in * rng.uniform(*cfg.traj_per_lane)))
    while len(chosen) < target:
        free = [r for r in routes if fits(r)]
        if not free:
            break
        take(free[int(rng.integers(len(free)))])
    return chosen, count


def _drop_empty(rng, routes, lanelets, prob: float):
    """Routes left after drawing each entering / leaving lane empty with ``prob`` (no
    draw at all when ``prob`` is 0; at least one route survives)."""
    if prob <= 0 or not routes:
        return routes
    lanes = [ll.id for ll in lanelets if ll.kind in ('entering', 'leaving')]
    empty = {lid for lid, u in zip(lanes, rng.uniform(size=len(lanes))) if u < prob}
    kept = [r for r in routes if r[0] not in empty and r[2] not in empty]
    return kept or [routes[int(rng.integers(len(routes)))]]


def n_cover(routes, lanelets, only_routed: bool = False) -> int:
    """Length of the prefix of ``routes`` needed to cover every entering and leaving lane
    (the covering routes of :func:`choose_routes` come first); ``only_routed``: every
    such lane that some route uses (lanes drawn empty have none)."""
    need = {ll.id for ll in lanelets if ll.kind in ('entering', 'leaving')}
    if only_routed:
        need &= {x for r in routes for x in (r[0], r[2])}
    seen: set = set()
    for i, r in enumerate(routes):
        if need <= seen:
            return i
        seen.update((r[0], r[2]))
    return len(routes)


def _path(route, by_id) -> np.ndarray:
    """Concatenated center line of a route without the shared junction points."""
    parts = [by_id[route[0]].center] + [by_id[x].center[1:] for x in route[1:]]
    return np.concatenate(parts)


def _limit_rate(w: np.ndarray, budget: np.ndarray) -> np.ndarray:
    """``w[i] = min(w[i], w[i-1] + budget[i-1])`` in closed form: with ``B = cumsum(budget)``,
    ``w[i] = B[i] + min_{j <= i}(w[j] - B[j])``."""
    b = np.concatenate([[0.0], np.cumsum(budget)])
    return b + np.minimum.accumulate(w - b)


def _speed_profile(s: np.ndarray, kappa: np.ndarray, v_cruise: float, cfg: SimConfig):
    """Cruise speed, ``v^2 |kappa| <= max_lat_acc`` in turns, limited acceleration and
    deceleration (forward / backward pass on ``v^2``)."""
    v = np.minimum(v_cruise, np.sqrt(cfg.max_lat_acc / np.maximum(np.abs(kappa), 1e-6)))
    ds = np.diff(s)
    w = _limit_rate(v ** 2, 2 * cfg.max_acc * ds)
    w = _limit_rate(w[::-1], 2 * cfg.max_dec * ds[::-1])[::-1]
    return np.sqrt(w)


def _kinematics(path: np.ndarray):
    seg = np.diff(path, axis=0)
    ds = np.linalg.norm(seg, axis=1)
    s = np.concatenate([[0.0], np.cumsum(ds)])
    yaw_seg = np.unwrap(np.arctan2(seg[:, 1], seg[:, 0]))
    yaw = np.concatenate([yaw_seg[:1], 0.5 * (yaw_seg[1:] + yaw_seg[:-1]), yaw_seg[-1:]])
    kappa = np.gradient(yaw, s)
    return s, yaw, kappa


def _sample(path, s, yaw, v, t0, duration, rate):
    """Sample a path driven with speed profile v, starting at t0, on the sensor grid."""
    dt_seg = np.diff(s) / np.maximum(0.5 * (v[1:] + v[:-1]), 0.1)
    t_path = t0 + np.concatenate([[0.0], np.cumsum(dt_seg)])
    i0 = int(np.ceil(max(t_path[0], 0.0) * rate - 1e-9))
    i1 = int(np.floor(min(t_path[-1], duration) * rate + 1e-9))
    t = np.arange(i0, i1 + 1) / rate
    sq = np.interp(t, t_path, s)
    xy = np.stack([np.interp(sq, s, path[:, 0]), np.interp(sq, s, path[:, 1])], axis=1)
    return t, xy, np.interp(sq, s, yaw), np.interp(sq, s, v)


def _observed_starts(path, s, t_rel, lanes, sens, rng_m: float, cfg: SimConfig, n_cyc: int):
    """Start cycles ``j`` (vehicle at the path start at ``t = j / rate``) and, per start,
    the smallest observed length [m] over the route's entering and leaving lane.

    A path sample is observed when it falls in ``[0, n_cyc)`` and lies within
    ``rng_m`` of the ego sensor at that cycle; only the ``observed_zone`` metres
    of each lane next to its stop line count. ``lanes`` are ``(s_lo, s_hi)`` arc ranges.
    """
    rate = cfg.rate_hz
    k_t = np.arange(int(np.floor(t_rel[-1] * rate)) + 1) / rate       # times after start
    sk = np.interp(k_t, t_rel, s)
    pk = np.stack([np.interp(sk, s, path[:, 0]), np.interp(sk, s, path[:, 1])], axis=1)
    starts = np.arange(-len(k_t) + 1, n_cyc)
    cyc = starts[:, None] + np.arange(len(k_t))[None, :]
    inside = (cyc >= 0) & (cyc < n_cyc)
    cc = np.clip(cyc, 0, n_cyc - 1)
    vis = inside & (np.linalg.norm(pk[None, :, :] - sens[cc], axis=2) <= rng_m)
    ds = np.diff(sk)
    both = vis[:, 1:] & vis[:, :-1]
    seen = np.full(len(starts), np.inf)
    for lo, hi in lanes:
        on = (sk[:-1] >= lo) & (sk[1:] <= hi)
        seen = np.minimum(seen, (both * (ds * on)[None, :]).sum(axis=1))
    return starts, seen


def make_tracks(rng: np.random.Generator, lanelets: list[Lanelet], routes, cfg: SimConfig,
                duration: float, ego: EgoTrajectory | None = None,
                n_observed: int = 0, sensor_range: float | None = None) -> list[Track]:
    """One vehicle per route, start times spread so that most pass within ``duration``.

    The first ``n_observed`` routes (the lane-covering ones) are *guaranteed observed*:
    their start is drawn (with the same single uniform draw) among the start cycles at
    which both their entering and leaving lane are seen by the ego sensor over at least
    ``min_observed_length`` metres of the ``observed_zone`` next to the stop line, or at
    the best start if none reaches it. Needs ``ego`` and the scene's ``sensor_range``
    (default ``cfg.sensor_range``); the other routes are drawn as before.
    """
    by_id = {ll.id: ll for ll in lanelets}
    sens = ego.sensor_xy(cfg.sensor_mount) if ego is not None else None
    tracks = []
    for i, route in enumerate(routes):
        path = _path(route, by_id)
        s, yaw, kappa = _kinematics(path)
        v = _speed_profile(s, kappa, float(rng.uniform(*cfg.cruise_speed)), cfg)
        dt_seg = np.diff(s) / np.maximum(0.5 * (v[1:] + v[:-1]), 0.1)
        travel = float(np.sum(dt_seg))
        lo, hi = -0.3 * travel, max(duration - 0.7 * travel, 0.0)
        u = float(rng.uniform())
        t0 = lo + (hi - lo) * u
        if i < n_observed and sens is not None:
            t_rel = np.concatenate([[0.0], np.cumsum(dt_seg)])
            n_in, n_con = len(by_id[route[0]].center), len(by_id[route[1]].center)
            zone = cfg.observed_zone
            s_in_end, s_out0 = s[n_in - 1], s[n_in + n_con - 2]
            lanes = ((s_in_end - zone, s_in_end), (s_out0, s_out0 + zone))
            rng_m = cfg.sensor_range if sensor_range is None else sensor_range
            starts, seen = _observed_starts(path, s, t_rel, lanes, sens, rng_m, cfg, len(ego.t))
            ok = np.flatnonzero(seen >= cfg.min_observed_length)
            if len(ok) == 0:
                ok = np.flatnonzero(seen >= seen.max() - 1e-9)
            t0 = float(starts[ok[min(int(u * len(ok)), len(ok) - 1)]]) / cfg.rate_hz
        t, xy, yw, sp = _sample(path, s, yaw, v, t0, duration, cfg.rate_hz)
        if len(t) >= 2:
            tracks.append(Track(id=i, t=t, xy=xy, yaw=np.asarray(yw), speed=np.asarray(sp),
                                route=tuple(route)))
    return tracks


def make_ego(rng: np.random.Generator, inter: Intersection, lanelets: list[Lanelet],
             cfg: SimConfig, duration: float) -> EgoTrajectory:
    """Ego on a random entering lane: constant speed, brakes at max_dec/2, stands still."""
    entering = [ll for ll in lanelets if ll.kind == 'entering']
    lane = entering[int(rng.integers(len(entering)))]
    v0 = float(rng.uniform(*cfg.ego_speed))
    t_stop = float(rng.uniform(*cfg.ego_stop_time)) * duration
    b = 0.5 * cfg.max_dec
    t_brake = max(t_stop - v0 / b, 0.0)
    t = np.arange(int(np.floor(duration * cfg.rate_hz + 1e-9)) + 1) / cfg.rate_hz
    tb = np.clip(t - t_brake, 0.0, v0 / b)
    dist = v0 * np.minimum(t, t_brake) + v0 * tb - 0.5 * b * tb ** 2  # travelled [m]
    speed = np.where(t < t_brake, v0, np.maximum(v0 - b * (t - t_brake), 0.0))
    heading = -inter.arms[lane.arm].direction
    stop_pt = lane.center[-1] - float(rng.uniform(*cfg.ego_stop_gap)) * heading
    xy = stop_pt - (dist[-1] - dist)[:, None] * heading
    yaw = np.full(len(t), float(np.arctan2(heading[1], heading[0])))
    return EgoTrajectory(t=t, xy=xy, yaw=yaw, speed=speed, arm=lane.arm, lane_index=lane.lane_index)
