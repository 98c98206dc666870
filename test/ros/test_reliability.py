# SPDX-License-Identifier: Apache-2.0
"""Bad input, stale data and solver failure end in a safe stop, and the nodes recover.

Every test spins the real nodes in their own context. Where timing matters the test owns
simulated time (it publishes /clock), so the assertions are about ROS time and do not depend
on how loaded the machine is.
"""

from __future__ import annotations

import copy
import math
import os
import signal
import subprocess
import sys
import time
from typing import Callable

from conftest import SimClock
from geometry_msgs.msg import PoseStamped, Twist
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from nav_msgs.msg import OccupancyGrid, Odometry, Path
import numpy as np
import pytest
from rcl_interfaces.msg import Log
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import LaserScan

from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import PlanSource
from mpc_local_planner.core.mpc.backends import SolverRun
from mpc_local_planner.core.obstacles import first_blocked_segment
from mpc_local_planner.ros.closed_loop_parameters import MODULES
from mpc_local_planner.ros.closed_loop_processes import spawn_node
from mpc_local_planner.ros.conversions import (
    odometry_to_state,
    path_to_poses,
    poses_to_path,
    seconds_to_stamp,
    state_to_odometry,
    u_from_twist,
    yaw_to_quaternion,
)
from mpc_local_planner.ros.global_planner_node import GlobalPlannerNode
from mpc_local_planner.ros.map_server_node import MapServerNode
from mpc_local_planner.ros.mpc_controller_node import MpcControllerNode
from mpc_local_planner.ros.node_main import autostart
from mpc_local_planner.ros.qos import MAP_QOS, SCAN_QOS
from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode
from mpc_local_planner.worlds.world import paper_world

pytestmark = pytest.mark.dds  # DDS, and node processes
WORLD = paper_world()
# A plan around the paper's box (above it), headings as the planner sends them.
PLAN = np.array([[0.0, 0.0, WORLD.start[2]], [0.8, 1.3, 0.0], [1.7, 1.3, -0.96],
                 [2.5, 0.0, WORLD.goal[2]]])
U_MAX = Unicycle().u_max
STEP = 0.2  # the controller's default step h (s): an upper bound of its control period (20 Hz)
ODOM_TIMEOUT = 0.5  # the controller's default odom_timeout (s)


# ----------------------------------------------------------------------------- helpers
def started(node: Node) -> Node:
    """Configure and activate a lifecycle node (autostart is true by default), as run_node does."""
    if isinstance(node, LifecycleNode):
        assert autostart(node) is None
    return node


class OdomClock(SimClock):
    """The test's simulated time (conftest's SimClock): each tick publishes odometry, if set."""

    def __init__(self, ros, probe, dt: float = 0.05) -> None:
        super().__init__(ros, probe, dt=dt)
        self.odom: np.ndarray | Odometry | None = None
        self.last_odom_stamp: float | None = None

    def publish(self) -> None:
        """Publish the odometry (a message restamped, or a state) at t."""
        if isinstance(self.odom, Odometry):
            msg = copy.deepcopy(self.odom)
            msg.header.stamp = seconds_to_stamp(self.t)
            self.probe.odom_pub.publish(msg)
        elif self.odom is not None:
            self.probe.publish_odom(self.odom, stamp=self.t)
        if self.odom is not None:
            self.last_odom_stamp = self.t


def check_commands(probe) -> np.ndarray:
    """Assert every cmd_vel so far is finite and within the unicycle's bounds; return them."""
    commands = np.array([u_from_twist(c) for c in probe.cmds]).reshape(-1, 2)
    raw = np.array([[c.linear.x, c.angular.z] for c in probe.cmds]).reshape(-1, 2)
    assert np.all(np.isfinite(raw))
    assert np.all(np.abs(raw) <= U_MAX + 1e-12)
    return commands


def applied(diag) -> np.ndarray:
    """The (v, omega) a control step published, from its diagnostics."""
    return np.array([diag.step.v, diag.step.omega])


def tracking(probe, after: int = 0) -> bool:
    """Say whether a step after the first `after` diagnostics drove on a solver solution."""
    return any(d.step.reason is Reason.TRACKING and d.step.source is PlanSource.SOLVER
               and applied(d)[0] > 0.01 for d in probe.diagnostics[after:])


def errors(probe, node: str, text: str) -> list[str]:
    """Error lines node logged that contain text."""
    return [line for line in probe.log_lines(node, Log.ERROR) if text in line]


def start_controller(ros, **params) -> tuple[MpcControllerNode, object, OdomClock]:
    """A controller in simulated time with a probe that owns the clock; tracking PLAN."""
    overrides = [Parameter('use_sim_time', value=True),
                 Parameter('world_file', value='paper_obstacle.yaml')]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    node = started(ros.add(MpcControllerNode(context=ros.context, parameter_overrides=overrides)))
    probe = ros.probe(use_sim_time=True)
    clock = OdomClock(ros, probe)
    assert ros.spin_until(lambda: probe.plan_pub.get_subscription_count() > 0
                          and probe.odom_pub.get_subscription_count() > 0)
    if not params.get('analytic_path'):
        probe.plan_pub.publish(poses_to_path(PLAN))
    clock.odom = WORLD.start.copy()
    assert clock.run_until(lambda: tracking(probe))
    return node, probe, clock


# ----------------------------------------------------------------------------- 1. bad input
def odometry_with(**changes: float) -> Odometry:
    """Odometry at the start pose with some fields replaced (e.g. x=nan, qw=0)."""
    msg = state_to_odometry(WORLD.start, np.zeros(2), stamp=seconds_to_stamp(0.0))
    position, q = msg.pose.pose.position, msg.pose.pose.orientation
    for name, value in changes.items():
        if name in ('x', 'y'):
            setattr(position, name, value)
        else:
            setattr(q, name[1], value)  # qx, qy, qz, qw
    return msg


def path_message(poses: np.ndarray, frame_id: str = 'map') -> Path:
    """A nav_msgs/Path of (M, 3) poses, NaN allowed (poses_to_path refuses NaN)."""
    msg = Path()
    msg.header.frame_id = frame_id
    for x, y, yaw in np.asarray(poses, dtype=float).reshape(-1, 3):
        pose = PoseStamped()
        pose.header.frame_id = frame_id
        pose.pose.position.x, pose.pose.position.y = float(x), float(y)
        pose.pose.orientation = yaw_to_quaternion(yaw if math.isfinite(yaw) else 0.0)
        msg.poses.append(pose)
    return msg


