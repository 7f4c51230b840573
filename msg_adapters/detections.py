"""Glue: any input message + the ego pose buffer -> :class:`observations.Detections` in the fixed frame.

* radar (PointCloud2, RadarScan): ``doppler`` (positive = moving away), ``rcs``,
  ``sensor_xy`` = the sensor origin in the fixed frame at the message stamp;
* tracked objects (all families): ``track_id``, ``heading``, ``speed``, ``label``;
  filtered by ``min_existence`` and ``labels`` (vehicles only by default);
* PoseArray: ``heading`` (NaN where the quaternion is zero).

Inputs in the fixed frame pass through; inputs in the ego frame or a mounted sensor frame
are transformed with the interpolated ego pose (:class:`odometry.EgoPoseBuffer`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from intersection_estimator.observations import Detections

from .errors import AdapterError, guarded
from .odometry import EgoPoseBuffer, apply
from .pointcloud2 import DOPPLER_NAMES, RadarCloud, read_pointcloud2
from .pose_array import read_pose_array
from .radar_scan import read_radar_scan
from .tracked_objects import MIN_SPEED_FOR_HEADING, read_objects

__all__ = ['VEHICLE_LABELS', 'AdapterOptions', 'message_kind', 'radar_detections', 'over_ground',
           'pose_array_detections', 'object_detections', 'to_detections']

#: Autoware labels kept by default: UNKNOWN, CAR, TRUCK, BUS, TRAILER, MOTORCYCLE.
VEHICLE_LABELS = frozenset({0, 1, 2, 3, 4, 5})


@dataclass
class AdapterOptions:
    """How inputs are read (node parameters map 1:1 onto these).

    doppler_field / rcs_field: name(s) to look up, None = the common names;
    doppler_sign: +1 if the driver's positive Doppler means moving away, -1 otherwise;
    doppler_ego_compensated: True if the driver removed the ego motion from the Doppler
    (over ground), False if it is relative to the moving sensor (the adapter then adds the
    sensor's own velocity along each line of sight, from the ego poses);
    min_existence: objects below this existence probability are dropped;
    labels: Autoware label ids to keep (None = all); mounts: ``{frame: (x, y, yaw)}`` of
    sensors in the ego frame; max_points: larger clouds are refused ('too_large').
    """

    doppler_field: str | tuple | None = None
    doppler_sign: float = 1.0
    doppler_ego_compensated: bool = True
    rcs_field: str | tuple | None = None
    min_existence: float = 0.0
    labels: frozenset | None = VEHICLE_LABELS
    mounts: dict = field(default_factory=dict)
    min_speed_for_heading: float = MIN_SPEED_FOR_HEADING
    max_points: int | None = None


def message_kind(msg) -> str:
    """'pointcloud2' | 'radar_scan' | 'pose_array' | 'objects' | 'odometry' by fields."""
    if hasattr(msg, 'point_step') and hasattr(msg, 'fields'):
        return 'pointcloud2'
    if hasattr(msg, 'returns'):
        return 'radar_scan'
    if hasattr(msg, 'poses'):
        return 'pose_array'
    if hasattr(msg, 'objects'):
        return 'objects'
    if hasattr(msg, 'child_frame_id') and hasattr(msg, 'twist'):
        return 'odometry'
    raise AdapterError('unknown_type', f'{type(msg).__name__} is no supported input')


def _origin(ego: EgoPoseBuffer, frame: str, stamp: float, tf, mounts) -> np.ndarray:
    """Sensor origin in the fixed frame; for fixed-frame inputs the ego position (or NaN)."""
    if frame != ego.fixed_frame:
        return np.array(tf[:2])
    try:
        return np.array(ego.transform(ego.base_frame, stamp, mounts)[:2])
    except AdapterError:
        return np.full(2, np.nan)


def _counted(dets: Detections, dropped: int) -> Detections:
    """Attach how many rows the reader cleaned as non-finite (``dets.non_finite``)."""
    dets.non_finite = int(dropped)
    return dets


def over_ground(doppler: np.ndarray, xy: np.ndarray, sensor_xy, sensor_v) -> np.ndarray:
    """Doppler relative to a sensor at ``sensor_xy`` moving with ``sensor_v`` (fixed frame)
    -> over ground: a range rate is ``(v_target - v_sensor) . los`` (``los`` the unit vector
    sensor -> point), so ``v_target . los = doppler + v_sensor . los``."""
    los = xy - np.asarray(sensor_xy, float)[None]
    los /= np.maximum(np.linalg.norm(los, axis=1, keepdims=True), 1e-6)
    return doppler + los @ np.asarray(sensor_v, float)


def _radar(cloud: RadarCloud, ego: EgoPoseBuffer, opts: AdapterOptions) -> Detections:
    if len(cloud) == 0:
        return _counted(Detections.empty(), cloud.dropped)
    tf = ego.transform(cloud.frame_id, cloud.stamp, opts.mounts)
    xy = apply(tf, cloud.xyz[:, :2])
    origin = _origin(ego, cloud.frame_id, cloud.stamp, tf, opts.mounts)
    doppler = cloud.doppler
    if not opts.doppler_ego_compensated:
        frame = cloud.frame_id if cloud.frame_id != ego.fixed_frame else ego.base_frame
        doppler = over_ground(doppler, xy, origin, ego.velocity(frame, cloud.stamp, opts.mounts))
    return _counted(Detections.make(xy, cloud.stamp, doppler=doppler, rcs=cloud.rcs, sensor_xy=origin),
                    cloud.dropped)


@guarded
def radar_detections(msg, ego: EgoPoseBuffer, opts: AdapterOptions = AdapterOptions()) -> Detections:
    """PointCloud2 or RadarScan -> radar Detections in the fixed frame."""
    if message_kind(msg) == 'radar_scan':
        cloud = read_radar_scan(msg, doppler_sign=opts.doppler_sign, max_points=opts.max_points)
    else:
        cloud = read_pointcloud2(msg, doppler_field=opts.doppler_field, doppler_sign=opts.doppler_sign,
                                 rcs_field=opts.rcs_field, max_points=opts.max_points)
        if len(cloud) and not cloud.doppler_field:
            # radar points without Doppler carry no direction of travel: nothing to estimate from
            names = ', '.join(str(f.name) for f in msg.fields)
            wanted = opts.doppler_field or DOPPLER_NAMES
            wanted = wanted if isinstance(wanted, str) else ', '.join(wanted)
            raise AdapterError('no_doppler', f'PointCloud2 without a Doppler field (fields {names}; '
                               f'looked for {wanted}; set doppler_field)')
    return _radar(cloud, ego, opts)


@guarded
def pose_array_detections(msg, ego: EgoPoseBuffer, opts: AdapterOptions = AdapterOptions()) -> Detections:
    """PoseArray -> Detections with heading in the fixed frame."""
    poses = read_pose_array(msg, max_points=opts.max_points)
    if len(poses) == 0:
        return _counted(Detections.empty(), poses.dropped)
    tf = ego.transform(poses.frame_id, poses.stamp, opts.mounts)
    return _counted(Detections.make(apply(tf, poses.xy), poses.stamp, heading=_wrap(poses.yaw + tf[2]),
                                    sensor_xy=_origin(ego, poses.frame_id, poses.stamp, tf, opts.mounts)),
                    poses.dropped)


@guarded
def object_detections(msg, ego: EgoPoseBuffer, opts: AdapterOptions = AdapterOptions()) -> Detections:
    """Tracked objects of any family -> Detections with track ids in the fixed frame."""
    objs = read_objects(msg, min_speed_for_heading=opts.min_speed_for_heading)
    keep = objs.existence >= opts.min_existence
    if opts.labels is not None:
        keep &= np.isin(objs.label, np.fromiter(opts.labels, dtype=np.int64))
    if not keep.any():
        return _counted(Detections.empty(), objs.dropped)
    tf = ego.transform(objs.frame_id, objs.stamp, opts.mounts)
    return _counted(Detections.make(apply(tf, objs.xy[keep]), objs.stamp,
                                    heading=_wrap(objs.yaw[keep] + tf[2]), speed=objs.speed[keep],
                                    track_id=objs.ids[keep], label=objs.label[keep],
                                    sensor_xy=_origin(ego, objs.frame_id, objs.stamp, tf, opts.mounts)),
                    objs.dropped)


def to_detections(msg, ego: EgoPoseBuffer, opts: AdapterOptions = AdapterOptions()) -> Detections:
    """Any supported input message -> Detections (Odometry: added to ``ego``, returns empty).

    ``result.non_finite`` (if set) counts the rows the reader removed as NaN/Inf.
    """
    kind = message_kind(msg)
    if kind == 'odometry':
        ego.add_msg(msg)
        return Detections.empty()
    if kind == 'pose_array':
        return pose_array_detections(msg, ego, opts)
    if kind == 'objects':
        return object_detections(msg, ego, opts)
    return radar_detections(msg, ego, opts)


def _wrap(a):
    return (np.asarray(a, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi
