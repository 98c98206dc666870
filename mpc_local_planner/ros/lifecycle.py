# SPDX-License-Identifier: Apache-2.0
"""The base of this package's lifecycle nodes (controller, planner, map server)."""

from __future__ import annotations

from typing import Any

from lifecycle_msgs.msg import Transition
from rclpy.lifecycle import (
    LifecycleNode,
    LifecyclePublisher,
    LifecycleState,
    TransitionCallbackReturn,
)
from rclpy.subscription import Subscription
from rclpy.timer import Timer

from mpc_local_planner.ros.lockstep import LockstepReporter

__all__ = ['ManagedNode']


class ManagedNode(LifecycleNode):
    """A LifecycleNode that releases what configure made, and frees its rcl node at once.

    cleanup, shutdown (from any state) and error (after a transition raised) all end in
    release(), which a node overrides to destroy its timers, publishers and subscriptions
    (destroy_entities) and drop its state, so that it can be configured again. Its
    messages name the transition in the log.

    rclpy 7.1's LifecycleNode leaves its state machine, which holds the rcl node handle, to
    the garbage collector: the rcl node outlives destroy_node, and when it is collected it
    unregisters the /rosout publisher of whichever node has the same name by then, whose logs
    then silently stop (seen in tests that start a node again under the same name).

    A transition the current state does not have (activate while unconfigured, configure
    while active, an unknown id) is refused: the change_state service answers
    ``success: false``, a ``trigger_*`` call returns FAILURE, the node stays where it is and
    says so in one warning. rclpy 7.1 instead raises RCLError out of the service callback
    (ros2/rclpy#1209), which ends the executor's spin and so the process, with no answer to
    the caller and, for the controller, no zero cmd_vel.

    A node with the parameter ``lockstep`` true takes part in a lockstep simulation
    (ros/lockstep.py): its reporter starts counting when it activates, before on_activate
    publishes (the map server publishes its map there), and reports once it is active.
    """

    _lockstep: LockstepReporter | None = None

    def transition_available(self, transition_id: int) -> bool:
        """Say whether the current state has a transition of this id."""
        return any(description[0] == transition_id
                   for description in self._state_machine.available_transitions)

    def _LifecycleNodeMixin__change_state(self, transition_id: int) -> TransitionCallbackReturn:
        """Run a transition if the current state has it; else refuse it and stay (rclpy#1209).

        This overrides rclpy's private ``LifecycleNodeMixin.__change_state`` (name-mangled),
        the one place both the change_state service and every ``trigger_*`` method go
        through; rclpy 7.1 offers no public hook there.
        """
        if not self.transition_available(transition_id):
            label = self._state_machine.current_state[1]
            self.get_logger().warning(
                f'transition {_transition_name(transition_id)} refused: the node is '
                f'{label}, which has no such transition (it stays {label})')
            return TransitionCallbackReturn.FAILURE
        activating = (transition_id == Transition.TRANSITION_ACTIVATE
                      and self.has_parameter('lockstep')
                      and bool(self.get_parameter('lockstep').value))
        if activating:
            if self._lockstep is None:
                self._lockstep = LockstepReporter(self)
            self._lockstep.attach()
        result = super()._LifecycleNodeMixin__change_state(transition_id)
        if activating and result == TransitionCallbackReturn.SUCCESS:
            self._lockstep.report()
        return result

    def trigger_shutdown(self) -> TransitionCallbackReturn:
        """Shut down from unconfigured, inactive or active; refuse it from anywhere else."""
        state = self._state_machine.current_state[1]
        if state not in ('unconfigured', 'inactive', 'active'):
            self.get_logger().warning(f'shutdown refused: the node is {state}')
            return TransitionCallbackReturn.FAILURE
        return super().trigger_shutdown()

    def release(self) -> None:
        """Free what configure made (nothing here); each transition out of it calls this."""

    def destroy_entities(self, *entities: Any) -> None:
        """Destroy each lifecycle publisher, subscription or timer given (None is skipped)."""
        for entity in entities:
            if isinstance(entity, LifecyclePublisher):
                self.destroy_lifecycle_publisher(entity)
            elif isinstance(entity, Subscription):
                self.destroy_subscription(entity)
            elif isinstance(entity, Timer):
                self.destroy_timer(entity)
            elif entity is not None:
                msg = f'cannot destroy a {type(entity).__name__}'
                raise TypeError(msg)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release what configure made."""
        self.release()
        self.get_logger().info('cleaned up')
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release everything, from whichever state the node is in."""
        self.release()
        return super().on_shutdown(state)

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release everything after a failed transition, so that it can be configured again."""
        self.release()
        return super().on_error(state)

    def destroy_node(self) -> None:
        """Destroy the node and its lifecycle state machine now, not at garbage collection."""
        super().destroy_node()
        self._state_machine.destroy_when_not_in_use()

    def on_exit(self) -> None:
        """Do what must be done before the process ends (nothing here; see node_main).

        Called once by run_node while the context is still up, whatever ends the spin:
        Ctrl-C, SIGTERM or an exception. The controller publishes a zero cmd_vel here.
        """


def _transition_name(transition_id: int) -> str:
    """Return a transition id's name as lifecycle_msgs/Transition spells it, or the id."""
    for name in dir(Transition):
        if name.startswith('TRANSITION_') and getattr(Transition, name) == transition_id:
            return f'{name[len("TRANSITION_"):].lower()} ({transition_id})'
    return f'{transition_id} (unknown)'