def dense_plan(count: int) -> Path:
    t = np.linspace(0.0, 1.0, count)
    poses = np.column_stack([2.5 * t, 1.3 * np.sin(np.pi * t), np.zeros(count)])
    return poses_to_path(poses)


BAD_ODOMETRY = {
    'nan position': (odometry_with(x=math.nan), 'position must be finite'),
    'inf position': (odometry_with(y=math.inf), 'position must be finite'),
    'zero-norm quaternion': (odometry_with(qx=0.0, qy=0.0, qz=0.0, qw=0.0), 'no orientation'),
    'nan quaternion': (odometry_with(qw=math.nan), 'no orientation'),
    'position 1e9 m away': (odometry_with(x=1e9), 'more than 1e+06 m'),
}

BAD_PLANS = {
    'empty': (lambda: path_message(np.zeros((0, 3))), 'needs at least two poses, got 0'),
    'one pose': (lambda: path_message(PLAN[:1]), 'needs at least two poses, got 1'),
    'nan': (lambda: path_message(np.vstack([PLAN[:2], [[math.nan, 1.0, 0.0]], PLAN[2:]])),
            'position must be finite'),
    'one point repeated': (lambda: path_message(np.tile(PLAN[1], (5, 1))), 'two distinct'),
    'frame odom': (lambda: path_message(PLAN, frame_id='odom'), "frame 'odom' is not 'map'"),
    '100,000 poses': (lambda: dense_plan(100_000),
                      '100000 poses, more than max_plan_poses (10000)'),
}


def check_refusal(ros, probe, clock, prefix: str, text: str,
                  restore: Callable[[], None]) -> None:
    """The command goes to zero with the problem as the reason; one error; then recovery."""
    first = len(probe.diagnostics)

    def refused() -> list[dict]:
        return [d for d in probe.diagnostics[first:]
                if d.message.startswith(prefix) and text in d.message]

    # a few refused steps, and the error line from /rosout
    assert clock.run_until(lambda: len(refused()) >= 3
                           and errors(probe, 'mpc_controller', text)), probe.diagnostics[-3:]
    for diag in refused():
        np.testing.assert_array_equal(applied(diag), [0.0, 0.0])
        assert diag.level == 2  # DiagnosticStatus.ERROR
    # every step after the first refused one commands zero until the input is fixed
    index = probe.diagnostics.index(refused()[0])
    assert all(not applied(d).any() for d in probe.diagnostics[index:])
    lines = errors(probe, 'mpc_controller', text)
    assert len(lines) == 1, lines  # the throttle's clock is held: one line, however long
    assert 'zero' in lines[0]

    restore()
    after = len(probe.diagnostics)
    assert clock.run_until(lambda: tracking(probe, after)), probe.diagnostics[-3:]
    check_commands(probe)


@pytest.mark.parametrize('case', list(BAD_ODOMETRY))
def test_bad_odometry_stops_the_robot_with_one_error_and_it_resumes(
        ros, case: str, throttle_clock) -> None:
    _, probe, clock = start_controller(ros)
    message, text = BAD_ODOMETRY[case]
    clock.odom = message

    def restore() -> None:
        clock.odom = WORLD.start.copy()

    check_refusal(ros, probe, clock, 'invalid odometry', text, restore)
    assert ros.spin_until(lambda: any('odometry is valid again' in line
                                      for line in probe.log_lines('mpc_controller', Log.INFO)))


@pytest.mark.parametrize('case', list(BAD_PLANS))
def test_a_bad_plan_stops_the_robot_with_one_error_and_a_valid_one_resumes(
        ros, case: str, throttle_clock) -> None:
    _, probe, clock = start_controller(ros)
    make, text = BAD_PLANS[case]
    probe.plan_pub.publish(make())
    check_refusal(ros, probe, clock, 'invalid plan', text,
                  lambda: probe.plan_pub.publish(poses_to_path(PLAN)))


def test_a_plan_with_repeated_points_is_followed_without_them(ros) -> None:
    _, probe, clock = start_controller(ros)
    repeated = np.repeat(PLAN, 3, axis=0)  # every waypoint three times
    after = len(probe.diagnostics)
    probe.plan_pub.publish(poses_to_path(repeated))
    assert clock.run_until(
        lambda: any('new plan: 12 poses' in line
                    for line in probe.log_lines('mpc_controller', Log.INFO)))
    assert clock.run_until(lambda: tracking(probe, after))
    assert not errors(probe, 'mpc_controller', 'invalid plan')
    check_commands(probe)


# ----------------------------------------------------------------------------- 2. stale data
def test_stale_odometry_gives_zero_within_one_control_period_and_fresh_odometry_resumes(
        ros) -> None:
    _, probe, clock = start_controller(ros)
    clock.odom = None  # the odometry stops
    last = clock.last_odom_stamp
    first = len(probe.diagnostics)

    def stale() -> list[dict]:
        return [d for d in probe.diagnostics[first:] if d.step.reason is Reason.STALE_ODOM]

    assert clock.run_until(lambda: bool(stale()))
    # the first step later than odom_timeout after the last odometry commands zero
    assert stale()[0].stamp <= last + ODOM_TIMEOUT + STEP + 1e-6
    np.testing.assert_array_equal(applied(stale()[0]), [0.0, 0.0])
    index = probe.diagnostics.index(stale()[0])
    # until then the robot was driven on odometry at most odom_timeout old
    for diag in probe.diagnostics[first:index]:
        assert diag.stamp - last <= ODOM_TIMEOUT + 1e-6
    assert clock.run_until(lambda: len(stale()) >= 3)
    assert all(not applied(d).any() for d in probe.diagnostics[index:])

    clock.odom = WORLD.start.copy()
    after = len(probe.diagnostics)
    assert clock.run_until(lambda: tracking(probe, after))
    check_commands(probe)


def test_odometry_stamped_in_the_future_goes_stale_when_it_stops(ros) -> None:
    _, probe, clock = start_controller(ros)
    clock.odom = None
    moved = WORLD.start + np.array([0.01, 0.0, 0.0])  # a pose to tell this message by
    probe.publish_odom(moved, stamp=clock.t + 3600.0)  # a clock an hour ahead, then silence
    first = len(probe.diagnostics)

    def steps() -> list[dict]:
        return probe.diagnostics[first:]

    assert clock.run_until(lambda: any(d.step.reason is Reason.STALE_ODOM for d in steps()))
    taken = next(d for d in steps() if d.step.x == moved[0])  # the first step using it
    stale = next(d for d in steps() if d.step.reason is Reason.STALE_ODOM)
    # timed from its arrival (before the step that first used it), not from its stamp
    assert taken.step.reason is not Reason.STALE_ODOM
    assert stale.stamp <= taken.stamp + ODOM_TIMEOUT + STEP + 1e-6


