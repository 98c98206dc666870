# SPDX-License-Identifier: Apache-2.0
"""Ctrl-C (SIGINT) stops a node process cleanly: exit code 0, no error, no traceback."""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest
from rclpy.node import Node

from mpc_local_planner.ros.closed_loop_parameters import MODULES

pytestmark = pytest.mark.dds  # a node process over DDS
# Wall seconds a process may take to start or to exit before it counts as hung.
HANG_GUARD = 60.0


def test_the_simulator_stops_on_sigint_mid_tick_without_an_error(ros) -> None:
    # a tick every millisecond of wall time: SIGINT lands while one is publishing
    command = [sys.executable, '-m', MODULES['unicycle_simulator'], '--ros-args',
               '-p', 'publish_clock:=true', '-p', 'rate:=1000.0',
               '-p', 'real_time_factor:=100.0']
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True)
    try:
        probe = ros.add(Node('clock_probe', context=ros.context))
        # no subscription: with nobody listening a tick is cheapest, and the process spends
        # most of its time in the timer callback
        assert ros.spin_until(lambda: probe.count_publishers('/clock') > 0,
                              timeout=HANG_GUARD)
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=HANG_GUARD)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 0, output
    assert 'ERROR' not in output and 'Traceback' not in output, output


def test_a_tick_that_runs_after_ctrl_c_shut_the_context_down_logs_no_error(capfd) -> None:
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode

    context = Context()
    rclpy.init(context=context)
    node = UnicycleSimulatorNode(context=context, parameter_overrides=[
        Parameter('publish_clock', value=True)])
    try:
        node.timer_callback()
        rclpy.shutdown(context=context)  # what the SIGINT handler does
        node.timer_callback()  # the tick the executor had already started
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert 'simulation step failed' not in capfd.readouterr().err


def test_run_node_treats_a_failed_spin_after_ctrl_c_as_a_clean_stop(monkeypatch) -> None:
    import rclpy
    from rclpy.node import Node as RclpyNode

    from mpc_local_planner.ros import node_main

    def interrupted_spin(node: RclpyNode, stop: node_main.StopRequest) -> None:
        rclpy.shutdown()  # the context goes down while the executor works
        msg = 'failed to initialize wait set: the given context is not valid'
        raise RuntimeError(msg)

    monkeypatch.setattr(node_main, 'spin_until_stopped', interrupted_spin)
    assert node_main.run_node(lambda: RclpyNode('spun'), 'spun', []) == 0

    def broken_spin(node: RclpyNode, stop: node_main.StopRequest) -> None:
        msg = 'a real failure'
        raise RuntimeError(msg)

    monkeypatch.setattr(node_main, 'spin_until_stopped', broken_spin)
    with pytest.raises(RuntimeError, match='a real failure'):
        node_main.run_node(lambda: RclpyNode('spun'), 'spun', [])


def test_an_exception_that_ends_the_process_runs_on_exit_first_while_the_context_is_up(
) -> None:
    import rclpy

    from mpc_local_planner.ros import node_main
    from mpc_local_planner.ros.lifecycle import ManagedNode

    exits: list[bool] = []

    class Failing(ManagedNode):
        """A node whose timer raises, as a bug in a callback would."""

        def __init__(self) -> None:
            super().__init__('failing')
            self.declare_parameter('autostart', False)
            self.create_timer(0.01, self.fail)

        def fail(self) -> None:
            msg = 'a bug in a callback'
            raise RuntimeError(msg)

        def on_exit(self) -> None:
            exits.append(self.context.ok())

    with pytest.raises(RuntimeError, match='a bug in a callback'):
        node_main.run_node(Failing, 'failing', [])
    assert exits == [True]  # once, and while it could still publish
    assert not rclpy.ok()


def test_sigterm_ends_run_node_cleanly_through_on_exit(monkeypatch) -> None:
    import os

    import rclpy

    from mpc_local_planner.ros import node_main
    from mpc_local_planner.ros.lifecycle import ManagedNode

    exits: list[bool] = []

    class Terminated(ManagedNode):
        """A node that gets SIGTERM from its supervisor after a few spins."""

        def __init__(self) -> None:
            super().__init__('terminated')
            self.declare_parameter('autostart', False)
            self.ticks = 0
            self.create_timer(0.01, self.tick)

        def tick(self) -> None:
            self.ticks += 1
            if self.ticks == 3:
                os.kill(os.getpid(), signal.SIGTERM)

        def on_exit(self) -> None:
            exits.append(self.context.ok())

    previous = signal.getsignal(signal.SIGTERM)
    assert node_main.run_node(Terminated, 'terminated', []) == 0
    assert exits == [True]
    assert signal.getsignal(signal.SIGTERM) is previous  # the handlers are put back
    assert not rclpy.ok()


@pytest.mark.dds
@pytest.mark.parametrize('node_name', ['unicycle_simulator', 'global_planner'])
def test_a_node_that_refused_its_parameters_leaves_no_handle_to_silence_the_next_one(
        ros, node_name: str) -> None:
    import gc

    from rclpy.parameter import Parameter

    from mpc_local_planner.ros.global_planner_node import GlobalPlannerNode
    from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode

    node_class, bad = {
        'unicycle_simulator': (UnicycleSimulatorNode,
                               Parameter('initial_pose', value=[0.0, float('nan'), 0.0])),
        'global_planner': (GlobalPlannerNode, Parameter('iterations', value=0)),
    }[node_name]
    probe = ros.probe()

    def refuse() -> Exception | None:
        try:
            node_class(context=ros.context, parameter_overrides=[bad])
        except Exception as err:  # what run_node turns into exit code 2
            return err  # its traceback keeps the refused node's frame alive, as pytest.raises does
        return None

    refusal = refuse()
    assert refusal is not None
    node = ros.add(node_class(context=ros.context))
    assert ros.spin_until(lambda: probe.count_subscribers('/rosout') > 0)
    del refusal
    gc.collect()  # a handle left behind is finalised now, after the new node of its name exists

    def heard() -> bool:
        node.get_logger().error('still heard')
        return 'still heard' in probe.log_lines(node_name)

    assert ros.spin_until(heard, timeout=20.0)
