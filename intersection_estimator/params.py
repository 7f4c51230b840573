"""Parameters of the node and the replay: one table, ROS-free.

The node declares every entry as a ROS parameter (with description and range), the
replay reads the same YAML file (``config/intersection_estimator.yaml``), and both turn
the values into a :class:`~intersection_estimator.pipeline.PipelineConfig` here, so the
two can never disagree.
"""

from __future__ import annotations

import array
from dataclasses import dataclass, replace
from pathlib import Path
import math

import yaml

__all__ = ['ParamSpec', 'PARAMS', 'defaults', 'check', 'plain', 'load_yaml', 'pipeline_config']


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: default (its type is the parameter's type), range and meaning."""

    name: str
    default: object
    description: str
    lo: float | None = None
    hi: float | None = None
    choices: tuple = ()

    def allowed(self) -> str:
        if self.choices:
            return 'one of ' + ', '.join(map(repr, self.choices))
        if self.lo is not None and self.hi is not None:
            return f'in [{self.lo}, {self.hi}]'
        return 'a ' + type(self.default).__name__


_TOPIC_ROLES = ('radar_topics', 'radar_scan_topics', 'detection_topics', 'object_topics',
                'autoware_object_topics')

PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('fixed_frame', 'map', 'fixed frame of all outputs (REP 105: map or odom)'),
    ParamSpec('radar_topics', ['/perception/radar/points'],
              'sensor_msgs/PointCloud2 radar clouds with x, y, z, Doppler (and rcs)'),
    ParamSpec('radar_scan_topics', [''], 'radar_msgs/RadarScan topics (live only if radar_msgs is installed)'),
    ParamSpec('detection_topics', [''], 'geometry_msgs/PoseArray object detections, orientation = heading'),
    ParamSpec('object_topics', ['/perception/objects'],
              'intersection_estimator_msgs/TrackedObjectArray tracked objects'),
    ParamSpec('autoware_object_topics', [''],
              'autoware_perception_msgs/TrackedObjects (live only if Autoware msgs are installed)'),
    ParamSpec('odometry_topic', '/localization/odometry', 'nav_msgs/Odometry ego pose in the fixed frame '
              '(or in odom, with map -> odom on /tf)'),
    ParamSpec('doppler_field', '', "Doppler field name; '' = first of doppler, velocity, radial_velocity, v_r"),
    ParamSpec('doppler_sign', 1, '+1: positive Doppler = moving away from the sensor; -1: the opposite',
              choices=(1, -1)),
    ParamSpec('doppler_ego_compensated', True, 'true: the radar driver removed the ego motion from the '
              'Doppler (over ground); false: the Doppler is relative to the moving sensor and the node '
              'removes the ego motion with the odometry'),
    ParamSpec('min_existence_probability', 0.3, 'tracked objects below this are ignored', 0.0, 1.0),
    ParamSpec('weak_labels', [6, 7], 'classification labels (Autoware ids) of tracked road users that '
              'count as traffic of an arm but neither ask for a lane of their own nor shape the lane '
              'course (they do not keep to a lane center): bicycle 6, pedestrian 7; [] = every '
              'label is a lane user'),
    ParamSpec('mount_frames', ['radar'], 'sensor frame ids with a static mount on base_link (fallback '
              'for frames /tf_static does not connect to base_link)'),
    ParamSpec('mount_x', [3.7], 'mount x of each mount_frames entry in base_link [m]'),
    ParamSpec('mount_y', [0.0], 'mount y of each mount_frames entry in base_link [m]'),
    ParamSpec('mount_yaw', [0.0], 'mount yaw of each mount_frames entry in base_link [rad]'),
    ParamSpec('timer_period', 0.2, 'estimation tick period [s]', 0.01, 10.0),
    ParamSpec('budget_ms', 150.0, 'wall time per tick for topology + lane course [ms]', 1.0, 10000.0),
    ParamSpec('lane_share', 0.6, 'share of the tick budget for the lane course', 0.0, 0.95),
    ParamSpec('topology_samples', 5000, 'topology samples per tick in sample-budget mode (replay)', 1, 10**7),
    ParamSpec('lane_samples', 20000, 'lane-course samples per tick in sample-budget mode (replay)', 0, 10**8),
    ParamSpec('window_s', 120.0, 'observations older than this are forgotten [s]', 1.0, 3600.0),
    ParamSpec('max_observations', 200000, 'cap on observations kept in the window', 100, 10**7),
    ParamSpec('lane_period', 1.0, 'lane course re-estimated at most this often (at once on a new '
              'topology) [s]', 0.0, 60.0),
    ParamSpec('lanes_enabled', True, 'estimate the lane course (needs tracked objects)'),
    ParamSpec('radar_tracking', True, 'radar rows go through the radar tracker and enter the window as '
              'tracks (the lane course then runs on radar alone); false = the paper\'s raw-detection '
              'model (radar rows voxelised, straight lanelets)'),
    ParamSpec('radar_track_spread_along', 1.64, 'radar tracker: spread of one radar return about the '
              "vehicle's center along its heading (body and noise) [m]", 0.05, 20.0),
    ParamSpec('radar_track_spread_across', 1.13, 'radar tracker: the same across the heading [m]',
              0.05, 20.0),
    ParamSpec('radar_track_doppler_tol', 4.0, "radar tracker: a return joins a track only when its "
              "Doppler is within this of the track's velocity along the line of sight [m/s]",
              0.1, 100.0),
    ParamSpec('radar_track_doppler_noise', 1.0, "radar tracker: standard deviation of one return's "
              'Doppler about its vehicle\'s radial speed, for the velocity update; 0 = Doppler only gates '
              'returns and starts tracks [m/s]', 0.0, 10.0),
    ParamSpec('radar_track_doppler_assoc', True, "radar tracker: a return joins the track nearest in "
              "position and Doppler together (Mahalanobis, the Doppler's sigma radar_track_doppler_tol / 3); "
              "false = nearest in position alone, the Doppler only gates"),
    ParamSpec('radar_track_standing_s', 3.0, 'radar tracker: a track that lived this long without '
              'driving (a queue, a parked car) is reported without a heading; 0 = never [s]', 0.0, 3600.0),
    ParamSpec('radar_track_reorder_s', 0.2, 'radar tracker: scans are held this long (stamp time) and '
              'tracked in stamp order, so that radars with different latencies interleave; a scan later '
              'than this is dropped, counted as radar_scan_late [s]', 0.0, 10.0),
    ParamSpec('reset_distance', 25.0, 'ego past the center by this -> start on the next intersection [m]',
              1.0, 1000.0),
    ParamSpec('seed', 0, 'seed of every random draw', 0, 2**31 - 1),
    ParamSpec('geo_origin', [49.0, 8.4], 'latitude, longitude [deg] of the fixed frame origin, written '
              'into the Lanelet2 OSM export (its <geoReference>; nodes are projected around it)'),
    ParamSpec('osm_path', '', "write the lane course as a Lanelet2 OSM map to this file on every lane "
              "update ('' = off; written to a temporary file and renamed, so a reader never sees half a map)"),
    ParamSpec('prior_map', '', "Lanelet2 OSM map to compare the estimate with ('' = off): changes on "
              "~/map_changes and markers (namespace map_changes); projected around geo_origin"),
    ParamSpec('map_changes_period', 2.0, 'the newest lane course is compared with prior_map at most this '
              'often, in two ticks of their own (map matching, then the rules) [s]', 0.0, 600.0),
)