def test_simulator_stops_the_robot_when_cmd_vel_stops_for_cmd_timeout(ros) -> None:
    rate, timeout = 50.0, 0.5
    ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter('publish_clock', value=True), Parameter('real_time_factor', value=5.0),
        Parameter('rate', value=rate), Parameter('cmd_timeout', value=timeout)]))
    probe = ros.probe()
    assert ros.spin_until(lambda: probe.cmd_pub.get_subscription_count() > 0)
    twist = Twist()
    twist.linear.x, twist.angular.z = 0.2, 0.3
    probe.cmd_pub.publish(twist)  # once: then the "controller" goes silent

    def moving() -> list[Odometry]:
        return [m for m in probe.odoms if m.twist.twist.linear.x != 0.0]

    def stopped_after_moving() -> bool:
        moved = moving()
        return bool(moved) and probe.odoms[-1].twist.twist.linear.x == 0.0 and len(
            probe.odoms) > probe.odoms.index(moved[-1]) + 10

    assert ros.spin_until(stopped_after_moving, timeout=20.0)
    moved = moving()
    stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in moved]
    # it drove for cmd_timeout of simulated time (to a tick), then stood still
    assert stamps[-1] - stamps[0] == pytest.approx(timeout, abs=2.0 / rate + 1e-9)
    rest = probe.odoms[probe.odoms.index(moved[-1]) + 1:]
    positions = np.array([[m.pose.pose.position.x, m.pose.pose.position.y] for m in rest])
    np.testing.assert_array_equal(positions, positions[:1].repeat(len(positions), axis=0))

    # a non-finite command stops it at the next tick, with an error, whatever the rest says
    probe.cmd_pub.publish(twist)
    assert ros.spin_until(lambda: probe.odoms[-1].twist.twist.linear.x != 0.0)
    bad = Twist()
    bad.linear.x, bad.angular.z = math.nan, 0.5
    probe.cmd_pub.publish(bad)
    count = len(probe.odoms)
    assert ros.spin_until(lambda: len(probe.odoms) > count + 3
                          and probe.odoms[-1].twist.twist.angular.z == 0.0)
    assert ros.spin_until(lambda: errors(probe, 'unicycle_simulator', 'invalid cmd_vel'))
    assert probe.odoms[-1].twist.twist.linear.x == 0.0


# ----------------------------------------------------------------------------- 3. solver failure
def failing_solver(nlp, w0, params, solver=None, **limits):
    """Stand-in for backends.run_solver in the MPC's step: every NLP solve fails (IPOPT's too)."""
    return SolverRun(w=np.asarray(w0, dtype=float).reshape(-1), value=math.inf, success=False,
                     status='injected failure', iterations=0, seconds=0.0)


def test_injected_solver_failures_apply_the_shifted_candidate_at_most_n_steps_then_stop(
        ros) -> None:
    horizon = 10
    ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter('publish_clock', value=True), Parameter('real_time_factor', value=2.0),
        Parameter('initial_pose', value=[float(v) for v in WORLD.start])]))
    node = started(ros.add(MpcControllerNode(context=ros.context, parameter_overrides=[
        Parameter('use_sim_time', value=True), Parameter('analytic_path', value='paper_sinusoid'),
        Parameter('horizon', value=horizon),
        Parameter('world_file', value='paper_obstacle.yaml')])))
    probe = ros.probe(use_sim_time=True)

    def driving_on_the_solver() -> bool:
        out = node.last_output
        solved = sum(d.step.source is PlanSource.SOLVER for d in probe.diagnostics)
        return (solved >= 5 and out is not None and out.solution is not None
                and out.solution.success and out.u[0] > 0.05)

    assert ros.spin_until(driving_on_the_solver, timeout=60.0)
    verified = node.last_output.solution  # the last plan the solver gave
    patched_at = node.get_clock().now().nanoseconds * 1e-9
    failures_before = node.controller.solver_failures
    solver = node.controller.runner
    node.controller.runner = failing_solver

    def after_patch() -> list[dict]:
        return [d for d in probe.diagnostics if d.stamp > patched_at]

    assert ros.spin_until(
        lambda: sum(d.step.reason is Reason.STOP for d in after_patch()) >= 3,
        timeout=60.0), after_patch()[-3:]
    steps = after_patch()
    # the MPC solves once per step h; the control ticks between (control_frequency) apply
    # the same input again, so the candidates are counted at the ticks that solved
    candidates = [d for d in steps if d.step.solved and d.step.source is PlanSource.CANDIDATE
                  and applied(d).any()]
    # the proof's candidate: the verified inputs shifted by one step per failure...
    assert 1 <= len(candidates) <= horizon
    for k, diag in enumerate(candidates, start=1):
        assert diag.step.reason is Reason.CANDIDATE
        assert diag.step.failures == k
        np.testing.assert_allclose(applied(diag), verified.u_pred[k], atol=1e-12)
    # ...then it has run out: zero from the N-th failure on, the robot stops
    stop = steps.index(next(d for d in steps if d.step.reason is Reason.STOP))
    assert steps[stop].step.failures == horizon + 1
    assert all(not applied(d).any() for d in steps[stop:])
    assert steps[stop].level == 2
    assert steps[-1].step.failures_total >= failures_before + horizon + 1
    assert ros.spin_until(lambda: abs(probe.odoms[-1].twist.twist.linear.x) < 1e-12
                          and abs(probe.odoms[-1].twist.twist.angular.z) < 1e-12)
    assert ros.spin_until(lambda: any(Reason.STOP.text in line for line in
                                      probe.log_lines('mpc_controller', Log.WARN)))
    check_commands(probe)

    # the solver is back: the robot drives on
    node.controller.runner = solver
    resumed = len(probe.diagnostics)
    assert ros.spin_until(lambda: tracking(probe, resumed), timeout=30.0)
    check_commands(probe)


