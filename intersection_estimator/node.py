"""``intersection_estimator_node``: the estimator beside a perception stack (thin rclpy shell).

Subscriptions hand messages to :mod:`msg_adapters` (via :mod:`.ingest`); the timer wakes
an estimation thread that spends the tick budget in :class:`~.pipeline.OnlineEstimator`,
and the result goes out on ``~/topology``, ``~/lanelets``, ``~/markers`` and
``/diagnostics``.

Why a thread of its own and not a timer callback in a multi-threaded executor: while a
long callback of a mutually exclusive group runs, rclpy's ``MultiThreadedExecutor``
keeps finding the timer ready and spins on it, holding the GIL; the estimator's
Python steps then waited for the GIL tick after tick (measured: ticks of 0.3-5 s against
a 150 ms budget, the process at 60 % CPU). Here the executor only runs short callbacks
(inputs, the timer's wake-up), and the compiled samplers release the GIL
(``nogil``), so inputs are served while the estimator samples.
"""

from __future__ import annotations

from collections import deque
import gc
import sys
import threading
import time

import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rcl_interfaces.msg import ParameterDescriptor, ParameterType, SetParametersResult
from rcl_interfaces.msg import FloatingPointRange, IntegerRange

from . import params as P
from .ingest import Ingest, RateLimitedLog, tick
from .pipeline import OnlineEstimator, warmup

from msg_adapters.types import RclpyTypes
from msg_adapters.topology import topology_msg
from msg_adapters.lanelets import lanelets_msg
from msg_adapters.markers import markers_msg

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_msgs.msg import Header

_PTYPE = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
          float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING}
_ARRAY = {str: ParameterType.PARAMETER_STRING_ARRAY, float: ParameterType.PARAMETER_DOUBLE_ARRAY,
          int: ParameterType.PARAMETER_INTEGER_ARRAY}
#: parameters that only take effect at start-up (topics, frames); the rest apply live
_STARTUP_ONLY = frozenset({'radar_topics', 'radar_scan_topics', 'detection_topics', 'object_topics',
                           'autoware_object_topics', 'odometry_topic', 'fixed_frame', 'timer_period'})
_STATE = {'NO_DATA': 0, 'CONVERGING': 1, 'CONVERGED': 2}
#: inputs: best effort (matches reliable and best-effort publishers, as sensor data QoS), but
#: a queue deep enough for bursts (several sensors at once, bag playback, a slow tick):
#: sensor data QoS keeps 5 and drops the rest silently
INPUT_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT,
                       durability=DurabilityPolicy.VOLATILE)


def _descriptor(spec: P.ParamSpec) -> ParameterDescriptor:
    d = ParameterDescriptor(description=spec.description + (f' ({spec.allowed()})' if spec.lo is not None
                                                             or spec.choices else ''))
    if isinstance(spec.default, list):
        d.type = _ARRAY[type(spec.default[0])]
    else:
        d.type = _PTYPE[type(spec.default)]
    if spec.lo is not None and isinstance(spec.default, float):
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.lo), to_value=float(spec.hi))]
    elif spec.lo is not None and isinstance(spec.default, int) and not isinstance(spec.default, bool):
        d.integer_range = [IntegerRange(from_value=int(spec.lo), to_value=int(spec.hi), step=0)]
    d.read_only = spec.name in _STARTUP_ONLY
    return d


