"""Settings of the radar tracker (:mod:`intersection_estimator.tracking`)."""

from __future__ import annotations

from dataclasses import dataclass

from ..ranges import check_table

__all__ = ['TrackerConfig']

_RANGES = {
    'cluster_m': ('(0, 20]', 'single-linkage distance of radar rows that start a track [m]'),
    'gate_sigma': ('(0, 20]', 'a row joins a track within this Mahalanobis distance [sigma]'),
    'spawn_gates': ('[1, 20]', 'rows within this many gates of a track start no new track'),
    'doppler_tol': ('(0, inf)', "|predicted radial speed - a row's Doppler| a track accepts [m/s]"),
    'max_miss': ('[1, 1000]', 'scans without rows before a track ends'),
    'min_rows': ('[0, 100000]', 'updates (rows) before a track is reported'),
    'min_path_m': ('[0, 1000]', 'first-to-last distance of a reported track [m]'),
    'standing_s': ('[0, 3600]', 'a track that lived this long [s of stamp time] without driving '
                   '(min_path_m) is reported headless (a queue, a parked car; 0: never)'),
    'accel_noise': ('(0, 1000]', 'white-acceleration density of the constant-velocity model [m^2/s^3]'),
    'body_along_m': ('(0, 20]', "spread of one radar row along the vehicle's heading [m]"),
    'body_across_m': ('(0, 20]', 'spread of one radar row across the heading [m]'),
    'row_var': ('(0, 100]', 'variance of one row about the vehicle center in the update [m^2]'),
    'doppler_assoc': (None, "a row goes to the track nearest in position and Doppler together "
                      "(doppler_tol = 3 sigma); false: in position, Doppler only gates"),
    'doppler_var': ('[0, 100]', "variance of one row's Doppler in the update [(m/s)^2]; 0: "
                    'Doppler gates and starts tracks only'),
    'velocity_sigma0': ('(0, 100]', 'velocity uncertainty of a new track [m/s]'),
    'min_speed': ('[0, 50]', 'below this a track stands: speed 0, and it has not moved [m/s]'),
    'heading_speed': ('[0, 50]', "below this a row keeps the heading the track last drove at this "
                      "speed or faster (min_speed at least) [m/s]"),
    'merge_gates': ('[0, 20]', 'two tracks this many gates apart, same velocity: the younger ends'),
    'merge_speed': ('[0, 50]', '... velocities within this [m/s]'),
    'max_backlog': ('[1, 1000000]', 'rows a track holds before it is reported (memory cap)'),
    'reorder_s': ('[0, 10]', 'online: scans are held this long [s of stamp time] and tracked in stamp order'),
}


@dataclass(frozen=True)
class TrackerConfig:
    """Radar tracker (beyond the paper; ``enabled`` False = the paper's raw-detection
    model). Defaults chosen on tracker quality against the simulators' truth (coverage of
    moving vehicles' rows, tracks per vehicle; docs/real_junctions.md, "Radar through a
    tracker"), not on the estimate scored with them."""

    enabled: bool = True
    cluster_m: float = 2.5
    gate_sigma: float = 3.0
    spawn_gates: float = 2.0
    doppler_tol: float = 4.0
    max_miss: int = 5
    min_rows: int = 20
    min_path_m: float = 10.0
    standing_s: float = 3.0
    accel_noise: float = 2.0
    body_along_m: float = 1.64     # 4.5 m body (uniform: 1.3 m) and 1 m noise
    body_across_m: float = 1.13    # 1.8 m body (0.52 m) and 1 m noise
    row_var: float = 2.0
    doppler_assoc: bool = True
    doppler_var: float = 1.0       # 1 m/s; with doppler_assoc (docs/real_junctions.md, "Doppler")
    velocity_sigma0: float = 3.0
    min_speed: float = 1.0
    heading_speed: float = 3.0
    merge_gates: float = 0.5
    merge_speed: float = 2.0
    max_backlog: int = 600         # 60 s of a parked car at 10 Hz
    reorder_s: float = 0.2         # radars of one vehicle arrive up to ~2 scans apart

    def validate(self) -> 'TrackerConfig':
        """Raise ValueError naming the first parameter outside its allowed range."""
        check_table(self, _RANGES, 'radar_tracking')
        return self