def test_a_state_inside_the_obstacle_is_infeasible_the_robot_stops_and_resumes_outside(
        ros) -> None:
    node, probe, clock = start_controller(ros)
    failures = node.controller.solver_failures
    first = len(probe.diagnostics)
    clock.odom = np.array([1.25, 0.0, 0.0])  # inside the box: no input keeps it clear

    def stopped() -> list[dict]:
        # the steps that solved (at 20 Hz a stop is held, not solved again, until the next
        # step's instant)
        return [d for d in probe.diagnostics[first:]
                if d.step.reason is Reason.STOP and d.step.solved]

    assert clock.run_until(lambda: len(stopped()) >= 2)
    for diag in stopped():
        np.testing.assert_array_equal(applied(diag), [0.0, 0.0])
        assert diag.step.source is PlanSource.STOP and diag.level == 2
        assert diag.step.failures >= 1
    assert node.controller.solver_failures >= failures + 2
    assert stopped()[-1].step.failures_total > failures
    check_commands(probe)

    clock.odom = WORLD.start.copy()
    after = len(probe.diagnostics)
    assert clock.run_until(lambda: tracking(probe, after))


# ----------------------------------------------------------------------------- 4. parameters
MALFORMED_WORLD = 'bounds: [0, 1\n'  # not YAML
# A decagon: more faces than the NLP's obstacle slots hold (faces_per_obstacle = 8).
DECAGON_WORLD = """bounds: [-5, 5, -5, 5]
obstacles:
  - polygon: [{}]
start: [-3.0, 0.0, 0.0]
goal: [3.0, 0.0, 0.0]
""".format(', '.join(f'[{math.cos(a):.6f}, {math.sin(a):.6f}]'
                     for a in np.linspace(0, 2 * math.pi, 10, endpoint=False)))


def test_invalid_parameters_refuse_to_start_with_a_reason_on_stderr_and_exit_code_2(
        tmp_path) -> None:
    malformed = tmp_path / 'malformed.yaml'
    malformed.write_text(MALFORMED_WORLD)
    cases = {
        'horizon 0': ('mpc_controller', 'horizon:=0', 'horizon out of range'),
        'step 0': ('mpc_controller', 'step:=0.0', 'step out of range'),
        'step as an integer': ('mpc_controller', 'step:=0', "parameter 'step'"),
        'negative weight': ('mpc_controller', 'weights.position:=-1.0',
                            'weights.position out of range'),
        'v_max 0': ('mpc_controller', 'v_max:=0.0', 'v_max out of range'),
        'missing world': ('mpc_controller', 'world_file:=/no/such/world.yaml', 'not found'),
        'malformed world': ('mpc_controller', f'world_file:={malformed}', 'not valid YAML'),
        'footprint not convex': ('mpc_controller',
                                 "footprint:='[[0.3, 0.2], [-0.3, 0.2], [0.0, 0.0], "
                                 "[-0.3, -0.2], [0.3, -0.2]]'", 'not convex'),
        'footprint of two points': ('mpc_controller', "footprint:='[[0, 0], [1, 1]]'",
                                    'at least 3'),
        'planner, missing world': ('global_planner', 'world_file:=/no/such/world.yaml',
                                   'not found'),
        'planner, malformed world': ('global_planner', f'world_file:={malformed}',
                                     'not valid YAML'),
        'simulator, NaN pose': ('unicycle_simulator', 'initial_pose:=[.nan, 0.0, 0.0]',
                                'initial_pose must be'),
    }
    processes = {}
    try:
        for case, (name, argument, _) in cases.items():
            command = [sys.executable, '-m', MODULES[name], '--ros-args', '-p', argument]
            processes[case] = subprocess.Popen(command, stdout=subprocess.PIPE,
                                               stderr=subprocess.PIPE, text=True)
        problems = []
        for case, process in processes.items():
            _, stderr = process.communicate(timeout=120)
            name, _, reason = cases[case]
            if (process.returncode != 2 or f'{name}: refusing to start' not in stderr
                    or reason not in stderr or 'Traceback' in stderr):
                problems.append(f'{case}: exit {process.returncode}, stderr {stderr!r}')
        assert not problems, '\n'.join(problems)
    finally:
        for process in processes.values():
            if process.poll() is None:
                process.kill()
                process.wait()


def test_invalid_parameters_at_run_time_are_refused_with_a_reason_and_the_node_runs_on(
        ros, tmp_path) -> None:
    (tmp_path / 'malformed.yaml').write_text(MALFORMED_WORLD)
    (tmp_path / 'decagon.yaml').write_text(DECAGON_WORLD)
    node, probe, clock = start_controller(ros)
    cases = [
        ('horizon', 0, 'horizon out of range'),
        ('step', 0.0, 'step out of range'),
        ('weights.position', -1.0, 'weights.position out of range'),
        ('v_max', 0.0, 'v_max out of range'),
        ('offset_weight', 0.0, 'offset_weight out of range'),
        ('odom_timeout', -1.0, 'odom_timeout out of range'),
        ('max_plan_poses', 1, 'max_plan_poses out of range'),
        ('solver', 'no_such_solver', 'solver must be one of'),
        ('world_file', str(tmp_path / 'no_such.yaml'), 'not found'),
        ('world_file', str(tmp_path / 'malformed.yaml'), 'not valid YAML'),
        ('world_file', str(tmp_path / 'decagon.yaml'), 'more than faces_per_obstacle'),
        ('footprint', '[[0.1, 0.1], [0.2, 0.2], [0.3, 0.3]]', 'collinear'),
        ('footprint', 'a rectangle', 'not of the form'),
    ]
    for name, value, reason in cases:
        before = node.get_parameter(name).value
        result = node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful, name
        assert reason in result.reason, (name, result.reason)
        assert node.get_parameter(name).value == before
    after = len(probe.diagnostics)
    assert clock.run_until(lambda: tracking(probe, after))

    planner = ros.add(GlobalPlannerNode(context=ros.context))
    result = planner.set_parameters([Parameter('world_file',
                                               value=str(tmp_path / 'malformed.yaml'))])[0]
    assert not result.successful and 'not valid YAML' in result.reason
    simulator = ros.add(UnicycleSimulatorNode(context=ros.context))
    result = simulator.set_parameters([Parameter('initial_pose', value=[math.nan, 0.0, 0.0])])[0]
    assert not result.successful and 'initial_pose must be' in result.reason


# ----------------------------------------------------------------------------- 5. planner
def goal_message(x: float, y: float, yaw: float = 0.0, frame_id: str = 'map') -> PoseStamped:
    goal = PoseStamped()
    goal.header.frame_id = frame_id
    goal.pose.position.x, goal.pose.position.y = x, y
    goal.pose.orientation = yaw_to_quaternion(yaw)
    return goal


def start_planner(ros) -> tuple[GlobalPlannerNode, object]:
    planner = started(ros.add(GlobalPlannerNode(context=ros.context, parameter_overrides=[
        Parameter('world_file', value='paper_obstacle.yaml')])))
    probe = ros.probe()
    assert ros.spin_until(lambda: probe.goal_pub.get_subscription_count() > 0
                          and probe.odom_pub.get_subscription_count() > 0)
    return planner, probe


