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

"""Session-wide test setup: isolate ROS 2 discovery before anything imports rclpy.

The environment is set at import time because DDS reads it when the first context is
initialised; pytest imports conftest.py before any test module, hence before rclpy.
Keeping discovery on localhost and using a domain id derived from the pid keeps parallel
test sessions (and other machines) from seeing each other's nodes.
"""

from __future__ import annotations

import os

# Domain ids 1..100: 0 is the default everyone else uses, and ids above ~101 collide with
# the ephemeral port range on Linux for some RMW implementations.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ['ROS_DOMAIN_ID'] = str(1 + os.getpid() % 100)


# ----------------------------------------------------------------------------- rclpy fixtures
# Imported after the environment is set (above): DDS reads it at the first rclpy.init.
import time  # noqa: E402
from typing import Callable, Iterator  # noqa: E402

import pytest  # noqa: E402


class RosHarness:
    """One rclpy context, a SingleThreadedExecutor on it, and the nodes a test adds."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        self.context = Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list = []

    def add(self, node):  # noqa: ANN001, ANN201 (any rclpy Node)
        """Spin node with the others; it is destroyed at teardown."""
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def spin_until(self, condition: Callable[[], bool], timeout: float = 10.0) -> bool:
        """Spin until condition() holds or timeout wall seconds pass; return condition()."""
        deadline = time.monotonic() + timeout
        while not condition() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)
        return condition()

    def close(self) -> None:
        """Tear down in rclpy's order: executor, nodes, context."""
        import rclpy

        self.executor.shutdown()
        for node in reversed(self.nodes):
            node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def ros() -> Iterator[RosHarness]:
    """Yield a fresh rclpy context with an executor; tear everything down afterwards."""
    harness = RosHarness()
    try:
        yield harness
    finally:
        harness.close()
