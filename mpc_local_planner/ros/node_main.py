# SPDX-License-Identifier: Apache-2.0
"""The main() every node shares: ``--help``, lifecycle autostart, spin until Ctrl-C, exit codes.

``<executable> --help`` prints the node's parameters with their defaults and starts nothing
(no rclpy.init, no files written), as a user of ``ros2 run`` expects.

A lifecycle node whose ``autostart`` parameter is true is configured and activated at once,
so ``ros2 run`` alone gives a working node; with autostart false it waits for a lifecycle
manager (or ``ros2 lifecycle set``). A configure that fails is refused like bad parameters.

Ctrl-C (SIGINT) and SIGTERM end the spin cleanly: no traceback, no error log, exit code 0.
Whatever ends the spin (a signal, or an exception escaping a callback), a lifecycle node's
``on_exit`` runs first, while the context is still up: the controller publishes a zero
cmd_vel there, so a process that ends does not leave the robot driving on its last
command. rclpy's own signal handlers would shut the context down before any of this could
publish, so run_node installs its own, which only ask the spin loop to stop; the loop wakes
every SPIN_WAKE_S to see that. A process killed outright (SIGKILL, a power cut) can send
nothing: the base's cmd_vel timeout (the simulator's ``cmd_timeout``) is the last line of
defence.

A node that cannot start with its parameters (or the files they name) says why in one line
on stderr and exits with EXIT_INVALID_PARAMETERS instead of a traceback, so that a launch
file, a supervisor or closed_loop --respawn can tell "misconfigured" from "crashed". So does
one given a parameter it does not declare (a typo: ros/parameters.py), and one whose command
line rcl refuses: a params file that is missing, not YAML, or not laid out as rcl reads it.
A params file without a section for the node (its sections match neither the node's fully
qualified name nor ``/**``) is used by nothing; the node says so in one warning and starts.
"""

from __future__ import annotations

import difflib
import functools
import os
import signal
import sys
import tempfile
from types import FrameType
from typing import Any, Callable, Sequence, TypeVar

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from mpc_local_planner.process_ties import tie_if_asked
from mpc_local_planner.ros.parameters import (
    format_help,
    ParameterSpec,
    params_file_problem,
    params_files,
    params_sections,
    section_applies,
)

__all__ = ['EXIT_INVALID_PARAMETERS', 'StopRequest', 'autostart', 'destroy_on_failure',
           'run_node', 'spin_until_stopped', 'wants_help']

# Exit code of a node whose parameters are invalid.
EXIT_INVALID_PARAMETERS = 2
# Wall seconds the spin loop waits at most before it looks whether a stop was asked for.
SPIN_WAKE_S = 0.1

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
    """Say whether the command line (without its --ros-args part) asks for --help.

    A --ros-args part that rcl cannot parse (a params file it refuses) asks for nothing:
    starting the node then says what is wrong with it.
    """
    argv = list(sys.argv if args is None else args)
    try:
        return any(arg in ('-h', '--help') for arg in remove_ros_args(argv)[1:])
    except rclpy_implementation.RCLError:
        return False


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


class StopRequest:
    """SIGINT and SIGTERM handlers that ask the spin loop to stop (and nothing else).

    A second signal while the first is being handled raises KeyboardInterrupt, so a process
    stuck in a callback can still be ended from the keyboard. ``restore()`` puts the
    handlers that were there back.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.requested: str | None = None  # the signal's name once one came
        self._previous = {number: signal.signal(number, self._handle)
                          for number in self.SIGNALS}

    def _handle(self, number: int, frame: FrameType | None) -> None:
        if self.requested is not None:
            raise KeyboardInterrupt
        self.requested = signal.Signals(number).name

    def restore(self) -> None:
        """Reinstate the handlers that were installed before."""
        for number, handler in self._previous.items():
            signal.signal(number, handler)


def spin_until_stopped(node: Node, stop: StopRequest) -> None:
    """Spin node until a signal asks to stop or the context goes down."""
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        while stop.requested is None and node.context.ok():
            executor.spin_once(timeout_sec=SPIN_WAKE_S)
    finally:
        executor.shutdown(timeout_sec=0.0)


def _exit_safely(node: Node) -> None:
    """Run a lifecycle node's on_exit while the context is up; never raise."""
    on_exit = getattr(node, 'on_exit', None)
    if on_exit is None or not node.context.ok():
        return
    try:
        on_exit()
    except Exception as err:  # the process is ending anyway: say so, do not mask the cause
        print(f'{node.get_name()}: on_exit failed: {err}', file=sys.stderr, flush=True)


def _one_line_rcl_error(err: Exception) -> str:
    """Return rcl's message without its prefix and source locations, on one line."""
    text = ' '.join(str(err).split())
    text = text.removeprefix('failed to initialize rcl: ')
    return text.split(', at /')[0]


def init_or_problem(args: Sequence[str] | None) -> str | None:
    """Call rclpy.init on the command line; return why it failed, in one line (None: it did).

    rcl logs a line of its own on stderr before rclpy raises ("Failed to parse global
    arguments"); that line is held back when init fails, so the caller's one line says it
    all. Whatever else init writes on stderr is passed on.
    """
    sys.stderr.flush()
    saved = os.dup(2)
    problem = None
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        except rclpy_implementation.RCLError as err:
            problem = _one_line_rcl_error(err)
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        if problem is None:
            held.seek(0)
            os.write(2, held.read())
    return problem


def warn_of_unused_params_files(node: Node, args: Sequence[str]) -> None:
    """Warn (one line each) of params files in args with no section that applies to node."""
    fqn = node.get_fully_qualified_name()
    for path in params_files(args):
        sections = params_sections(path)
        if any(section_applies(section, fqn) for section in sections):
            continue
        close = difflib.get_close_matches(node.get_name(), sections, n=1)
        hint = f"; did you mean '{node.get_name()}'?" if close else ''
        listed = ', '.join(sections) if sections else 'none'
        node.get_logger().warning(
            f'params file {path} has no section for {fqn} (its sections: {listed}{hint}): '
            'none of its parameters is used')


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

    Raises:
        Exception: whatever escaped a callback, after the node's on_exit ran.

    """
    if wants_help(args):
        print(format_help(name, summary, parameters), end='')
        return 0
    tie_if_asked()  # started by closed_loop: end with it (process_ties)
    argv = list(sys.argv if args is None else args)
    problem = next(filter(None, map(params_file_problem, params_files(argv))), None)
    # rclpy's handlers would shut the context down at once (no zero cmd_vel after that)
    if problem is None:
        problem = init_or_problem(args)
    if problem is not None:
        print(f'{name}: refusing to start: {problem}', file=sys.stderr, flush=True)
        return EXIT_INVALID_PARAMETERS
    stop = StopRequest()
    node = None
    try:
        try:
            node = make_node()
            warn_of_unused_params_files(node, argv)
            problem = autostart(node) if isinstance(node, LifecycleNode) else None
        except (ParameterException, ValueError, TypeError, OSError) as err:
            problem = str(err)
        if problem is not None:
            print(f'{name}: refusing to start: {problem}', file=sys.stderr, flush=True)
            return EXIT_INVALID_PARAMETERS
        spin_until_stopped(node, stop)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # A context shut down by someone else while the executor builds its wait set (rclpy
        # 7.1 then raises RCLError, not ExternalShutdownException): a clean stop all the
        # same. With the context still up, it is a failure.
        if rclpy.ok():
            raise
    finally:
        stop.restore()
        if node is not None:
            _exit_safely(node)
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
