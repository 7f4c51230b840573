"""Simulated scenarios as messages and bags on the node's default input topics."""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from pathlib import Path
from typing import Iterator

import numpy as np

from .writer import BagWriter

__all__ = ['SCENARIO_TOPICS', 'SCENARIO_FRAMES', 'SCENARIO_RADAR_MOUNT', 'BAG_T0', 'ScenarioBagInfo',
           'scenario_mount', 'scenario_messages', 'write_scenario_bag', 'drive_through', 'write_drive_bag']

#: Topics written by :func:`write_scenario_bag` (the node's default input topics).
SCENARIO_TOPICS = {
    'odometry': '/localization/odometry',
    'radar': '/perception/radar/points',
    'objects': '/perception/objects',
    'autoware': '/perception/autoware/objects',
    'detections': '/perception/detections',
    'tf_static': '/tf_static',
}
#: Frames of scenario bags: fixed frame, ego frame, radar frame (mounted on the ego).
SCENARIO_FRAMES = {'fixed': 'map', 'base': 'base_link', 'radar': 'radar'}
#: Radar mount (x, y, yaw) in base_link of scenario bags with the default SimConfig
#: (``sensor_mount`` = 3.7 m ahead); also written to ``/tf_static`` (base_link -> radar).
SCENARIO_RADAR_MOUNT = (3.7, 0.0, 0.0)
#: Bag time of the scenario's t = 0 [s] (2023-11-14T22:13:20Z): avoids zero stamps.
BAG_T0 = 1_700_000_000.0


def scenario_mount(scenario) -> tuple[float, float, float]:
    """Radar mount (x, y, yaw) in base_link: from sensor_xy vs the ego pose, else the config."""
    ego = scenario.ego
    for mode in ('raw', 'tracked', 'heading'):
        try:
            d = scenario.detections(mode)
        except Exception:
            continue
        ok = np.isfinite(d.sensor_xy).all(axis=1)
        if not ok.any():
            continue
        i = np.clip(np.searchsorted(ego.t, d.t[ok] - 1e-9), 0, len(ego.t) - 1)
        off = d.sensor_xy[ok] - ego.xy[i]
        c, s = np.cos(ego.yaw[i]), np.sin(ego.yaw[i])
        local = np.stack([c * off[:, 0] + s * off[:, 1], -s * off[:, 0] + c * off[:, 1]], axis=1)
        mx, my = np.round(np.median(local, axis=0), 9) + 0.0
        return float(mx), float(my), 0.0
    return float(getattr(scenario.config, 'sensor_mount', 0.0)), 0.0, 0.0




def _tf_static(types, t: float, parent: str, child: str, mount) -> object:
    from msg_adapters._common import quat_from_yaw
    from msg_adapters.types import make_header
    g = types.get
    qx, qy, qz, qw = (float(v) for v in quat_from_yaw(mount[2]))
    tr = g('geometry_msgs/msg/Transform')(
        translation=g('geometry_msgs/msg/Vector3')(x=mount[0], y=mount[1], z=0.0),
        rotation=g('geometry_msgs/msg/Quaternion')(x=qx, y=qy, z=qz, w=qw))
    ts = g('geometry_msgs/msg/TransformStamped')(header=make_header(types, parent, t),
                                                 child_frame_id=child, transform=tr)
    return g('tf2_msgs/msg/TFMessage')(transforms=[ts])


def _sensor_relative(d, ego, i: int, mount, rate) -> np.ndarray:
    """The simulator's Doppler (over ground) as a sensor on the moving ego measures it:
    minus the sensor's velocity (the ego's along its heading plus the mount's lever arm
    turning with it) along each line of sight."""
    from msg_adapters.detections import over_ground
    sensor = np.array(_compose((ego.xy[i, 0], ego.xy[i, 1], ego.yaw[i]), mount)[:2])
    arm = sensor - ego.xy[i]
    heading = np.array([math.cos(ego.yaw[i]), math.sin(ego.yaw[i])])
    v = ego.speed[i] * heading + rate[i] * np.array([-arm[1], arm[0]])
    return over_ground(d.doppler, d.xy, sensor, -v)    # the inverse: minus the sensor's motion