_BY_NAME = {p.name: p for p in PARAMS}


def defaults() -> dict:
    return {p.name: p.default for p in PARAMS}


def plain(name: str, value):
    """A value as ROS hands it over -> the Python type of the table: array parameters come
    as ``array.array`` (set at run time) or tuples, an empty list in a parameter file as
    None (no type): all become lists."""
    spec = _BY_NAME.get(name)
    if spec is not None and isinstance(spec.default, list):
        if value is None:
            return []
        if isinstance(value, (tuple, array.array)) or hasattr(value, 'tolist'):
            return list(value.tolist() if hasattr(value, 'tolist') else value)
    return value


def check(name: str, value) -> str | None:
    """Return why ``value`` is not allowed for parameter ``name`` (None if it is)."""
    spec = _BY_NAME.get(name)
    if spec is None:
        return f'unknown parameter {name!r}'
    want = type(spec.default)
    if want is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if want is list:
        if not isinstance(value, (list, tuple)):
            return f'{name} must be a list, got {value!r}'
    elif not isinstance(value, want) or (want is int and isinstance(value, bool)):
        return f'{name} must be a {want.__name__}, got {value!r}'
    if isinstance(value, float) and not math.isfinite(value):
        return f'{name}={value!r} is not finite: must be {spec.allowed()}'
    if spec.choices and value not in spec.choices:
        return f'{name}={value!r} not allowed: must be {spec.allowed()}'
    if spec.lo is not None and not (spec.lo <= value <= spec.hi):
        return f'{name}={value!r} out of range: must be {spec.allowed()}'
    return None


