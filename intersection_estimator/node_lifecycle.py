"""``intersection_estimator_lifecycle_node``: the estimator as a managed node (REP 2002 /
``rclpy.lifecycle``), e.g. under ``nav2_lifecycle_manager``.

Transitions (``lifecycle_msgs/srv/ChangeState`` on ``~/change_state``):

* configure -- read and check the parameters (a bad one fails the transition with one
  error line naming it), build the estimator, create the publishers and the input
  subscriptions (inputs are kept from now on);
* activate -- publishers on, the empty latched topology out, the estimation thread and
  its timer started;
* deactivate -- timer and thread stopped (before the publishers go off: no tick publishes
  on an inactive publisher), publishers off; the window is kept;
* cleanup -- subscriptions, publishers and the estimator dropped (back to unconfigured);
* shutdown -- from any state: the thread stopped, everything dropped.

The plain node (:mod:`.node`) stays the default executable.
"""

from __future__ import annotations

import sys

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from .node import run
from .node_core import EstimatorCore

__all__ = ['ManagedIntersectionEstimatorNode', 'main']


class ManagedIntersectionEstimatorNode(EstimatorCore, LifecycleNode):
    """The intersection estimator with a managed life cycle."""

    def __init__(self, **kwargs):
        super().__init__('intersection_estimator', **kwargs)
        self._declare_errors = self.declare_estimator_parameters()
        self.values, self.estimator, self._worker = {}, None, None
        self.add_on_set_parameters_callback(self.on_set_parameters)

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        errors = self._declare_errors
        values, errors = self.current_values() if not errors else ({}, errors)
        if errors:
            self.get_logger().error('configure failed: invalid parameter(s): ' + '; '.join(errors))
            return TransitionCallbackReturn.FAILURE
        try:
            self.setup_estimator(values)
        except ValueError as exc:          # e.g. a prior_map that does not load
            self.get_logger().error(f'configure failed: {exc}')
            self.estimator = None
            return TransitionCallbackReturn.FAILURE
        self.create_outputs(self.create_lifecycle_publisher)
        self.create_inputs()
        return super().on_configure(state)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = super().on_activate(state)      # publishers on first: start_worker publishes
        self.start_worker()
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.stop_worker()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._drop_all()
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.stop_worker()
        self._drop_all()
        return super().on_shutdown(state)

    def _drop_all(self) -> None:
        if self.estimator is None:
            return
        self.destroy_inputs()
        for pub in (self.pub_topology, self.pub_lanelets, self.pub_markers, self.pub_diag, self.pub_map_changes):
            self.destroy_lifecycle_publisher(pub)
        self.estimator = None

    def destroy_node(self):
        self.stop_worker()
        return super().destroy_node()


def main(argv: list[str] | None = None) -> int:
    """Console script ``intersection_estimator_lifecycle_node``."""
    return run(ManagedIntersectionEstimatorNode, sys.argv if argv is None else argv, __doc__,
               'intersection_estimator_lifecycle_node')


if __name__ == '__main__':
    sys.exit(main())