class IntersectionEstimatorNode(Node):
    """Estimates the intersection ahead from live perception output (DESIGN.md §4)."""

    def __init__(self, **kwargs):
        super().__init__('intersection_estimator', **kwargs)
        for spec in P.PARAMS:
            self.declare_parameter(spec.name, spec.default, _descriptor(spec))
        self.values = {s.name: self.get_parameter(s.name).value for s in P.PARAMS}
        errors = P.check_all(self.values)
        if errors:
            raise ValueError('invalid parameters: ' + '; '.join(errors))
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self.log = RateLimitedLog(self.get_logger(), period_s=5.0)
        self.estimator = OnlineEstimator(P.pipeline_config(self.values), seed=self.values['seed'])
        self.ingest = Ingest(self.values, RclpyTypes())
        self.types = RclpyTypes()
        self._marker_keys: set = set()
        self._tick_ms: list[float] = []
        # recent time [ms] ticks spent besides estimating, per kind (see _tick): the budget
        # keeps the median of plain ticks and the worst of recent lane-publishing ticks back
        self._overhead_ms = {False: deque(maxlen=20), True: deque(maxlen=5)}
        self._prev_samples = 0

        from intersection_estimator_msgs.msg import LaneletArray, Topology
        from visualization_msgs.msg import MarkerArray
        latched = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_topology = self.create_publisher(Topology, '~/topology', latched)
        self.pub_lanelets = self.create_publisher(LaneletArray, '~/lanelets', latched)
        self.pub_markers = self.create_publisher(MarkerArray, '~/markers', latched)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)

        for role, topic, msg_type in self.ingest.subscriptions():
            self.create_subscription(msg_type, topic, self._callback(role), INPUT_QOS)
            self.get_logger().info(f'listening to {topic} ({role})')
        header = Header(frame_id=self.values['fixed_frame'], stamp=self.get_clock().now().to_msg())
        self.pub_topology.publish(topology_msg(self.types, header, None, 0, float('-inf'), 0, 'NO_DATA'))
        self._wake, self._stop = threading.Event(), threading.Event()
        self._worker = threading.Thread(target=self._estimation_loop, name='estimator', daemon=True)
        self._worker.start()
        self.timer = self.create_timer(self.values['timer_period'], self._wake.set)

    def _estimation_loop(self) -> None:
        """Compile (or load) the kernels, then one tick per timer period (a late tick skips
        the periods it missed). The node is on the graph meanwhile: inputs are kept, the
        latched topology says NO_DATA."""
        self.get_logger().info(f'estimator kernels ready in {warmup():.1f} s')
        gc.collect()
        gc.freeze()     # start-up objects (types, kernels) out of the collector: shorter pauses
        while not self._stop.is_set():
            if self._wake.wait(0.5) and not self._stop.is_set():
                self._wake.clear()
                self._tick()

    def destroy_node(self):
        self._stop.set()
        self._wake.set()
        self._worker.join(timeout=10.0)
        return super().destroy_node()

    # -- inputs ---------------------------------------------------------------------------
    def _callback(self, role: str):
        def on_message(msg):
            try:
                self.ingest.handle(role, msg, self.estimator)
            except Exception as exc:  # noqa: BLE001 - a callback must never die on input
                self.ingest.count_drop('internal_error')
                self.log.warn('internal_error', f'{role}: dropped a message: {type(exc).__name__}: {exc}')
            for reason, text in self.ingest.pop_warnings():
                self.log.warn(reason, text)
        return on_message

    # -- estimation -----------------------------------------------------------------------
    def _tick(self) -> None:
        t0 = time.perf_counter()
        try:
            samples = self.estimator.result.topology_samples
            base, lanes = self._overheads()
            result = tick(self.ingest, self.estimator, wall_budget=True, log=self.get_logger().info,
                          budget_s=max(self.values['budget_ms'] - base, 0.5 * self.values['budget_ms']) / 1e3,
                          lanes_reserve_s=min(max(lanes - base, 0.0), 0.5 * self.values['budget_ms']) / 1e3)
            if result is not None and result.topology_samples < samples:
                self._prev_samples = 0
            self._publish(result, t0)
        except Exception as exc:  # noqa: BLE001 - keep estimating on the next tick
            self.ingest.count_drop('tick_error')
            self.log.warn('tick_error', f'tick failed: {type(exc).__name__}: {exc}')

    def _publish(self, result, t0: float) -> None:
        header = Header(frame_id=self.values['fixed_frame'])
        stamp = self.ingest.latest_stamp
        header.stamp = (rclpy.time.Time(seconds=stamp).to_msg() if stamp is not None
                        else self.get_clock().now().to_msg())
        t = self.types
        if result is None or result.intersection is None:
            self.pub_topology.publish(topology_msg(t, header, None, 0, float('-inf'),
                                                   self.estimator.n_observations, 'NO_DATA'))
        else:
            self.pub_topology.publish(topology_msg(t, header, result.intersection, result.topology_samples,
                                                   result.log_posterior, result.observations, result.state))
            if result.lanes_updated:   # latched: subscribers keep the last one meanwhile
                self.pub_lanelets.publish(lanelets_msg(t, header, result.lanelets, result.lane_samples))
                markers, self._marker_keys = markers_msg(t, header, result.intersection, result.lanelets,
                                                         self._marker_keys)
                self.pub_markers.publish(markers)
        self._tick_ms.append((time.perf_counter() - t0) * 1e3)
        self._tick_ms = self._tick_ms[-100:]
        if result is not None and result.timing_ms:   # what ticks spend besides estimating:
            over = max(self._tick_ms[-1] - result.timing_ms.get('total', 0.0), 0.0)   # messages,
            self._overhead_ms[bool(result.lanes_updated)].append(over)   # markers when lanes changed
        self.pub_diag.publish(self._diagnostics(header, result))

    def _overheads(self) -> tuple[float, float]:
        """[ms] the median overhead of recent plain ticks, the worst of recent ticks that
        published new lanelets and markers."""
        return (float(np.median(self._overhead_ms[False] or [0.0])),
                max(self._overhead_ms[True], default=0.0))

    def _diagnostics(self, header, result) -> DiagnosticArray:
        budget = self.values['budget_ms']
        ticks = np.asarray(self._tick_ms)
        state = result.state if result is not None else 'NO_DATA'
        kv = {'state': state, 'observations': self.estimator.n_observations,
              'tick_ms_median': float(np.median(ticks)), 'tick_ms_p95': float(np.percentile(ticks, 95)),
              'tick_ms_last': float(ticks[-1]), 'budget_ms': budget,
              'budget_use': float(np.median(ticks)) / budget,
              **dict(zip(('overhead_ms', 'lanes_publish_ms'), self._overheads()))}
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
        status = DiagnosticStatus(level=level, name=f'{self.get_name()}: estimator',
                                  hardware_id='intersection_estimator', message=state,
                                  values=[KeyValue(key=k, value=str(v)) for k, v in kv.items()])
        return DiagnosticArray(header=header, status=[status])

    # -- parameters -----------------------------------------------------------------------
    def _on_set_parameters(self, changes: list[Parameter]) -> SetParametersResult:
        new = dict(self.values)
        for p in changes:
            if p.name in _STARTUP_ONLY:
                return SetParametersResult(successful=False, reason=f'{p.name} is read-only at run time')
            new[p.name] = p.value
        errors = P.check_all(new)
        if not errors:
            try:
                cfg = P.pipeline_config(new)
            except ValueError as exc:
                errors = [str(exc)]
        if errors:
            return SetParametersResult(successful=False, reason='; '.join(errors))
        self.values = new
        self.estimator.config = cfg
        self.ingest.configure(new)
        return SetParametersResult(successful=True)


def main(argv: list[str] | None = None) -> int:
    """Console script ``intersection_estimator_node`` (``ros2 run intersection_estimator ...``)."""
    argv = sys.argv if argv is None else argv
    if any(a in ('-h', '--help') for a in argv[1:]) and '--ros-args' not in argv:
        print(__doc__.strip().splitlines()[0])
        print('\nusage: intersection_estimator_node [--ros-args -p NAME:=VALUE ... '
              '--params-file config/intersection_estimator.yaml -r __ns:=/NS]\n\nparameters:')
        for spec in P.PARAMS:
            print(f'  {spec.name:28s} {spec.description} (default {spec.default!r})')
        return 0
    rclpy.init(args=argv)
    node = None
    try:
        node = IntersectionEstimatorNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except ValueError as exc:
        print(f'intersection_estimator_node: {exc}', file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
