"""``intersection_estimator_node``: the estimator beside a perception stack (thin rclpy shell).

Subscriptions hand messages to :mod:`msg_adapters` (via :mod:`.ingest`); the timer wakes
an estimation thread that spends the tick budget in :class:`~.pipeline.OnlineEstimator`,
and the result goes out on ``~/topology``, ``~/lanelets``, ``~/markers`` and
``/diagnostics`` (see :mod:`.node_core`). This is the plain node (the default); the
managed one, for ``nav2_lifecycle_manager``, is :mod:`.node_lifecycle`.

Start-up refuses a bad parameter with one line naming it (exit code 2, no traceback).
SIGINT / SIGTERM stop the estimation thread first, then the node and the context.
"""

from __future__ import annotations

import signal
import sys
import threading

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from . import params as P
from .node_core import EstimatorCore

__all__ = ['IntersectionEstimatorNode', 'main', 'run']


class IntersectionEstimatorNode(EstimatorCore, Node):
    """Estimates the intersection ahead from live perception output (DESIGN.md §4)."""

    def __init__(self, **kwargs):
        super().__init__('intersection_estimator', **kwargs)
        errors = self.declare_estimator_parameters()
        values, more = self.current_values() if not errors else ({}, [])
        if errors or more:
            raise ValueError('invalid parameter(s): ' + '; '.join(errors or more))
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.setup_estimator(values)
        self.create_outputs(self.create_publisher)
        self.create_inputs()
        self.start_worker()

    def destroy_node(self):
        self.stop_worker()
        return super().destroy_node()


def _usage(doc: str, executable: str) -> None:
    print(doc.strip().splitlines()[0])
    print(f'\nusage: {executable} [--ros-args -p NAME:=VALUE ... '
          '--params-file config/intersection_estimator.yaml -r __ns:=/NS]\n\nparameters:')
    for spec in P.PARAMS:
        print(f'  {spec.name:28s} {spec.description} (default {spec.default!r})')


def run(make_node, argv: list[str], doc: str, executable: str) -> int:
    """Init, build the node with ``make_node()``, spin until SIGINT / SIGTERM / shutdown;
    then stop the estimation thread *before* the node and the context go."""
    if any(a in ('-h', '--help') for a in argv[1:]) and '--ros-args' not in argv:
        _usage(doc, executable)
        return 0
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    node, code = None, 0
    try:
        node = make_node()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except ValueError as exc:
        print(f'{executable}: {exc}', file=sys.stderr)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.stop_worker()
            node.destroy_node()
        rclpy.try_shutdown()
    return code


def main(argv: list[str] | None = None) -> int:
    """Console script ``intersection_estimator_node`` (``ros2 run intersection_estimator ...``)."""
    return run(IntersectionEstimatorNode, sys.argv if argv is None else argv, __doc__,
               'intersection_estimator_node')


if __name__ == '__main__':
    sys.exit(main())
