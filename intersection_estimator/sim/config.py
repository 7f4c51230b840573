"""Simulator parameters (paper §IV, Table I), one frozen dataclass.

Ranges are closed ``(low, high)`` tuples unless the name says otherwise. Every random
draw of the simulator goes through a ``numpy.random.Generator`` seeded from the
scenario seed, so a ``(seed, SimConfig)`` pair fixes the whole scenario.

Observed traffic on every lane (Table I: "vehicles traveling alongside the lanes").
With ``cover_all_lanes`` each entering and leaving lane gets one *covering* route, and
that route is scheduled so that the sensors actually see it: its start time is drawn
(same single uniform draw as any other route, so the rest of the scene is unchanged)
among the sensor cycles at which both its entering and its leaving lane are inside the
scenario's time window and the sensor range over >= ``min_observed_length`` metres of
the ``observed_zone`` metres next to the stop line (best start if none; ~0.1 % of covering
routes). With ``auto_sensor_range`` the range of a scene is ``sensor_range`` raised, in
10 m steps, until the sensor on the stopped ego covers the ``observed_zone`` of every
arm plus 5 m: stop lines of wide 5-arm intersections lie up to ~50 m from the center, so
a fixed 100 m missed far arms (seeds 0..199: 41 % of scenes raised, median 100 m, max
130 m -- a 360 deg radar/lidar setup). Routes, counts (<= ``max_traj_per_lane``),
durations and geometry are unchanged. Measured with 'tracked' detections (>= 5 within
1 m of the center line, heading within 30 deg, spanning >= 20 m), seeds 0..199: every
lane observed in 66.5 % of scenes before, 100 % after (seeds 1000..1299: 100 %).

Lanes without traffic (issue 15, measured separately): with ``empty_lane_prob > 0`` each
entering and leaving lane is drawn empty with that probability (one extra draw per lane,
after the routes are listed; none at 0, so the default scenes are unchanged) and every
route through an empty lane is dropped (at least one route is kept); covering then
covers the lanes that still have routes.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

__all__ = ['SimConfig', 'MODES']

#: Detection streams the simulator can produce (see :mod:`.sensors`).
MODES = ('tracked', 'raw', 'heading')


@dataclass(frozen=True)
class SimConfig:
    # --- geometry (Table I) -------------------------------------------------------
    arms: tuple[int, int] = (3, 5)                  # number of arms
    lanes: tuple[int, int] = (1, 4)                 # lanes per driving direction
    min_arm_angle_deg: float = 45.0                 # between neighbouring arms
    gap_max: float = 3.0                            # median gap in [0, gap_max)
    lane_width: tuple[float, float] = (3.0, 3.75)   # per arm [m]
    traffic_side: int = 1                           # +1 right-hand, -1 left-hand traffic
    center_range: float = 50.0                      # center uniform in [-r, r]^2 [m]
    kerb_radius: float = 5.0                        # rounded corners between arms [m]
    stop_margin: tuple[float, float] = (1.0, 4.0)   # stop line beyond the corner [m]
    arm_length: tuple[float, float] = (60.0, 80.0)  # lane length outside the stop line [m]
    point_spacing: float = 1.0                      # lanelet support points [m]
    # --- traffic (paper §IV: <= 6 trajectories per lane) ---------------------------
    max_traj_per_lane: int = 6
    traj_per_lane: tuple[float, float] = (2.0, 5.0)  # target mean per entering lane
    cover_all_lanes: bool = True                    # every lane gets >= 1 observed trajectory
    empty_lane_prob: float = 0.0                    # each entering / leaving lane left without
                                                    # traffic with this probability (issue 15:
                                                    # "<= 6 per lane" includes 0; 0 = as before)
    min_observed_length: float = 30.0               # ... seen over >= this [m] of the lane's
    observed_zone: float = 40.0                     # ... first/last this [m] at the stop line
    duration: tuple[float, float] = (20.0, 40.0)    # scenario length [s]
    cruise_speed: tuple[float, float] = (8.0, 14.0)  # approach speed [m/s]
    max_lat_acc: float = 2.5                        # turn speed limit v^2 * kappa [m/s^2]
    max_acc: float = 2.0                            # [m/s^2]
    max_dec: float = 3.0                            # [m/s^2]
    # connector center lines (scenario.TURN_HANDLES): 'arc', circular-arc Beziers -- the family
    # the lane course's connectors start from (lanes/init.py), so the bench cannot see that
    # start's error; 'corner', Beziers through the corner of the lanes' lines (SUMO's way)
    turn_shape: str = 'arc'
    # --- ego vehicle --------------------------------------------------------------
    ego_speed: tuple[float, float] = (8.0, 12.0)    # approach speed [m/s]
    ego_stop_gap: tuple[float, float] = (2.0, 6.0)  # stops this far before the stop line
    ego_stop_time: tuple[float, float] = (0.3, 0.6)  # stop reached at this share of duration
    sensor_mount: float = 3.7                       # radar ahead of the ego origin [m]
    # --- sensors ------------------------------------------------------------------
    rate_hz: float = 10.0                           # sensor cycle (all sensors)
    sensor_range: float = 100.0                     # around the ego sensor [m], at least
    auto_sensor_range: bool = True                  # raise it per scene to see every arm
    position_noise: float = 1.0                     # N(0, sigma) on every detection [m]
    # 'tracked': the position error of a track as AR(1) over its cycles, this correlation per
    # cycle at the same sigma (a tracker's smoothed output; 0 = white, the paper's §IV model)
    track_noise_corr: float = 0.0
    heading_noise_deg: float = 5.0                  # tracked / heading detections
    speed_noise: float = 0.3                        # tracked speed [m/s]
    clutter_radius: float = 80.0                    # false detections around the center [m]
    false_tracks_per_s: float = 1.0                 # 'tracked': short-lived false tracks
    false_track_cycles: tuple[int, int] = (1, 5)    # their lifetime [cycles]
    false_heading_per_cycle: float = 0.5            # 'heading': false detections per cycle
    radar_clutter_per_cycle: float = 8.0            # 'raw': clutter points per cycle
    radar_points_per_vehicle: float = 2.0           # 'raw': 1 + Poisson(this) per vehicle
    vehicle_size: tuple[float, float] = (4.5, 1.8)  # length, width: radar point spread [m]
    doppler_noise: float = 0.1                      # [m/s]
    rcs_vehicle: tuple[float, float] = (10.0, 4.0)  # mean, sigma [dBsm]
    rcs_clutter: tuple[float, float] = (-5.0, 4.0)  # mean, sigma [dBsm]

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict) -> 'SimConfig':
        """Inverse of :meth:`to_dict`; unknown keys are ignored (older/newer gt.json)."""
        names = {f.name: f for f in fields(cls)}
        kw = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in names}
        return cls(**kw)
