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

"""The main() every node shares: spin until Ctrl-C, refuse bad parameters with exit code 2.

Ctrl-C (SIGINT) ends the spin cleanly: no traceback, no error log, exit code 0.

A node that cannot start with its parameters (or the files they name) says why in one line
on stderr and exits with EXIT_INVALID_PARAMETERS instead of a traceback, so that a launch
file, a supervisor or closed_loop --respawn can tell "misconfigured" from "crashed".
"""

from __future__ import annotations

import sys
from typing import Callable

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

__all__ = ['EXIT_INVALID_PARAMETERS', 'run_node']

# Exit code of a node whose parameters are invalid.
EXIT_INVALID_PARAMETERS = 2


def run_node(make_node: Callable[[], Node], name: str, args: list[str] | None = None) -> int:
    """Create the node and spin it until Ctrl-C or shutdown.

    Returns:
        0, or EXIT_INVALID_PARAMETERS if creating the node raised on its parameters.

    """
    rclpy.init(args=args)
    node = None
    try:
        try:
            node = make_node()
        except (ParameterException, ValueError, TypeError, OSError) as err:
            print(f'{name}: refusing to start: {err}', file=sys.stderr, flush=True)
            return EXIT_INVALID_PARAMETERS
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # Ctrl-C can shut the context down while the executor builds its wait set (rclpy 7.1
        # then raises RCLError, not ExternalShutdownException): a clean stop all the same.
        # With the context still up, it is a failure.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
