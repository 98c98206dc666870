# Copyright 2026 mpc_local_planner developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.


"""The base of this package's lifecycle nodes (controller, planner, map server)."""

from __future__ import annotations

from typing import Any

from rclpy.lifecycle import (
    LifecycleNode,
    LifecyclePublisher,
    LifecycleState,
    TransitionCallbackReturn,
)
from rclpy.subscription import Subscription
from rclpy.timer import Timer

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
    """

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