def refuse_goal(ros, planner, probe, goal: PoseStamped, state: np.ndarray, text: str) -> None:
    """Send goal with the robot at state: an error that says text, and no plan."""
    plans = planner.plan_count
    probe.goal_pub.publish(goal)

    def refused() -> bool:
        probe.publish_odom(state)
        return bool(errors(probe, 'global_planner', text))

    assert ros.spin_until(refused, timeout=20.0), probe.log_lines('global_planner')
    assert 'no plan' in errors(probe, 'global_planner', text)[-1]
    assert planner.plan_count == plans


def plan_to(ros, planner, probe, goal: np.ndarray, state: np.ndarray) -> np.ndarray:
    """Send a valid goal: the plan from state to goal, as published."""
    plans = planner.plan_count
    received = len(probe.raw_plans)

    def located() -> bool:
        probe.publish_odom(state)
        pose = planner.robot_pose
        return pose is not None and np.allclose(pose, state)

    assert ros.spin_until(located)
    probe.goal_pub.publish(goal_message(*goal))

    def planned() -> bool:
        probe.publish_odom(state)
        return planner.plan_count > plans and len(probe.raw_plans) > received

    assert ros.spin_until(planned, timeout=20.0)
    assert planner.plan_count == plans + 1
    poses = path_to_poses(probe.plans[-1])
    np.testing.assert_allclose(poses[0], state, atol=1e-9)
    np.testing.assert_allclose(poses[-1], goal, atol=1e-9)
    return poses


def test_planner_refuses_goals_it_cannot_reach_publishes_nothing_and_plans_the_next(
        ros) -> None:
    planner, probe = start_planner(ros)
    start = np.array([0.1, -0.2, 0.3])
    nan_goal = goal_message(0.0, 0.0)
    nan_goal.pose.position.y = math.nan
    no_orientation = goal_message(2.5, 1.5)
    no_orientation.pose.orientation.w = 0.0
    cases = [
        (goal_message(1.25, 0.0), 'goal (1.25, 0) is in collision with obstacle 0'),
        (goal_message(10.0, 0.0), 'goal (10, 0) is outside the bounds'),
        (nan_goal, 'position must be finite'),
        (no_orientation, 'no orientation'),
        (goal_message(2.5, 1.5, frame_id='odom'), "frame 'odom' is not 'map'"),
    ]
    for goal, text in cases:
        refuse_goal(ros, planner, probe, goal, start, text)
    assert probe.raw_plans == []
    plan_to(ros, planner, probe, np.array([2.5, 1.5, 1.0]), start)


def test_planner_publishes_no_plan_from_a_start_in_collision_and_plans_once_clear(ros) -> None:
    planner, probe = start_planner(ros)
    goal = np.array([2.5, 0.0, 0.0])
    refuse_goal(ros, planner, probe, goal_message(*goal), np.array([1.25, 0.5, 0.0]),
                'start (1.25, 0.5) is in collision with obstacle 0')
    assert probe.raw_plans == []
    poses = plan_to(ros, planner, probe, goal, np.array(WORLD.start))
    inflated = [o.inflate(0.99 * planner.get_parameter('clearance').value)
                for o in WORLD.obstacles]
    assert first_blocked_segment(inflated, poses[:, :2]) is None


# ----------------------------------------------------------------------------- 6. restart
# Wall seconds the whole drill may take before it counts as hung. It guards against a process
# that never answers; no assertion depends on it (they are all in simulated time).
HANG_GUARD = 600.0
SIM_RATE = 50.0  # the simulator's default rate (Hz of simulated time)
CMD_TIMEOUT = 0.5  # the simulator's default cmd_timeout (s of simulated time)
TIME_LIMIT = 60.0  # simulated seconds for the drill (closed_loop's default time limit)


class RecordingSimulator(UnicycleSimulatorNode):
    """The simulator, noting when (its simulated time) and what each cmd_vel it took said."""

    def __init__(self, **kwargs) -> None:
        self.received: list[tuple[float, np.ndarray]] = []
        super().__init__(**kwargs)

    def cmd_vel_callback(self, msg: Twist) -> None:
        super().cmd_vel_callback(msg)
        self.received.append((self.get_clock().now().nanoseconds * 1e-9, u_from_twist(msg)))


TICKS_PER_STEP = round(STEP * SIM_RATE)  # the controller's default step is 10 simulator ticks


