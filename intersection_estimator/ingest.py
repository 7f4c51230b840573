"""Messages in, detections out: what the node and the replay do with every input message.

ROS-free: it sees messages only through :mod:`msg_adapters` (duck-typed), so the node
feeds it rclpy messages and the replay feeds it messages rosbags decoded. It keeps the
ego pose buffer, counts what was received and dropped per reason, holds back messages
that arrive before the ego pose for their stamp, and guards the time base against stamps
that jump or run backwards.
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import replace
import math
import time

import numpy as np

from msg_adapters.detections import AdapterOptions, to_detections
from msg_adapters.errors import AdapterError
from msg_adapters.odometry import EgoPose, EgoPoseBuffer, read_odometry

from . import params as P
from .roles import ODOMETRY, ROLE_TYPES, node_type
from .tf import TfBuffer, TfMounts, compose

__all__ = ['ROLE_TYPES', 'TF_TOPICS', 'Ingest', 'RateLimitedLog']

#: TF topics (tf2_msgs/msg/TFMessage) -> static?; fed to :meth:`Ingest.handle_tf`
TF_TOPICS = {'/tf': False, '/tf_static': True}
TF_TYPE = 'tf2_msgs/msg/TFMessage'

PENDING_MAX = 256        # messages held back waiting for the ego pose
JUMP_S = 30.0            # a stamp this far from the time base is suspicious
JUMP_CONFIRM = 5         # ... and accepted as a new time base after this many consistent ones in a row
MAX_COORD = 1e7          # |x|, |y| beyond this [m] is no place in a metric map frame (UTM northing < 1e7)
MAX_EGO_SPEED = 70.0     # [m/s] odometry implying more than this is an ego jump (confirmed like a time jump)
EGO_DT_MAX = 0.5         # [s] ... over at most this much time: a stamp far ahead buys no distance
EGO_SLACK = 2.0          # [m] position noise allowed on top of MAX_EGO_SPEED * dt


class RateLimitedLog:
    """At most one warning per reason and period (the rest are counted, not printed)."""

    def __init__(self, logger, period_s: float = 5.0):
        self.logger, self.period_s = logger, period_s
        self._last: dict[str, float] = {}
        self.suppressed = Counter()

    def warn(self, reason: str, text: str) -> bool:
        now = time.monotonic()
        if now - self._last.get(reason, -1e9) < self.period_s:
            self.suppressed[reason] += 1
            return False
        extra = f' ({self.suppressed.pop(reason)} more since last report)' if self.suppressed[reason] else ''
        self._last[reason] = now
        self.logger.warning(text + extra)
        return True


class Ingest:
    """Converts input messages and adds them to an :class:`~.pipeline.OnlineEstimator`."""

    def __init__(self, values: dict, types=None):
        self.types = types
        self.received = Counter()
        self.dropped = Counter()
        self._warnings: list[tuple[str, str]] = []
        self._pending: deque = deque(maxlen=PENDING_MAX)
        self._pending_points = 0
        self.latest_stamp: float | None = None
        self._late_seen = 0                        # the estimator's late radar scans counted so far
        self._jumps, self._jump_to = 0, None       # time jump: count of consistent stamps, last one
        self._ego_jumps: list[EgoPose] = []        # ego jump candidates, consistent among themselves
        self.tf = TfBuffer()                       # /tf, /tf_static: mounts and map -> odom
        self.missing: list[str] = []               # configured topics whose type is not installed
        self.configure(values)
        self.ego = EgoPoseBuffer(fixed_frame=values['fixed_frame'])

    def configure(self, values: dict) -> None:
        self.values = values
        self.opts = AdapterOptions(doppler_field=values['doppler_field'] or None,
                                   doppler_sign=float(values['doppler_sign']),
                                   doppler_ego_compensated=bool(values['doppler_ego_compensated']),
                                   min_existence=float(values['min_existence_probability']),
                                   mounts=TfMounts(self.tf, 'base_link', P.mounts(values)),
                                   max_points=int(values['max_observations']))

    # -- topics -----------------------------------------------------------------------------
    def topics(self) -> list[tuple[str, str, str]]:
        """(role, topic, message type) of every configured input."""
        out = [(role, t, node_type(role)) for role, ts in P.topics(self.values).items() for t in ts]
        if self.values[ODOMETRY]:
            out.append((ODOMETRY, self.values[ODOMETRY], node_type(ODOMETRY)))
        return out

    def subscriptions(self) -> list[tuple[str, str, type]]:
        """(role, topic, message class) for live subscriptions. A configured topic whose
        message package is not installed is not subscribed: :attr:`missing` gets one line
        naming the topic and the package (the node logs it as an error and reports it on
        /diagnostics: a misconfiguration is never silent)."""
        subs, self.missing = [], []
        for role, topic, msgtype in self.topics():
            try:
                subs.append((role, topic, self.types.get(msgtype).msgclass))
            except (ImportError, AttributeError):
                pkg = msgtype.split('/')[0]
                self.missing.append(f'{topic} ({role}) is NOT subscribed: its type {msgtype} needs the ROS '
                                    f'package {pkg}, which is not installed (install {pkg} or clear {role})')
        return subs

    # -- messages ---------------------------------------------------------------------------
    def handle(self, role: str, msg, estimator) -> int:
        """Convert one message and add it to ``estimator``; returns detections added."""
        self.received[role] += 1
        try:
            stamp = self._check_stamp(msg, estimator)
            if role == 'odometry_topic':
                self._add_pose(read_odometry(msg))
                dets = None
            else:
                dets = self._convert(role, msg)
        except AdapterError as exc:
            if exc.reason == 'no_ego_pose' and self._waits_for_pose(msg):
                self._hold(role, msg)
                return 0
            return self.drop(exc.reason, f'{role}: dropped a message: {exc}')
        added = self._add(estimator, dets) if dets is not None and len(dets) else 0
        self.latest_stamp = stamp if self.latest_stamp is None else max(self.latest_stamp, stamp)
        if role == 'odometry_topic' and self._pending:
            added += self._retry_pending(estimator)
        return added

    def _add(self, estimator, dets) -> int:
        """Add to the window; counts rows it refused (non-finite) and the observations that
        gave way to the max_observations cap (a burst degrades to dropping, counted)."""
        before = getattr(estimator, 'evicted', 0)
        added = estimator.add(dets)
        if len(dets) > added:
            self.dropped['non_finite'] += len(dets) - added
        self.count_late(estimator)
        pushed = getattr(estimator, 'evicted', 0) - before
        if pushed:
            self.dropped['window_full'] += pushed
            self.warn('window_full', f'max_observations={self.values["max_observations"]} reached: '
                      f'{pushed} older observation(s) gave way')
        return added

    def count_late(self, estimator) -> None:
        """Count the radar scans the estimator's tracker found late since the last call
        (its tracker runs in the tick, so they are counted as they are found)."""
        total = getattr(estimator, 'radar_scans_late', 0)
        late, self._late_seen = total - self._late_seen, total
        if late > 0:
            self.dropped['radar_scan_late'] += late
            self.warn('radar_scan_late', f'{late} radar scan(s) came more than radar_track_reorder_s='
                      f'{self.values["radar_track_reorder_s"]:g} s after a newer one: left out of the radar '
                      'tracks (radars with different latencies need a larger radar_track_reorder_s)')

    def handle_tf(self, msg, static: bool) -> int:
        """A ``tf2_msgs/TFMessage`` from ``/tf`` (``static`` False) or ``/tf_static``: sensor
        mounts and ``map -> odom`` come from it (the ``mount_*`` parameters are the fallback).
        Returns the transforms taken."""
        self.received['tf_static' if static else 'tf'] += 1
        try:
            n = self.tf.add(msg, static)
        except Exception as exc:  # noqa: BLE001 - a malformed message is dropped, counted
            return self.drop('malformed', f'{"/tf_static" if static else "/tf"}: dropped a message: {exc}')
        if n == 0 and len(getattr(msg, 'transforms', ()) or ()):
            return self.drop('malformed', f'{"/tf_static" if static else "/tf"}: no usable transform in a message')
        return n

    def drop(self, reason: str, text: str) -> int:
        self.dropped[reason] += 1
        self.warn(reason, text)
        return 0

    def count_drop(self, reason: str) -> None:
        self.dropped[reason] += 1

    def warn(self, reason: str, text: str) -> None:
        self._warnings.append((reason, text))
        del self._warnings[:-32]

    def pop_warnings(self) -> list[tuple[str, str]]:
        out, self._warnings = self._warnings, []
        return out

    def _hold(self, role, msg) -> None:
        """Hold a message back until odometry covers its stamp: at most PENDING_MAX messages
        and max_observations points (a burst before the first pose must not grow memory)."""
        cap = int(self.values['max_observations'])
        size = _points_of(msg)
        while self._pending and (len(self._pending) == self._pending.maxlen
                                 or self._pending_points + size > cap):
            self._pending_points -= _points_of(self._pending.popleft()[1])
            self.drop('no_ego_pose', f'{role}: no ego pose for {len(self._pending) + 1} held-back messages '
                      f'({self._pending_points + size} points); dropping the oldest (is odometry published?)')
        self._pending.append((role, msg))
        self._pending_points += size

    def _check_stamp(self, msg, estimator) -> float:
        """Stamp of ``msg`` in seconds; refuses non-finite ones and unconfirmed time jumps."""
        try:
            s = msg.header.stamp
            stamp = float(s.sec) + 1e-9 * float(s.nanosec)
        except (AttributeError, TypeError, ValueError) as exc:
            raise AdapterError('malformed', f'no usable header.stamp ({exc})') from exc
        if not np.isfinite(stamp):
            raise AdapterError('non_finite', 'stamp is not finite')
        if self.latest_stamp is not None and abs(stamp - self.latest_stamp) > JUMP_S:
            # only stamps that agree with each other confirm a new time base: random garbage
            # stamps in a row must not make the node forget everything
            consistent = self._jump_to is not None and abs(stamp - self._jump_to) <= JUMP_S
            self._jumps = self._jumps + 1 if consistent else 1
            self._jump_to = stamp
            if self._jumps < JUMP_CONFIRM:
                raise AdapterError('stamp_jump', f'stamp {stamp:.3f} s is {stamp - self.latest_stamp:+.1f} s '
                                   'from the time base')
            self.warn('time_base_reset', f'time base moved to {stamp:.3f} s: forgetting older data')
            self.latest_stamp, self._jumps, self._jump_to = stamp, 0, None
            self._ego_jumps.clear()
            self.ego.clear()
            self.tf.clear()
            self._set_pending([])
            estimator.reset()
        else:
            self._jumps, self._jump_to = 0, None
        return stamp

    # -- plausibility ----------------------------------------------------------------------------
    def _convert(self, role: str, msg):
        """Adapter output, cleaned; rows the adapter removed as NaN/Inf are counted."""
        dets = to_detections(msg, self.ego, self.opts)
        bad = getattr(dets, 'non_finite', 0)
        if bad:
            self.dropped['non_finite'] += bad
            self.warn('non_finite', f'{role}: cleaned {bad} non-finite point(s)/object(s)')
        return self._clean(role, dets)

    def _clean(self, role: str, dets):
        """Drop detections with absurd (finite) coordinates (they would overflow the estimator)
        and the objects whose track id occurs more than once in one message (one id, two
        places: a track that would zig-zag between vehicles)."""
        far = ~(np.abs(dets.xy) <= MAX_COORD).all(axis=1) & np.isfinite(dets.xy).all(axis=1)
        if far.any():
            self.drop('out_of_range', f'{role}: dropped {int(far.sum())} detection(s) beyond '
                      f'{MAX_COORD:g} m from the origin of the fixed frame')
            dets = dets.subset(~far)
        ids = dets.track_id
        if len(ids) > 1 and (ids >= 0).any():
            # which of the objects the id belongs to is unknowable: drop them all, keep the rest
            uniq, counts = np.unique(ids, return_counts=True)
            dup = np.isin(ids, uniq[counts > 1]) & (ids >= 0)
            if dup.any():
                self.drop('duplicate_id', f'{role}: dropped {int(dup.sum())} object(s) whose track id '
                          'occurs more than once in one message')
                dets = dets.subset(~dup)
        return dets

    def _add_pose(self, pose: EgoPose) -> None:
        """Add an ego pose unless it is absurd, or a jump that the next poses do not confirm.

        A single glitch (a pose kilometres away, or seconds back in time) would otherwise make
        the node believe the ego has passed the intersection and forget what it saw. A real
        relocalisation is accepted after JUMP_CONFIRM consistent poses (the buffer restarts).
        """
        if pose.frame_id and pose.frame_id != self.ego.fixed_frame:
            pose = self._to_fixed(pose)
        if not (abs(pose.x) <= MAX_COORD and abs(pose.y) <= MAX_COORD):
            raise AdapterError('out_of_range', f'ego pose ({pose.x:g}, {pose.y:g}) beyond {MAX_COORD:g} m')
        twist = (pose.vx, pose.vy, pose.yaw_rate)
        if not all(math.isfinite(v) and abs(v) <= 1e3 for v in twist):
            pose = replace(pose, vx=0.0, vy=0.0, yaw_rate=0.0)    # cleaned: extrapolate without it
        latest = self.ego.latest
        if latest is None or _plausible(latest, pose):
            self._ego_jumps.clear()
            self.ego.add(pose)
            return
        if not (self._ego_jumps and _plausible(self._ego_jumps[-1], pose)):
            self._ego_jumps.clear()
        self._ego_jumps.append(pose)
        if len(self._ego_jumps) < JUMP_CONFIRM:
            raise AdapterError('ego_jump', f'ego pose ({pose.x:.1f}, {pose.y:.1f}) at {pose.stamp:.3f} s is '
                               f'not reachable from ({latest.x:.1f}, {latest.y:.1f}) at {latest.stamp:.3f} s')
        self.warn('ego_relocalised', f'ego pose jumped to ({pose.x:.1f}, {pose.y:.1f}): restarting the pose buffer')
        self.ego.clear()
        for p in self._ego_jumps:
            self.ego.add(p)
        self._ego_jumps.clear()

    def _to_fixed(self, pose: EgoPose) -> EgoPose:
        """Odometry in another frame (REP 105: ``odom``) -> the fixed frame through TF
        (``map -> odom`` at the pose stamp); twist stays in the child frame."""
        fixed = self.ego.fixed_frame
        tf = self.tf.lookup(fixed, pose.frame_id, pose.stamp)
        if tf is None:
            raise AdapterError('frame_mismatch', f'odometry in {pose.frame_id!r}, fixed frame is {fixed!r} '
                               f'and /tf has no {fixed} -> {pose.frame_id} transform at {pose.stamp:.3f} s')
        x, y, yaw = compose(tf, (pose.x, pose.y, pose.yaw))
        return replace(pose, frame_id=fixed, x=x, y=y, yaw=yaw)

    def _waits_for_pose(self, msg) -> bool:
        latest = self.ego.latest
        return latest is None or self._stamp(msg) > latest.stamp

    @staticmethod
    def _stamp(msg) -> float:
        return float(msg.header.stamp.sec) + 1e-9 * float(msg.header.stamp.nanosec)

    def _retry_pending(self, estimator) -> int:
        latest = self.ego.latest.stamp
        pending = list(self._pending)
        self._set_pending([(r, m) for r, m in pending if self._stamp(m) > latest])
        added = 0
        for role, msg in pending:
            if self._stamp(msg) > latest:
                continue
            try:
                dets = self._convert(role, msg)
            except AdapterError as exc:
                self.drop(exc.reason, f'{role}: dropped a held-back message: {exc}')
                continue
            added += self._add(estimator, dets) if len(dets) else 0
        return added

    def _set_pending(self, items) -> None:
        self._pending = deque(items, maxlen=PENDING_MAX)
        self._pending_points = sum(_points_of(m) for _, m in self._pending)

    # -- ego --------------------------------------------------------------------------------
    def ego_pose(self) -> tuple[float, float, float] | None:
        p = self.ego.latest
        return None if p is None else (p.x, p.y, p.yaw)

    def flush_pending(self) -> int:
        """End of input (a replay's last message): the messages still held back for an ego
        pose never get one; they are dropped and counted as ``no_ego_pose``. Returns how many."""
        n, self._pending = len(self._pending), deque(maxlen=PENDING_MAX)
        if n:
            self.dropped['no_ego_pose'] += n
            self.warn('no_ego_pose', f'{n} message(s) still waiting for an ego pose at the end of the input '
                      'were dropped (is odometry recorded?)')
        return n

    def forget_before(self, t: float) -> None:
        """After a reset: drop held-back messages older than ``t``."""
        self._set_pending([(r, m) for r, m in self._pending if self._stamp(m) >= t])


def _points_of(msg) -> int:
    """Rows a held-back message will become (cloud points, objects, poses, returns)."""
    try:
        if hasattr(msg, 'width') and hasattr(msg, 'height'):
            return max(int(msg.width) * int(msg.height), 1)
        for name in ('objects', 'poses', 'returns'):
            if hasattr(msg, name):
                return max(len(getattr(msg, name)), 1)
    except (TypeError, ValueError, OverflowError):
        pass
    return 1


def _plausible(a: EgoPose, b: EgoPose) -> bool:
    """Can the ego get from pose ``a`` to pose ``b`` (not far back in time, not too fast)?"""
    dt = b.stamp - a.stamp
    return dt >= -1.0 and math.hypot(b.x - a.x, b.y - a.y) <= MAX_EGO_SPEED * min(abs(dt), EGO_DT_MAX) + EGO_SLACK


def tick(ingest: Ingest, estimator, *, wall_budget: bool, log=None, budget_s: float | None = None):
    """One estimation tick as node and replay both run it: next intersection, then estimate
    (``budget_s``: see :meth:`~.pipeline.OnlineEstimator.tick`).

    Returns the :class:`~.pipeline.EstimateResult`, or None before the first message.
    """
    now = ingest.latest_stamp
    if now is None:
        return None
    ego = ingest.ego_pose()
    if ego is not None and estimator.passed(ego[:2], ego[2]):
        if log is not None:
            log('ego passed the intersection: starting on the next one')
        estimator.reset()
        ingest.forget_before(now)
    result = estimator.tick(now, wall_budget=wall_budget, budget_s=budget_s)
    ingest.count_late(estimator)       # the radar tracker runs in the tick
    return result
