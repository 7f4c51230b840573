"""Issue 16: the managed node over real DDS, driven through lifecycle_msgs services as
nav2_lifecycle_manager drives it: configure -> activate -> deactivate -> cleanup -> shutdown."""

from __future__ import annotations

import pytest

from conftest import script, wait_for
from test_node_dds import _spinner, _subscribe

pytestmark = pytest.mark.dds
NODE = '/intersection_estimator'


class Lifecycle:
    """Client of a lifecycle node's ~/change_state and ~/get_state."""

    def __init__(self, ctx, spin, node):
        from lifecycle_msgs.srv import ChangeState, GetState
        self.spin, self.node = spin, node
        self.change = node.create_client(ChangeState, f'{NODE}/change_state')
        self.get = node.create_client(GetState, f'{NODE}/get_state')
        self.ChangeState, self.GetState = ChangeState, GetState

    def ready(self) -> bool:
        return self.change.service_is_ready() and self.get.service_is_ready()

    def matched(self) -> bool:
        """Does ~/change_state answer us, and refuse what it cannot do? A transition is not
        idempotent, so it cannot be re-sent when its answer is lost; a request with an
        unknown transition label is (the node answers ``success=False`` and stays where it
        is), so it is re-sent until answered, which proves the service's response writer has
        matched our reader before the first real transition goes out."""
        probe = self.ChangeState.Request()
        probe.transition.label = 'not_a_transition'
        return not self._call(self.change, probe, attempt=10.0).success

    def _call(self, client, request, timeout: float = 120.0, attempt: float | None = None):
        """One request, answered within ``timeout``; with ``attempt`` (idempotent requests
        only) re-sent every ``attempt`` seconds until then: Fast DDS can drop the answer to
        a request sent right after the service was discovered, when the server's response
        writer has not yet matched our response reader (ros2/rmw_fastrtps#392, #842)."""
        per = timeout if attempt is None else attempt
        waited = 0.0
        while waited < timeout:
            future = client.call_async(request)
            if wait_for(future.done, per, self.spin):
                return future.result()
            client.remove_pending_request(future)
            waited += per
        raise AssertionError(f'{client.srv_name}: no answer in {timeout} s')

    def state(self) -> int:
        return self._call(self.get, self.GetState.Request(), attempt=10.0).current_state.id

    def transition(self, transition_id: int) -> bool:
        req = self.ChangeState.Request()
        req.transition.id = transition_id
        return self._call(self.change, req).success


def test_managed_node_follows_its_transitions(ros_context, node_process):
    from diagnostic_msgs.msg import DiagnosticArray
    from intersection_estimator_msgs.msg import Topology
    from lifecycle_msgs.msg import State, Transition
    proc = node_process([script('intersection_estimator_lifecycle_node'), '--ros-args', '-p', 'timer_period:=0.1'])
    listener, topos = _subscribe(ros_context, Topology, f'{NODE}/topology', 'latched')
    diags = []
    listener.create_subscription(DiagnosticArray, '/diagnostics', diags.append, 50)
    try:
        spin = _spinner(ros_context, listener)
        lc = Lifecycle(ros_context, spin, listener)
        assert wait_for(lc.ready, 120, spin), proc.output()
        assert lc.matched()
        assert lc.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert topos == [] and diags == []                # nothing is published unconfigured
        assert lc.transition(Transition.TRANSITION_CONFIGURE), proc.output()
        assert lc.state() == State.PRIMARY_STATE_INACTIVE
        assert 'listening to' in proc.output()            # subscriptions made at configure
        assert lc.transition(Transition.TRANSITION_ACTIVATE), proc.output()
        assert lc.state() == State.PRIMARY_STATE_ACTIVE
        assert wait_for(lambda: topos and diags, 60, spin), proc.output()
        assert topos[-1].state == Topology.NO_DATA
        assert lc.transition(Transition.TRANSITION_DEACTIVATE), proc.output()
        assert lc.state() == State.PRIMARY_STATE_INACTIVE
        wait_for(lambda: False, 3.0, spin)                # what was in flight arrives
        n = len(diags)                                    # thread stopped: no more ticks
        wait_for(lambda: False, 3.0, spin)                # (at 0.1 s a period: ~30 if not)
        assert len(diags) == n
        assert lc.transition(Transition.TRANSITION_CLEANUP), proc.output()
        assert lc.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert lc.transition(Transition.TRANSITION_CONFIGURE), proc.output()     # and again
        assert lc.transition(Transition.TRANSITION_INACTIVE_SHUTDOWN), proc.output()
        assert lc.state() == State.PRIMARY_STATE_FINALIZED
        assert proc.alive(), proc.output()
        assert proc.stop() == 0, proc.output()
        assert 'Traceback' not in proc.output() and 'not activated' not in proc.output(), proc.output()
    finally:
        listener.destroy_node()


def test_managed_node_refuses_to_configure_with_a_bad_parameter(ros_context, node_process):
    from lifecycle_msgs.msg import State, Transition
    from rclpy.node import Node
    proc = node_process([script('intersection_estimator_lifecycle_node'), '--ros-args', '-p', 'budget_ms:=-5.0'])
    client = Node('ie_test_lifecycle', context=ros_context)
    try:
        spin = _spinner(ros_context, client)
        lc = Lifecycle(ros_context, spin, client)
        assert wait_for(lc.ready, 120, spin), proc.output()
        assert lc.matched()
        assert not lc.transition(Transition.TRANSITION_CONFIGURE)
        assert lc.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert wait_for(lambda: 'budget_ms' in proc.output(), 60), proc.output()
        assert 'Traceback' not in proc.output()
    finally:
        client.destroy_node()