class Lockstep:
    """Simulated time owned by the test, advanced in lockstep with the nodes.

    Each tick publishes /clock one simulator period later and waits until the simulator has
    integrated that period (its odometry stamped with the new time has arrived). The
    controller's timer, created before its first /clock, fires at the multiples of STEP
    (TICKS_PER_STEP ticks); a controller process starts at such an instant, and time stands
    still (the same /clock published again) until it has the plan. From then on every tick
    at a multiple of STEP waits for that step's diagnostics and for the simulator to have
    received a cmd_vel at that instant. So every step happens at its instant whatever the
    machine's speed: a slow solve only stops the clock. The one wall-clock limit,
    HANG_GUARD, fails the test if a process stops answering.

    A new process's first step may publish before DDS has matched its writers with the
    test's readers (the discovery of the two sides is not atomic): those volatile messages
    are dropped, and waiting for them hung CI once. So the first step is awaited only if it
    has come by the time the controller has the plan; otherwise time moves on, the robot
    halted, and the next control instant's step is the first one awaited.
    """

    def __init__(self, ros, probe, simulator: RecordingSimulator, logs) -> None:
        self.ros, self.probe, self.simulator, self.logs = ros, probe, simulator, logs
        self.ticks = int(SIM_RATE)  # t = 1 s: 0 is "no time yet" for a node with use_sim_time
        self.deadline = time.monotonic() + HANG_GUARD
        self.controller: subprocess.Popen | None = None
        self.first_diagnostic = 0  # the index of the current controller's first diagnostics
        self.first_command = 0  # the index of the first cmd_vel it can have sent

    @property
    def t(self) -> float:
        return self.ticks / SIM_RATE

    def at_control_instant(self) -> bool:
        return self.ticks % TICKS_PER_STEP == 0

    def wait(self, condition: Callable[[], bool], what: str) -> None:
        """Spin until condition() holds; fail if the controller died or the guard ran out."""
        while not condition():
            if self.controller is not None and self.controller.poll() is not None:
                pytest.fail(f'the controller exited (code {self.controller.returncode}) while '
                            f'waiting for {what}:\n{self.log_tail()}')
            if time.monotonic() > self.deadline:
                pytest.fail(f'hang guard ({HANG_GUARD:g} s wall): no {what} at '
                            f't = {self.t:.2f} s; {self.state()}:\n{self.log_tail()}')
            self.ros.executor.spin_once(timeout_sec=0.01)

    def state(self) -> str:
        steps = [(d.stamp, d.step.reason) for d in self.steps()[-3:]]
        return (f'last steps {steps} of {len(self.steps())}, '
                f'{len(self.simulator.received) - self.first_command} commands received')

    def log_tail(self) -> str:
        log = self.logs / 'mpc_controller.log'
        return log.read_text()[-3000:] if log.exists() else '(no controller log)'

    def start_controller(self, *, again: bool = False) -> None:
        """Start an mpc_controller process as closed_loop does.

        Time stands still until it has the plan (see the class docstring for its first step).
        """
        assert self.at_control_instant()
        self.first_diagnostic = len(self.probe.diagnostics)
        self.first_command = len(self.simulator.received)
        rosout = len(self.probe.logs)
        # one control tick per step h (control_frequency 1 / STEP, every tick solves): the
        # lockstep waits for a step at each multiple of STEP, and at the default 20 Hz a
        # tick fired late by the stepped clock (at 2.78 s for 2.75 s) makes the duplicate
        # guard skip the one at 2.80 s; the drill is about a killed process, not the rate
        self.controller = spawn_node('mpc_controller',
                                     {'use_sim_time': True, 'control_frequency': 1.0 / STEP,
                                      'world_file': 'paper_obstacle.yaml'},
                                     self.logs / 'mpc_controller.log', append=again)
        published = -math.inf

        def has_plan() -> bool:
            nonlocal published
            if time.monotonic() - published > 0.1:  # until it listens: the same time again
                self.probe.publish_clock(self.t)
                published = time.monotonic()
            return any(entry.name == 'mpc_controller' and entry.msg.startswith('new plan')
                       for entry in self.probe.logs[rosout:])

        self.wait(has_plan, 'the plan')
        if not self.stepped():  # its first step's messages were dropped (or come late)
            self.tick()
            self.run_until(self.at_control_instant, 'the next control instant')

    def kill_controller(self) -> None:
        """SIGKILL the controller process and reap it: it sends nothing more."""
        os.kill(self.controller.pid, signal.SIGKILL)
        self.controller.wait(timeout=HANG_GUARD)
        self.controller = None

    def steps(self) -> list[dict]:
        """The current controller's control steps (its diagnostics)."""
        return self.probe.diagnostics[self.first_diagnostic:]

    def stepped(self) -> bool:
        """Say whether the controller's step at this instant is done and its cmd_vel taken.

        Both by time: the diagnostics stamped now, a cmd_vel received now (an earlier
        command was received at an earlier simulated time, and one may have been dropped).
        """
        steps = self.steps()
        commands = self.simulator.received[self.first_command:]
        half_tick = 0.5 / SIM_RATE
        return (bool(steps) and abs(steps[-1].stamp - self.t) < half_tick
                and bool(commands) and commands[-1][0] > self.t - half_tick)

    def tick(self) -> None:
        self.ticks += 1
        self.probe.publish_clock(self.t)
        self.wait(lambda: bool(self.probe.odoms) and stamp(self.probe.odoms[-1])
                  >= self.t - 1e-6, 'odometry from the simulator')
        if self.controller is not None and self.at_control_instant():
            self.wait(self.stepped, 'control step')

    def run_until(self, condition: Callable[[], bool], what: str) -> None:
        """Tick until condition() holds (bounded by the hang guard only)."""
        while not condition():
            if time.monotonic() > self.deadline:
                pytest.fail(f'hang guard ({HANG_GUARD:g} s wall): not {what} at '
                            f't = {self.t:.2f} s:\n{self.log_tail()}')
            self.tick()


def stamp(msg: Odometry) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def drill(ros, tmp_path) -> tuple[RecordingSimulator, object, Lockstep]:
    """The simulator at the start, the probe (the plan published once) and the lockstep."""
    simulator = ros.add(RecordingSimulator(context=ros.context, parameter_overrides=[
        Parameter('use_sim_time', value=True), Parameter('rate', value=SIM_RATE),
        Parameter('cmd_timeout', value=CMD_TIMEOUT),
        Parameter('initial_pose', value=[float(v) for v in WORLD.start])]))
    probe = ros.probe(use_sim_time=True)
    probe.plan_pub.publish(poses_to_path(PLAN))  # once: transient_local keeps it for late nodes
    return simulator, probe, Lockstep(ros, probe, simulator, tmp_path / 'logs')


def test_a_killed_controller_stops_the_robot_and_a_restarted_one_drives_to_the_target(
        ros, tmp_path) -> None:
    simulator, probe, loop = drill(ros, tmp_path)
    try:
        # a controller process drives the robot past x = 1 (above the box)
        loop.start_controller()
        def halfway() -> bool:
            return (simulator.state[0] > 1.0 and bool(simulator.received)
                    and simulator.received[-1][1][0] > 0.05)

        loop.run_until(lambda: halfway() or loop.t > TIME_LIMIT, 'halfway')
        assert halfway(), f'not past x = 1 after {loop.t:g} s: {simulator.state}'
        last_time, last_u = simulator.received[-1]
        commands = len(simulator.received)
        loop.kill_controller()

        # the simulator drives on the last command for cmd_timeout, then stops the robot
        loop.run_until(lambda: loop.t > last_time + CMD_TIMEOUT + 1.0, 'a second after')
        assert len(simulator.received) == commands  # the killed controller sent nothing more
        after = [m for m in probe.odoms if stamp(m) > last_time]
        moving = [m for m in after if stamp(m) - last_time <= CMD_TIMEOUT + 1e-9]
        halted = after[len(moving):]
        assert stamp(moving[-1]) - last_time >= CMD_TIMEOUT - 1.0 / SIM_RATE - 1e-9
        for msg in moving:
            np.testing.assert_array_equal(u_from_twist(msg.twist.twist), last_u)
        assert len(halted) >= SIM_RATE  # a second of odometry, all of it standing still
        halted_at = odometry_to_state(halted[0])
        for msg in halted:
            np.testing.assert_array_equal(u_from_twist(msg.twist.twist), [0.0, 0.0])
            np.testing.assert_array_equal(odometry_to_state(msg), halted_at)

        # a new controller process gets the plan (published once, transient_local) and
        # drives to the target
        loop.run_until(loop.at_control_instant, 'a control instant')
        rosout = len(probe.logs)
        loop.start_controller(again=True)
        def arrived() -> bool:
            return any(d.step.goal_reached for d in loop.steps())

        loop.run_until(lambda: arrived() or loop.t > TIME_LIMIT, 'at the goal')
        assert arrived(), f'not at the goal after {loop.t:g} s: {simulator.state}'
        restarted = stamp(next(m for m in probe.odoms if stamp(m) > loop.steps()[0].stamp))
    finally:
        if loop.controller is not None:
            loop.controller.send_signal(signal.SIGINT)
            try:
                loop.controller.wait(timeout=15)
            except subprocess.TimeoutExpired:
                loop.controller.kill()
                loop.controller.wait()
    new_plans = [entry.msg for entry in probe.logs[rosout:]
                 if entry.name == 'mpc_controller' and entry.msg.startswith('new plan')]
    assert len(new_plans) == 1 and new_plans[0].startswith(f'new plan: {len(PLAN)} poses')
    # the robot stood still until the new controller's first step
    for msg in probe.odoms:
        if stamp(halted[0]) <= stamp(msg) < restarted:
            np.testing.assert_array_equal(odometry_to_state(msg), halted_at)
    # arrived as the restarted controller declares it: within its default xy_goal_tolerance
    assert (np.hypot(*(simulator.state[:2] - WORLD.goal[:2]))
            <= ControllerSettings().xy_goal_tolerance + 1e-6), simulator.state
    positions = np.array([[m.pose.pose.position.x, m.pose.pose.position.y] for m in probe.odoms])
    for obstacle in WORLD.obstacles:
        assert not np.any(obstacle.contains(positions))
    assert 'started again' in (tmp_path / 'logs' / 'mpc_controller.log').read_text()