def _yaw_rate(t, yaw):
    if len(t) < 2:
        return np.zeros(len(t))
    return np.gradient(np.unwrap(yaw), t)


@dataclass
class ScenarioBagInfo:
    """What :func:`write_scenario_bag` wrote: topics with message counts, the radar mount,
    bag time of scenario t = 0, and the size in bytes."""

    path: Path
    counts: dict = field(default_factory=dict)
    mount: tuple = (0.0, 0.0, 0.0)
    t0: float = BAG_T0
    size: int = 0


def scenario_messages(scenario, types, sensors=('tracked', 'raw', 'heading'), autoware: bool = True,
                      t0: float = BAG_T0, mount=None,
                      doppler_over_ground: bool = True) -> Iterator[tuple[float, str, object]]:
    """``(t, topic, msg)`` of a simulated scenario in time order, messages built with ``types``.

    What :func:`write_scenario_bag` records (see there), also usable without a bag (soak,
    DDS tests with ``RclpyTypes``; there ``/tf_static`` is left out when ``tf2_msgs`` is not
    importable). ``mount`` defaults to :func:`scenario_mount`. ``doppler_over_ground``
    False writes the radar's Doppler relative to the moving sensor, as radars without
    ego-motion compensation report it (:func:`_sensor_relative`).
    """
    from msg_adapters.odometry import odometry_msg
    from msg_adapters.pointcloud2 import radar_cloud_msg
    from msg_adapters.pose_array import pose_array_msg
    from msg_adapters.tracked_objects import autoware_tracked_objects_msg, tracked_object_array_msg
    from msg_adapters.types import make_header

    ego = scenario.ego
    fx, base, radar = SCENARIO_FRAMES['fixed'], SCENARIO_FRAMES['base'], SCENARIO_FRAMES['radar']
    mount = scenario_mount(scenario) if mount is None else mount
    frames = {s: scenario.frames(s) for s in sensors}
    rate = _yaw_rate(ego.t, ego.yaw)
    try:
        yield t0 + float(ego.t[0]), SCENARIO_TOPICS['tf_static'], _tf_static(
            types, t0 + float(ego.t[0]), base, radar, mount)
    except ImportError:   # rclpy namespace without tf2_msgs (no wheel): no /tf_static
        pass
    for i, te in enumerate(ego.t):
        t = t0 + float(te)
        yield t, SCENARIO_TOPICS['odometry'], odometry_msg(
            types, t, ego.xy[i, 0], ego.xy[i, 1], ego.yaw[i], vx=ego.speed[i], yaw_rate=rate[i],
            frame_id=fx, child_frame_id=base)
        for s, it in frames.items():
            stamp, d = next(it)
            ts = t0 + stamp
            if s == 'raw':
                dop = d.doppler if doppler_over_ground else _sensor_relative(d, ego, i, mount, rate)
                yield ts, SCENARIO_TOPICS['radar'], radar_cloud_msg(
                    types, make_header(types, radar, ts),
                    _to_sensor(d.xy, (ego.xy[i, 0], ego.xy[i, 1], ego.yaw[i]), mount), dop, d.rcs)
            elif s == 'tracked':
                args = (make_header(types, fx, ts), d.track_id, d.xy, d.heading, d.speed, d.label)
                yield ts, SCENARIO_TOPICS['objects'], tracked_object_array_msg(types, *args)
                if autoware:
                    yield ts, SCENARIO_TOPICS['autoware'], autoware_tracked_objects_msg(types, *args)
            elif s == 'heading':
                yield ts, SCENARIO_TOPICS['detections'], pose_array_msg(
                    types, make_header(types, fx, ts), d.xy, d.heading)


