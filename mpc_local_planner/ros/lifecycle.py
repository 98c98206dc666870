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

from rclpy.lifecycle import LifecycleNode

__all__ = ['ManagedNode']


class ManagedNode(LifecycleNode):
    """A LifecycleNode whose destroy_node frees its rcl node at once.

    rclpy 7.1's LifecycleNode leaves its state machine, which holds the rcl node handle, to
    the garbage collector: the rcl node outlives destroy_node, and when it is collected it
    unregisters the /rosout publisher of whichever node has the same name by then, whose logs
    then silently stop (seen in tests that start a node again under the same name).
    """

    def destroy_node(self) -> None:
        """Destroy the node and its lifecycle state machine now, not at garbage collection."""
        super().destroy_node()
        self._state_machine.destroy_when_not_in_use()