def test_sigterm_to_a_driving_controller_sends_zero_before_the_process_ends(
        ros, tmp_path) -> None:
    simulator, probe, loop = drill(ros, tmp_path)
    try:
        loop.start_controller()
        process = loop.controller

        def driving() -> bool:
            return bool(simulator.received) and simulator.received[-1][1][0] > 0.05

        loop.run_until(lambda: driving() or loop.t > TIME_LIMIT, 'driving')
        assert driving(), 'the controller never drove'
        commands = len(simulator.received)
        loop.controller = None  # it is meant to exit now
        process.send_signal(signal.SIGTERM)
        # time stands still: a command now can only come from the process on its way out
        assert ros.spin_until(lambda: process.poll() is not None
                              and len(simulator.received) > commands, timeout=HANG_GUARD)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 0, loop.log_tail()
    np.testing.assert_array_equal(simulator.received[-1][1], [0.0, 0.0])
    assert 'exiting: cmd_vel zero' in loop.log_tail()
    assert 'Traceback' not in loop.log_tail()


# ----------------------------------------------------------------------------- 7. a hostile client
# What an outside adversarial client found over DDS: lifecycle requests out of order, scans
# whose beams do not match their angles or are stamped in the future, a map source that
# never delivers.
# (transition id, name) requests that none of the states listed with them has.
BAD_TRANSITIONS = {
    'unconfigured': [(Transition.TRANSITION_ACTIVATE, 'activate'),
                     (Transition.TRANSITION_DEACTIVATE, 'deactivate'),
                     (Transition.TRANSITION_CLEANUP, 'cleanup'), (99, 'unknown id')],
    'inactive': [(Transition.TRANSITION_CONFIGURE, 'configure'),
                 (Transition.TRANSITION_DEACTIVATE, 'deactivate'), (99, 'unknown id')],
    'active': [(Transition.TRANSITION_CONFIGURE, 'configure'),
               (Transition.TRANSITION_CLEANUP, 'cleanup'),
               (Transition.TRANSITION_ACTIVATE, 'activate'), (99, 'unknown id')],
}


class LifecycleClient(Node):
    """A lifecycle manager's side of one node's change_state and get_state services."""

    def __init__(self, context, target: str) -> None:
        super().__init__('hostile_manager', context=context)
        self.change = self.create_client(ChangeState, f'/{target}/change_state')
        self.get = self.create_client(GetState, f'/{target}/get_state')

    def call(self, ros, client, request):
        assert ros.spin_until(client.service_is_ready)
        future = client.call_async(request)
        assert ros.spin_until(future.done, timeout=60.0), 'no answer: did the node die?'
        return future.result()

    def request(self, ros, transition: int) -> bool:
        return self.call(ros, self.change,
                         ChangeState.Request(transition=Transition(id=transition))).success

    def state(self, ros) -> str:
        return self.call(ros, self.get, GetState.Request()).current_state.label


def refuse_all(ros, client: LifecycleClient, probe, name: str, state: str) -> None:
    """Every request state has no transition for is answered false; the node stays put."""
    assert client.state(ros) == state
    for transition, label in BAD_TRANSITIONS[state]:
        assert not client.request(ros, transition), f'{label} accepted while {state}'
        assert client.state(ros) == state, f'{label} while {state} moved the node'
    assert ros.spin_until(lambda: any(
        f'the node is {state}, which has no such transition' in line
        for line in probe.log_lines(name, Log.WARN))), probe.log_lines(name)


MANAGED = {
    'mpc_controller': lambda ctx: MpcControllerNode(context=ctx, parameter_overrides=[
        Parameter('autostart', value=False),
        Parameter('world_file', value='paper_obstacle.yaml')]),
    'global_planner': lambda ctx: GlobalPlannerNode(context=ctx, parameter_overrides=[
        Parameter('autostart', value=False),
        Parameter('world_file', value='paper_obstacle.yaml')]),
    'map_server': lambda ctx: MapServerNode(context=ctx, parameter_overrides=[
        Parameter('autostart', value=False),
        Parameter('yaml_filename', value='maps/paper_obstacle.yaml')]),
}


@pytest.mark.parametrize('name', sorted(MANAGED))
def test_out_of_order_lifecycle_requests_are_refused_and_the_node_stays_in_its_state(
        ros, name: str) -> None:
    node = ros.add(MANAGED[name](ros.context))
    probe = ros.probe()
    client = ros.add(LifecycleClient(ros.context, name))
    refuse_all(ros, client, probe, name, 'unconfigured')
    assert client.request(ros, Transition.TRANSITION_CONFIGURE)
    refuse_all(ros, client, probe, name, 'inactive')
    assert client.request(ros, Transition.TRANSITION_ACTIVATE)
    refuse_all(ros, client, probe, name, 'active')
    assert client.request(ros, Transition.TRANSITION_DEACTIVATE)
    assert client.request(ros, Transition.TRANSITION_CLEANUP)
    assert client.state(ros) == 'unconfigured'
    # the trigger_* methods a process calls go through the same gate
    assert node.trigger_activate() == TransitionCallbackReturn.FAILURE
    assert client.state(ros) == 'unconfigured'