def write_scenario_bag(scenario, path, sensors=('tracked', 'raw', 'heading'), autoware: bool = True,
                       t0: float = BAG_T0) -> ScenarioBagInfo:
    """Write a simulated scenario as a rosbag2 MCAP bag on the node's input topics.

    Topics (:data:`SCENARIO_TOPICS`), bag time = header stamp = ``t0`` + scenario time:

    * ``/localization/odometry`` nav_msgs/Odometry ``map`` -> ``base_link`` every ego cycle,
      twist in base_link (vx = speed, yaw rate);
    * ``/tf_static`` tf2_msgs/TFMessage ``base_link`` -> ``radar`` (the mount, once, latched);
    * ``/perception/radar/points`` ('raw') PointCloud2 in ``radar``: x, y, z, doppler, rcs
      float32 in the sensor frame (the simulator's fixed-frame points mapped through the
      ego pose and the mount, which is recovered from ``sensor_xy``);
    * ``/perception/objects`` ('tracked') our TrackedObjectArray in ``map``;
    * ``/perception/autoware/objects`` ('tracked', ``autoware=True``) Autoware
      TrackedObjects in ``map`` (schema embedded in the bag);
    * ``/perception/detections`` ('heading') geometry_msgs/PoseArray in ``map``.

    Every sensor topic gets a message per cycle (empty ones too). Deterministic.
    """
    mount = scenario_mount(scenario)
    info = ScenarioBagInfo(Path(path), mount=mount, t0=t0)
    with BagWriter(path) as w:
        for t, topic, msg in scenario_messages(scenario, w.types, sensors, autoware, t0, mount):
            w.write(topic, msg, t)
            info.counts[topic] = info.counts.get(topic, 0) + 1
    info.size = sum(f.stat().st_size for f in Path(path).iterdir())
    return info


def _to_sensor(xy, ego_pose, mount) -> np.ndarray:
    """Fixed-frame points (N, 2) -> the frame of a sensor mounted on the ego."""
    sx, sy, syaw = _compose(ego_pose, mount)
    c, s = math.cos(syaw), math.sin(syaw)
    dx, dy = xy[:, 0] - sx, xy[:, 1] - sy
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1)


def _compose(pose, mount):
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    return x + c * mount[0] - s * mount[1], y + s * mount[0] + c * mount[1], yaw + mount[2]


def drive_through(types, ego, center, t_start: float, speed: float = 12.0, rate: float = 10.0,
                  wait_s: float = 0.0) -> Iterator[tuple[float, str, object]]:
    """``(t, topic, odometry)`` after a scenario: the ego waits ``wait_s`` at its stop position,
    then drives straight through ``center`` and 60 m on (the pipeline starts on the next
    intersection once it is ``reset_distance`` past it)."""
    from msg_adapters.odometry import odometry_msg
    p0 = ego.xy[-1]
    d = np.asarray(center) - p0
    yaw = math.atan2(d[1], d[0])
    n_wait = int(round(wait_s * rate))
    for k in range(1, n_wait + int((float(np.hypot(*d)) + 60.0) / speed * rate) + 1):
        s = max(0, k - n_wait) * speed / rate
        t = t_start + k / rate
        yield t, SCENARIO_TOPICS['odometry'], odometry_msg(
            types, t, p0[0] + s * math.cos(yaw), p0[1] + s * math.sin(yaw), yaw, vx=speed if s else 0.0,
            frame_id=SCENARIO_FRAMES['fixed'], child_frame_id=SCENARIO_FRAMES['base'])


def write_drive_bag(path, seeds, *, gap_s: float | None = None, sensors=('tracked',), wait_s: float = 4.0,
                    t0: float = BAG_T0) -> Path:
    """A drive through the simulated intersections ``seeds``, one after the other, in one bag:
    after each the ego waits ``wait_s`` and drives through (``gap_s`` None), or the next
    recording starts ``gap_s`` seconds after the last message (no drive through; a gap in
    bag time)."""
    from ..sim import simulate_scenario
    with BagWriter(path) as w:
        for seed in seeds:
            sc = simulate_scenario(seed)
            msgs = list(scenario_messages(sc, w.types, sensors=sensors, autoware=False, t0=t0))
            if gap_s is None:
                msgs += list(drive_through(w.types, sc.ego, sc.gt.center, t0 + sc.duration, wait_s=wait_s))
            for t, topic, msg in msgs:
                w.write(topic, msg, t)
            t0 = msgs[-1][0] + (1.0 if gap_s is None else gap_s)
    return Path(path)