def check_all(values: dict) -> list[str]:
    """Every problem with a full parameter set, including cross-parameter ones."""
    errors = [e for n, v in values.items() if (e := check(n, v))]
    if not errors:
        from .export.osm import check_origin
        try:
            check_origin(values['geo_origin'], 'geo_origin')
        except ValueError as exc:
            errors.append(str(exc))
        bad = [v for v in values['weak_labels']
               if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 255]
        if bad:
            errors.append(f'weak_labels must hold classification ids in [0, 255], got {bad!r}')
        n = len(values['mount_frames'])
        for k in ('mount_x', 'mount_y', 'mount_yaw'):
            if len(values[k]) != n:
                errors.append(f'{k} must have one entry per mount_frames entry ({n}), got {len(values[k])}')
    return errors


def load_yaml(path: str | Path, node_name: str = 'intersection_estimator') -> dict:
    """Read a ROS 2 parameter file (``node: ros__parameters: ...``) into a full value dict."""
    data = yaml.safe_load(Path(path).read_text()) or {}
    section = data.get(node_name) or data.get('/**') or next(iter(data.values()), {})
    values = defaults()
    values.update((section or {}).get('ros__parameters', {}))
    errors = check_all(values)
    if errors:
        raise ValueError(f'{path}: ' + '; '.join(errors))
    return values


def topics(values: dict) -> dict[str, list[str]]:
    """Configured input topics per role (empty strings dropped)."""
    return {role: [t for t in values[role] if t] for role in _TOPIC_ROLES}


def mounts(values: dict) -> dict[str, tuple[float, float, float]]:
    return {f: (float(x), float(y), float(yaw)) for f, x, y, yaw in
            zip(values['mount_frames'], values['mount_x'], values['mount_y'], values['mount_yaw'])}


def pipeline_config(values: dict):
    """Map parameter values onto a validated :class:`~.pipeline.PipelineConfig`."""
    from .pipeline import PipelineConfig
    from .lanes import LaneConfig
    from .topology import TopologyConfig
    from .tracking import TrackerConfig
    weak = tuple(int(v) for v in values['weak_labels'])
    cfg = replace(PipelineConfig(), window_s=float(values['window_s']),
                  max_observations=int(values['max_observations']),
                  topology_samples=int(values['topology_samples']),
                  lane_samples=int(values['lane_samples']),
                  budget_s=float(values['budget_ms']) / 1e3, lane_share=float(values['lane_share']),
                  lanes_enabled=bool(values['lanes_enabled']), lane_period=float(values['lane_period']),
                  reset_distance=float(values['reset_distance']),
                  topology=replace(TopologyConfig(), weak_labels=weak),
                  lanes=replace(LaneConfig(), skip_labels=weak),
                  radar_tracking=replace(TrackerConfig(), enabled=bool(values['radar_tracking']),
                                         body_along_m=float(values['radar_track_spread_along']),
                                         body_across_m=float(values['radar_track_spread_across']),
                                         doppler_tol=float(values['radar_track_doppler_tol']),
                                         doppler_var=float(values['radar_track_doppler_noise']) ** 2,
                                         doppler_assoc=bool(values['radar_track_doppler_assoc']),
                                         standing_s=float(values['radar_track_standing_s']),
                                         reorder_s=float(values['radar_track_reorder_s'])))
    cfg.validate()
    return cfg