def test_a_controller_asked_for_wrong_transitions_while_driving_keeps_driving(ros) -> None:
    node, probe, clock = start_controller(ros)
    client = ros.add(LifecycleClient(ros.context, 'mpc_controller'))
    refuse_all(ros, client, probe, 'mpc_controller', 'active')
    after = len(probe.diagnostics)
    assert clock.run_until(lambda: tracking(probe, after))
    check_commands(probe)


# 181 beams over the front half-plane, as a 1-degree laser sends them.
SCAN_BEAMS = 181
SCAN_INCREMENT = math.pi / (SCAN_BEAMS - 1)


def free_scan(stamp: float, *, beams: int = SCAN_BEAMS, increment: float = SCAN_INCREMENT,
              angle_min: float = -math.pi / 2, angle_max: float = math.pi / 2) -> LaserScan:
    """A scan that sees nothing (every beam inf, REP 117's "no return"), stamped stamp."""
    msg = LaserScan()
    msg.header.frame_id = 'base_link'
    msg.header.stamp = seconds_to_stamp(stamp)
    msg.angle_min, msg.angle_max, msg.angle_increment = angle_min, angle_max, increment
    msg.range_min, msg.range_max = 0.05, 5.0
    msg.ranges = [math.inf] * beams
    return msg


BAD_SCANS = {
    '250 beams for 181': (lambda t: free_scan(t, beams=250), 'scan has 250 ranges',
                          'imply 181'),
    '60 beams for 181': (lambda t: free_scan(t, beams=60), 'scan has 60 ranges', 'imply 181'),
    'a negative increment from min to max': (
        lambda t: free_scan(t, increment=-SCAN_INCREMENT), 'scan has 181 ranges',
        "increment's sign leads away"),
    'stamped 30 s in the future': (lambda t: free_scan(t + 30.0), 'in the future',
                                   'are the clocks in sync'),
}


class ScanningClock(OdomClock):
    """OdomClock that also publishes scan(t) on `scan` each tick (before the odometry)."""

    def __init__(self, ros, probe, scan_pub) -> None:
        super().__init__(ros, probe)
        self.scan_pub = scan_pub
        self.scan: Callable[[float], LaserScan] | None = None

    def publish(self) -> None:
        if self.scan is not None:
            self.scan_pub.publish(self.scan(self.t))
        super().publish()


def start_sensing_controller(ros, sources: list[str]):
    """A controller in simulated time with obstacle_sources, the probe, a scanning clock."""
    node = started(ros.add(MpcControllerNode(context=ros.context, parameter_overrides=[
        Parameter('use_sim_time', value=True), Parameter('obstacle_sources', value=sources),
        Parameter('world_file', value='paper_obstacle.yaml')])))
    probe = ros.probe(use_sim_time=True)
    scan_pub = probe.create_publisher(LaserScan, 'scan', SCAN_QOS)
    probe.map_pub = probe.create_publisher(OccupancyGrid, 'map', MAP_QOS)
    clock = ScanningClock(ros, probe, scan_pub)
    assert ros.spin_until(lambda: probe.plan_pub.get_subscription_count() > 0
                          and probe.odom_pub.get_subscription_count() > 0
                          and ('scan' not in sources or scan_pub.get_subscription_count() > 0))
    probe.plan_pub.publish(poses_to_path(PLAN))
    clock.odom = WORLD.start.copy()
    return node, probe, clock


def stands_still(probe, first: int, reason: Reason, seconds: float, clock: OdomClock) -> None:
    """For `seconds` of simulated time every step commands zero, for reason."""
    end = clock.t + seconds
    assert clock.run_until(lambda: clock.t >= end)
    steps = probe.diagnostics[first:]
    assert len(steps) >= seconds / STEP - 2, steps
    for diag in steps:
        np.testing.assert_array_equal(applied(diag), [0.0, 0.0])
    assert steps[-1].step.reason is reason, steps[-1]
    assert all(c.linear.x == 0.0 and c.angular.z == 0.0 for c in probe.cmds)


@pytest.mark.parametrize('case', sorted(BAD_SCANS))
def test_a_scan_the_controller_cannot_place_is_refused_with_one_error_and_the_robot_waits(
        ros, case: str, throttle_clock) -> None:
    make, *texts = BAD_SCANS[case]
    node, probe, clock = start_sensing_controller(ros, ['world', 'scan'])
    clock.scan = make
    stands_still(probe, 0, Reason.NO_SCAN, 3.0, clock)

    def said() -> list[str]:
        return [line for line in errors(probe, 'mpc_controller', 'invalid scan')
                if all(text in line for text in texts)]

    assert ros.spin_until(lambda: bool(said())), probe.log_lines('mpc_controller')
    assert len(said()) == 1, said()  # the throttle's clock is held
    # a scan that is right: the robot drives
    clock.scan = free_scan
    after = len(probe.diagnostics)
    assert clock.run_until(lambda: tracking(probe, after)), probe.diagnostics[-3:]


def test_with_the_map_a_source_the_controller_waits_for_a_valid_map_and_says_so_once(
        ros) -> None:
    node, probe, clock = start_sensing_controller(ros, ['world', 'map'])
    bad = OccupancyGrid()
    bad.header.frame_id = 'map'
    bad.info.width, bad.info.height, bad.info.resolution = 10, 10, 0.1
    bad.data = [0] * 7  # not width x height
    probe.map_pub.publish(bad)
    stands_still(probe, 0, Reason.NO_MAP, 3.0, clock)

    def said() -> list[str]:
        return [line for line in probe.log_lines('mpc_controller', Log.WARN)
                if line.startswith(Reason.NO_MAP.text)]

    # /rosout is a topic of its own: wait for the lines, then count them
    assert ros.spin_until(lambda: said() and errors(probe, 'mpc_controller', 'invalid map'))
    assert len(said()) == 1 and 'cmd_vel is zero' in said()[0], said()
    good = copy.deepcopy(bad)
    good.info.origin.position.x = good.info.origin.position.y = -5.0
    good.info.width = good.info.height = 100
    good.data = [0] * 10_000
    probe.map_pub.publish(good)
    after = len(probe.diagnostics)
    assert clock.run_until(lambda: tracking(probe, after)), probe.diagnostics[-3:]
