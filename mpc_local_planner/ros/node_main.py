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

"""The main() every node shares: ``--help``, lifecycle autostart, spin until Ctrl-C, exit codes.

``<executable> --help`` prints the node's parameters with their defaults and starts nothing
(no rclpy.init, no files written), as a user of ``ros2 run`` expects.

A lifecycle node whose ``autostart`` parameter is true is configured and activated at once,
so ``ros2 run`` alone gives a working node; with autostart false it waits for a lifecycle
manager (or ``ros2 lifecycle set``). A configure that fails is refused like bad parameters.

Ctrl-C (SIGINT) ends the spin cleanly: no traceback, no error log, exit code 0.

A node that cannot start with its parameters (or the files they name) says why in one line
on stderr and exits with EXIT_INVALID_PARAMETERS instead of a traceback, so that a launch
file, a supervisor or closed_loop --respawn can tell "misconfigured" from "crashed".
"""

from __future__ import annotations

import functools
import sys
from typing import Any, Callable, Sequence, TypeVar

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.utilities import remove_ros_args

from mpc_local_planner.ros.parameters import format_help, ParameterSpec

__all__ = ['EXIT_INVALID_PARAMETERS', 'autostart', 'destroy_on_failure', 'run_node',
           'wants_help']

# Exit code of a node whose parameters are invalid.
EXIT_INVALID_PARAMETERS = 2

_Init = TypeVar('_Init', bound=Callable[..., None])


def destroy_on_failure(init: _Init) -> _Init:
    """Decorate a node's __init__: if it raises, destroy the half-built node, then re-raise.

    A node whose constructor raised (invalid parameters, a file that cannot be read) is never
    destroyed by its caller; rclpy then finalises its handle at some later garbage collection,
    which unregisters the /rosout publisher of whichever node has the same name by then, so
    that node's log lines are silently lost. Destroying it at once avoids that.
    """

    @functools.wraps(init)
    def wrapper(self: Node, *args: Any, **kwargs: Any) -> None:
        try:
            init(self, *args, **kwargs)
        except BaseException:
            try:
                self.destroy_node()
            except Exception:  # the node may not have been built far enough to destroy
                pass
            raise

    return wrapper  # type: ignore[return-value]


def wants_help(args: Sequence[str] | None) -> bool:
    """Say whether the command line (without its --ros-args part) asks for --help."""
    argv = list(sys.argv if args is None else args)
    return any(arg in ('-h', '--help') for arg in remove_ros_args(argv)[1:])


def autostart(node: LifecycleNode) -> str | None:
    """Configure and activate node if its ``autostart`` parameter is true.

    Returns:
        None when the node is active (or waits for a manager), else why it is not.

    """
    if not node.get_parameter('autostart').value:
        return None
    if node.trigger_configure() != TransitionCallbackReturn.SUCCESS:
        return 'configure failed (see the log above)'
    if node.trigger_activate() != TransitionCallbackReturn.SUCCESS:
        return 'activate failed (see the log above)'
    return None


def run_node(make_node: Callable[[], Node], name: str, args: list[str] | None = None, *,
             summary: str = '', parameters: Sequence[ParameterSpec] = ()) -> int:
    """Print --help, or create the node (autostarting a lifecycle node) and spin it.

    Args:
        make_node: builds the node (after rclpy.init).
        name: the executable's name, for messages.
        args: the command line, sys.argv by default.
        summary: what the node does, for --help.
        parameters: the node's parameter table, for --help.

    Returns:
        0, or EXIT_INVALID_PARAMETERS if creating (or configuring) the node failed on its
        parameters.

    """
    if wants_help(args):
        print(format_help(name, summary, parameters), end='')
        return 0
    rclpy.init(args=args)
    node = None
    try:
        try:
            node = make_node()
            problem = autostart(node) if isinstance(node, LifecycleNode) else None
        except (ParameterException, ValueError, TypeError, OSError) as err:
            problem = str(err)
        if problem is not None:
            print(f'{name}: refusing to start: {problem}', file=sys.stderr, flush=True)
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
