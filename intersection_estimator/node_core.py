"""What the plain and the managed (lifecycle) node share: parameters, inputs, the
estimation thread and the outputs. A mixin over ``rclpy.node.Node`` /
``rclpy.lifecycle.LifecycleNode`` (see :mod:`.node`, :mod:`.node_lifecycle`).

Why a thread of its own and not a timer callback in a multi-threaded executor: while a
long callback of a mutually exclusive group runs, rclpy's ``MultiThreadedExecutor``
keeps finding the timer ready and spins on it, holding the GIL; the estimator's
Python steps then waited for the GIL tick after tick (measured: ticks of 0.3-5 s against
a 150 ms budget, the process at 60 % CPU). Here the executor only runs short callbacks
(inputs, the timer's wake-up), and the compiled samplers release the GIL
(``nogil``), so inputs are served while the estimator samples.

Outputs carry the data time they estimate (the newest input stamp; zero before any
data), never wall time. A reset (ego past the intersection, time-base jump) clears the
latched markers (DELETEALL) and publishes an empty ``~/lanelets``.
"""

from __future__ import annotations

from collections import deque
import gc
import os
from pathlib import Path
import threading
import time

import numpy as np
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              ParameterUninitializedException)
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rcl_interfaces.msg import SetParametersResult

from . import params as P
from .ingest import TF_TOPICS, TF_TYPE, Ingest, RateLimitedLog, tick
from .pipeline import OnlineEstimator, warmup

from msg_adapters.types import RclpyTypes, make_time
from msg_adapters.topology import topology_msg
from msg_adapters.lanelets import lanelets_msg
from msg_adapters.markers import clear_markers_msg, markers_msg

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_msgs.msg import Header

_PTYPE = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
          float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING}
_ARRAY = {str: ParameterType.PARAMETER_STRING_ARRAY, float: ParameterType.PARAMETER_DOUBLE_ARRAY,
          int: ParameterType.PARAMETER_INTEGER_ARRAY}
#: parameters that only take effect at start-up (topics, frames); the rest apply live
STARTUP_ONLY = frozenset({'radar_topics', 'radar_scan_topics', 'detection_topics', 'object_topics',
                          'autoware_object_topics', 'odometry_topic', 'fixed_frame', 'timer_period',
                          'prior_map'})
#: inputs: best effort (matches reliable and best-effort publishers, as sensor data QoS), but
#: a queue deep enough for bursts (several sensors at once, bag playback, a slow tick):
#: sensor data QoS keeps 5 and drops the rest silently
INPUT_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT,
                       durability=DurabilityPolicy.VOLATILE)
LATCHED_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: what tf2_ros listens with: /tf reliable volatile, /tf_static transient local
TF_QOS = {False: QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.VOLATILE),
          True: QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)}
_WARMED = threading.Event()     # kernels compiled (or loaded) once per process


def descriptor(spec: P.ParamSpec) -> ParameterDescriptor:
    d = ParameterDescriptor(description=spec.description + (f' ({spec.allowed()})' if spec.lo is not None
                                                             or spec.choices else ''))
    d.type = _ARRAY[type(spec.default[0])] if isinstance(spec.default, list) else _PTYPE[type(spec.default)]
    if spec.lo is not None and isinstance(spec.default, float):
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.lo), to_value=float(spec.hi))]
    elif spec.lo is not None and isinstance(spec.default, int) and not isinstance(spec.default, bool):
        d.integer_range = [IntegerRange(from_value=int(spec.lo), to_value=int(spec.hi), step=0)]
    d.read_only = spec.name in STARTUP_ONLY
    return d


class EstimatorCore:
    """Mixin: the estimator's ROS side, independent of the node's life cycle."""

    # -- parameters -----------------------------------------------------------------------
    def declare_estimator_parameters(self) -> list[str]:
        """Declare every parameter; returns one line per bad one (wrong type, out of range),
        naming it. ``[]`` in a parameter file (no type in ROS) is an empty list."""
        errors = []
        for spec in P.PARAMS:
            given, desc = self._parameter_overrides.get(spec.name), descriptor(spec)
            if isinstance(spec.default, list) and given is not None and given.value is None:
                # ROS gives `[]` no type: an empty list of any type is this parameter's empty list
                self._parameter_overrides[spec.name] = Parameter(spec.name, value=[])
                desc.dynamic_typing = True
            try:
                self.declare_parameter(spec.name, spec.default, desc)
            except (InvalidParameterTypeException, InvalidParameterValueException,
                    ParameterUninitializedException) as exc:
                given = self._parameter_overrides.get(spec.name)
                given = None if given is None else P.plain(spec.name, given.value)
                errors.append(P.check(spec.name, given) or f'{spec.name}: {exc}'.splitlines()[0])
        return errors

    def current_values(self) -> tuple[dict, list[str]]:
        """The declared parameters as table values, and what is wrong with them."""
        values = {s.name: P.plain(s.name, self.get_parameter(s.name).value) for s in P.PARAMS}
        return values, P.check_all(values)

    def on_set_parameters(self, changes: list[Parameter]) -> SetParametersResult:
        new = dict(self.values)
        for p in changes:
            if p.name in STARTUP_ONLY:
                return SetParametersResult(successful=False, reason=f'{p.name} is read-only at run time')
            new[p.name] = P.plain(p.name, p.value)
        errors = P.check_all(new)
        if not errors:
            try:
                cfg = P.pipeline_config(new)
            except ValueError as exc:
                errors = [str(exc)]
        if errors:
            return SetParametersResult(successful=False, reason='; '.join(errors))
        self.values = new
        if getattr(self, 'estimator', None) is not None:
            self.estimator.config = cfg
            self.ingest.configure(new)
        return SetParametersResult(successful=True)

    # -- set-up ---------------------------------------------------------------------------
    def setup_estimator(self, values: dict) -> None:
        self.values = values
        self.log = RateLimitedLog(self.get_logger(), period_s=5.0)
        self.types = RclpyTypes()
        self.estimator = OnlineEstimator(P.pipeline_config(values), seed=values['seed'])
        self.ingest = Ingest(values, self.types)
        self._marker_keys: frozenset = frozenset()
        self._lanes_out = False            # lanelets / markers of an intersection are latched
        self._lanes_due = None             # (header, result) of a lane course not yet published
        self._lanes_waited = False         # ... that already waited one tick
        self._resets_seen = self.estimator.resets
        self._tick_ms: list[float] = []
        # recent time [ms] ticks spent besides estimating, per kind (see _tick): the budget
        # keeps the median of plain ticks and the worst of recent lane-publishing ticks back
        self._overhead_ms = {False: deque(maxlen=20), True: deque(maxlen=5)}
        self._prev_samples = 0
        self._subs: list = []
        self.prior = self._load_prior_map(values)
        self._change_keys: frozenset = frozenset()
        self._changes_due = None            # (header, result) to compare with the prior map
        self._comparing = None              # (header, result, its vehicles matched to the map)
        self._change_t = float('-inf')      # when it was last compared (monotonic) [s]
        self._change_ms = deque(maxlen=5)   # recent costs of the comparison's second half [ms]
        self._match_ms = deque(maxlen=5)    # ... of its first half, the map matching [ms]

    @staticmethod
    def _load_prior_map(values: dict):
        """The prior map's intersections (``prior_map`` set) or None; a map that does not
        load is a ValueError naming the parameter (the node refuses to start)."""
        if not values['prior_map']:
            return None
        from .fleet.live import LiveChanges
        try:
            return LiveChanges.load(values['prior_map'], origin=values['geo_origin'])
        except ValueError as exc:
            raise ValueError(f"prior_map={values['prior_map']}: {' '.join(str(exc).split())}") from None

    def create_inputs(self) -> None:
        """Subscribe every configured input; a topic whose type is not installed is an
        error in the log and on /diagnostics. /tf and /tf_static when tf2_msgs is there."""
        for role, topic, msg_type in self.ingest.subscriptions():
            self._subs.append(self.create_subscription(msg_type, topic, self._callback(role), INPUT_QOS))
            self.get_logger().info(f'listening to {topic} ({role})')
        for text in self.ingest.missing:
            self.get_logger().error(text)
        try:
            tf_cls = self.types.get(TF_TYPE).msgclass
        except (ImportError, AttributeError):
            self.get_logger().info('tf2_msgs is not installed: sensor mounts from the mount_* parameters only, '
                                   'odometry must be in fixed_frame')
            return
        for topic, static in TF_TOPICS.items():
            self._subs.append(self.create_subscription(tf_cls, topic, self._tf_callback(static), TF_QOS[static]))

    def create_outputs(self, create) -> None:
        """Publishers through ``create`` (``create_publisher`` or ``create_lifecycle_publisher``)."""
        from intersection_estimator_msgs.msg import LaneletArray, MapChangeArray, Topology
        from visualization_msgs.msg import MarkerArray
        self.pub_topology = create(Topology, '~/topology', LATCHED_QOS)
        self.pub_lanelets = create(LaneletArray, '~/lanelets', LATCHED_QOS)
        self.pub_markers = create(MarkerArray, '~/markers', LATCHED_QOS)
        self.pub_diag = create(DiagnosticArray, '/diagnostics', 10)
        self.pub_map_changes = create(MapChangeArray, '~/map_changes', LATCHED_QOS)

    def destroy_inputs(self) -> None:
        for sub in self._subs:
            self.destroy_subscription(sub)
        self._subs = []

    # -- the estimation thread --------------------------------------------------------------
    def start_worker(self) -> None:
        """Publish the empty estimate, start the thread and the timer that wakes it."""
        self.pub_topology.publish(topology_msg(self.types, self._header(), None, 0, float('-inf'), 0, 'NO_DATA'))
        self._wake, self._stop = threading.Event(), threading.Event()
        self._worker = threading.Thread(target=self._estimation_loop, name='estimator', daemon=True)
        self._worker.start()
        self.timer = self.create_timer(self.values['timer_period'], self._wake.set)

    def stop_worker(self, timeout: float = 30.0) -> None:
        """Stop the timer and the thread and wait for it: after this no tick publishes (call
        it before the context goes, or 'publisher's context is invalid')."""
        if getattr(self, '_worker', None) is None:
            return
        self._stop.set()
        self._wake.set()
        self.destroy_timer(self.timer)
        self._worker.join(timeout)
        if self._worker.is_alive():
            self.get_logger().warning(f'estimation thread still busy after {timeout:.0f} s')
        self._worker = None

    def _estimation_loop(self) -> None:
        """Compile (or load) the kernels, then one tick per timer period (a late tick skips
        the periods it missed). The node is on the graph meanwhile: inputs are kept, the
        latched topology says NO_DATA."""
        if not _WARMED.is_set():
            self.get_logger().info(f'estimator kernels ready in {warmup():.1f} s')
            _WARMED.set()
            gc.collect()
            gc.freeze()     # start-up objects (types, kernels) out of the collector: shorter pauses
        while not self._stop.is_set():
            if self._wake.wait(0.5) and not self._stop.is_set():
                self._wake.clear()
                self._tick()

    # -- inputs ---------------------------------------------------------------------------
    def _callback(self, role: str):
        def on_message(msg):
            try:
                self.ingest.handle(role, msg, self.estimator)
            except Exception as exc:  # noqa: BLE001 - a callback must never die on input
                self.ingest.count_drop('internal_error')
                self.log.warn('internal_error', f'{role}: dropped a message: {type(exc).__name__}: {exc}')
            self._flush_warnings()
        return on_message

    def _tf_callback(self, static: bool):
        def on_tf(msg):
            self.ingest.handle_tf(msg, static)
            self._flush_warnings()
        return on_tf

    def _flush_warnings(self) -> None:
        for reason, text in self.ingest.pop_warnings():
            self.log.warn(reason, text)

    # -- estimation -----------------------------------------------------------------------
    def _tick(self) -> None:
        t0 = time.perf_counter()
        try:
            samples = self.estimator.result.topology_samples
            base, lanes = self._overheads()
            stamp = self.ingest.latest_stamp      # the data time this tick estimates
            # new lanelets are published in the first tick with room for them
            # (_publish_lanes_now): a lane update's estimation keeps the whole budget, a
            # tick with lanelets waiting leaves room for publishing them
            reserve = lanes if self._lanes_due is not None else 0.0
            # the map comparison of the last lane update (prior_map) runs in two ticks of their
            # own, each estimating in what its half of the comparison leaves of the budget
            compare = self._compare_now()
            reserve += max(self._match_ms if self._comparing is None else self._change_ms,
                           default=0.0) if compare else 0.0
            budget = self.values['budget_ms']
            floor = 0.1 if compare else 0.5
            result = tick(self.ingest, self.estimator, wall_budget=True, log=self.get_logger().info,
                          budget_s=max(budget - base - reserve, floor * budget) / 1e3)
            if result is not None and result.topology_samples < samples:
                self._prev_samples = 0
            if not self._stop.is_set():
                self._publish(result, t0, stamp, compare)
        except Exception as exc:  # noqa: BLE001 - keep estimating on the next tick
            if self._stop.is_set():
                return        # shutting down: the publishers may be gone, nothing to report
            self.ingest.count_drop('tick_error')
            self.log.warn('tick_error', f'tick failed: {type(exc).__name__}: {exc}')

    def _header(self, stamp: float | None = None) -> Header:
        """Header in the fixed frame stamped with data time (zero before any data)."""
        header = Header(frame_id=self.values['fixed_frame'])
        if stamp is not None:
            header.stamp = make_time(self.types, stamp)
        return header

    def _publish(self, result, t0: float, stamp: float | None, compare: bool | None = None) -> None:
        """This tick's outputs; ``compare``: the tick's decision to compare the waiting lane
        course with the prior map (taken before it estimated, :meth:`_compare_now` if None)."""
        header = self._header(stamp)
        t = self.types
        self._clear_after_reset(header)
        if result is None or result.intersection is None:
            self.pub_topology.publish(topology_msg(t, header, None, 0, float('-inf'),
                                                   self.estimator.n_observations, 'NO_DATA'))
        else:
            self.pub_topology.publish(topology_msg(t, header, result.intersection, result.topology_samples,
                                                   result.log_posterior, result.observations, result.state))
            if result.lanes_updated:          # the newest lane course waits for its tick
                self._lanes_due = (header, result)
        compare = self._compare_now() if compare is None else compare
        change = self._compare_half() if compare else 0.0
        published = self._lanes_due is not None and self._publish_lanes_now(t0)
        if published:
            self._publish_lanes(*self._lanes_due)
            self._lanes_due = None
        self._tick_ms.append((time.perf_counter() - t0) * 1e3)
        self._tick_ms = self._tick_ms[-100:]
        if result is not None and result.timing_ms:   # what ticks spend besides estimating:
            over = max(self._tick_ms[-1] - result.timing_ms.get('total', 0.0) - change, 0.0)   # messages,
            self._overhead_ms[published].append(over)   # lanelets and markers when published
        self.pub_diag.publish(self._diagnostics(header, result))

    def _compare_now(self) -> bool:
        """Run half of a comparison with the prior map in this tick? The second half always
        follows the first in the next tick; a new comparison starts when a lane course waits
        and ``map_changes_period`` has passed since the last one (~/map_changes is latched;
        comparing costs up to ~130 ms on a large junction, so it is not done on every lane
        update)."""
        return self._comparing is not None or (
            self._changes_due is not None
            and time.monotonic() - self._change_t >= self.values['map_changes_period'])

    def _compare_half(self) -> float:
        """One half of the comparison of the newest lane update with the prior map, each in a
        tick of its own (either costs ~60 ms on a large junction, both together more than the
        budget): first the window's vehicles map-matched to the nearest mapped intersection,
        then the change rules and ~/map_changes. Returns its cost [ms]."""
        tc = time.perf_counter()
        first = self._comparing is None
        if first:
            header, result = self._changes_due
            self._changes_due = None
            self._comparing = (header, result, self.prior.match(result.intersection, self.estimator.window()))
        else:
            self._publish_map_changes(*self._comparing)
            self._comparing, self._change_t = None, time.monotonic()
        ms = (time.perf_counter() - tc) * 1e3
        (self._match_ms if first else self._change_ms).append(ms)
        return ms

    def _publish_lanes_now(self, t0: float) -> bool:
        """Publish the waiting lane course in this tick? Yes when the recent worst cost of
        publishing it still fits into the budget after this tick's estimation, or when it
        has already waited one tick (lanelets are at most one tick period late)."""
        if self._lanes_waited:
            self._lanes_waited = False
            return True
        _, cost = self._overheads()
        if (time.perf_counter() - t0) * 1e3 + cost <= self.values['budget_ms']:
            return True
        self._lanes_waited = True
        return False

    def _publish_lanes(self, header, result) -> None:
        """~/lanelets, the markers and the OSM file of ``result`` (latched: subscribers keep
        the last ones meanwhile); its comparison with the prior map follows in the next two
        ticks (:meth:`_compare_half`; each leaves room for its half)."""
        t = self.types
        self.pub_lanelets.publish(lanelets_msg(t, header, result.lanelets, result.lane_samples))
        markers, self._marker_keys = markers_msg(t, header, result.intersection, result.lanelets,
                                                 self._marker_keys)
        self.pub_markers.publish(markers)
        self._lanes_out = True
        self._write_osm(result.lanelets)
        if self.prior is not None:
            self._changes_due = (header, result)

    def _clear_after_reset(self, header) -> None:
        """The estimator started over: the latched lanes and markers of the previous
        intersection are void -- DELETEALL markers, an empty ~/lanelets."""
        resets = self.estimator.resets
        if resets == self._resets_seen:
            return
        self._resets_seen = resets
        self._lanes_due, self._lanes_waited = None, False    # the previous intersection's
        if self._lanes_out or self._marker_keys:
            self.pub_markers.publish(clear_markers_msg(self.types, header))
            self.pub_lanelets.publish(lanelets_msg(self.types, header, [], 0))
            self._marker_keys, self._lanes_out = frozenset(), False
            self._write_osm([])
            self._change_keys = frozenset()          # DELETEALL took the change markers too
            self._changes_due = self._comparing = None   # the previous intersection's comparison
            self._publish_map_changes(header, None)

    def _publish_map_changes(self, header, result, matched=None) -> None:
        """The estimate against the prior map (when ``prior_map`` is set): ~/map_changes and
        the ``map_changes`` markers (stale ones deleted); None (after a reset): no changes.
        ``matched``: the estimate's :meth:`.fleet.live.LiveChanges.match`, done a tick before
        (the window it matched is not read again)."""
        if self.prior is None:
            return
        from msg_adapters.map_changes import map_change_markers, map_changes_msg
        from .fleet.live import LiveReport
        report = LiveReport(None) if result is None else self.prior.update(
            result.intersection, result.lanelets, matched=matched)
        self.pub_map_changes.publish(map_changes_msg(self.types, header, report))
        markers, self._change_keys = map_change_markers(self.types, header, report, self._change_keys)
        if markers.markers:
            self.pub_markers.publish(markers)

    def _write_osm(self, lanelets) -> None:
        """The lane course as a Lanelet2 map at ``osm_path`` (when set): written beside it
        and renamed, so a planner that reloads the file never reads half a map. A failure
        (folder missing, no permission) is logged, rate-limited, and the node goes on."""
        path = self.values['osm_path']
        if not path:
            return
        from .export.osm import write_osm
        target = Path(path)
        tmp = target.with_name(f'.{target.stem}.tmp.osm')
        try:
            write_osm(tmp, lanelets, origin_latlon=self.values['geo_origin'])
            os.replace(tmp, target)
        except (OSError, RuntimeError, ValueError) as exc:
            self.log.warn('osm_path', f'osm_path={path}: could not write the map: {exc}')

    def _overheads(self) -> tuple[float, float]:
        """[ms] the median overhead of recent plain ticks, the worst of recent ticks that
        published new lanelets and markers."""
        return (float(np.median(self._overhead_ms[False] or [0.0])),
                max(self._overhead_ms[True], default=0.0))

    def _diagnostics(self, header, result) -> DiagnosticArray:
        budget = self.values['budget_ms']
        ticks = np.asarray(self._tick_ms or [0.0])
        state = result.state if result is not None else 'NO_DATA'
        kv = {'state': state, 'observations': self.estimator.n_observations,
              'tick_ms_median': float(np.median(ticks)), 'tick_ms_p95': float(np.percentile(ticks, 95)),
              'tick_ms_last': float(ticks[-1]), 'budget_ms': budget,
              'budget_use': float(np.median(ticks)) / budget,
              **dict(zip(('overhead_ms', 'lanes_publish_ms'), self._overheads())),
              'map_changes_ms': max([*self._change_ms, *self._match_ms], default=0.0)}
        if result is not None:
            drawn = result.topology_samples - self._prev_samples
            self._prev_samples = result.topology_samples
            kv.update(topology_samples=result.topology_samples, lane_samples=result.lane_samples,
                      topology_ms=result.timing_ms.get('topology', 0.0),
                      lanes_ms=result.timing_ms.get('lanes', 0.0),
                      topology_samples_per_s=drawn / max(result.timing_ms.get('topology', 0.0), 1e-6) * 1e3)
        kv.update({f'received_{k}': v for k, v in self.ingest.received.items()})
        kv.update({f'dropped_{k}': v for k, v in self.ingest.dropped.items()})
        level = DiagnosticStatus.OK if state == 'CONVERGED' else DiagnosticStatus.WARN
        if self.ingest.dropped and sum(self.ingest.dropped.values()) > 0.5 * max(1, sum(self.ingest.received.values())):
            level = DiagnosticStatus.WARN
        status = [DiagnosticStatus(level=level, name=f'{self.get_name()}: estimator',
                                   hardware_id='intersection_estimator', message=state,
                                   values=[KeyValue(key=k, value=str(v)) for k, v in kv.items()])]
        if self.ingest.missing:
            status.append(DiagnosticStatus(
                level=DiagnosticStatus.ERROR, name=f'{self.get_name()}: configuration',
                hardware_id='intersection_estimator', message='; '.join(self.ingest.missing),
                values=[KeyValue(key=f'not_subscribed_{i}', value=t) for i, t in enumerate(self.ingest.missing)]))
        return DiagnosticArray(header=header, status=status)
