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
"""Bad input, stale data and solver failure end in a safe stop, and the nodes recover.

Every test spins the real nodes in their own context. Where timing matters the test owns
simulated time (it publishes /clock), so the assertions are about ROS time and do not depend
on how loaded the machine is.
"""

from __future__ import annotations

import copy
import glob
import json
import math
import os
import signal
import subprocess
import sys
import time
from typing import Callable

from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import Odometry, Path
import numpy as np
import pytest
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter

from mpc_local_planner.core.controller import (
    first_blocked_segment,
    REASON_CANDIDATE,
    REASON_OK,
    REASON_STALE_ODOM,
    REASON_STOP,
)
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.ros.closed_loop import MODULES
from mpc_local_planner.ros.conversions import (
    path_to_poses,
    poses_to_path,
    seconds_to_stamp,
    state_to_odometry,
    u_from_twist,
    yaw_to_quaternion,
)
from mpc_local_planner.ros.global_planner_node import GlobalPlannerNode
from mpc_local_planner.ros.mpc_controller_node import ERROR_THROTTLE_S, MpcControllerNode
from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode
from mpc_local_planner.worlds.world import paper_world

WORLD = paper_world()
# A plan around the paper's box (above it), headings as the planner sends them.
PLAN = np.array([[0.0, 0.0, WORLD.start[2]], [0.8, 1.3, 0.0], [1.7, 1.3, -0.96],
                 [2.5, 0.0, WORLD.goal[2]]])
U_MAX = Unicycle().u_max
STEP = 0.2  # the controller's default control period (s)
ODOM_TIMEOUT = 0.5  # the controller's default odom_timeout (s)


# ----------------------------------------------------------------------------- helpers
class SimClock:
    """Simulated time owned by the test: each tick publishes odometry (if set), then /clock.

    Args:
        ros: the harness whose executor is spun between ticks.
        probe: the Probe that publishes.
        dt: simulated seconds per tick.

    """

    def __init__(self, ros, probe, dt: float = 0.05) -> None:  # noqa: ANN001
        self.ros, self.probe, self.dt = ros, probe, dt
        self.t = 1.0  # 0 is "no time yet" for a node with use_sim_time
        self.odom: np.ndarray | Odometry | None = None
        self.last_odom_stamp: float | None = None

    def tick(self) -> None:
        """Advance time by dt, publish, and let every node react."""
        self.t += self.dt
        if isinstance(self.odom, Odometry):
            msg = copy.deepcopy(self.odom)
            msg.header.stamp = seconds_to_stamp(self.t)
            self.probe.odom_pub.publish(msg)
        elif self.odom is not None:
            self.probe.publish_odom(self.odom, stamp=self.t)
        if self.odom is not None:
            self.last_odom_stamp = self.t
        self.probe.publish_clock(self.t)
        for _ in range(6):
            self.ros.executor.spin_once(timeout_sec=0.002)

    def run_until(self, condition: Callable[[], bool], timeout: float = 30.0) -> bool:
        """Tick until condition() holds or timeout wall seconds pass; return condition()."""
        deadline = time.monotonic() + timeout
        while not condition() and time.monotonic() < deadline:
            self.tick()
        return condition()


def check_commands(probe) -> np.ndarray:  # noqa: ANN001
    """Assert every cmd_vel so far is finite and within the unicycle's bounds; return them."""
    commands = np.array([u_from_twist(c) for c in probe.cmds]).reshape(-1, 2)
    raw = np.array([[c.linear.x, c.angular.z] for c in probe.cmds]).reshape(-1, 2)
    assert np.all(np.isfinite(raw))
    assert np.all(np.abs(raw) <= U_MAX + 1e-12)
    return commands


def applied(diag: dict) -> np.ndarray:
    """The (v, omega) a control step published, from its diagnostics."""
    return np.array([float(diag['v']), float(diag['omega'])])


def tracking(probe, after: int = 0) -> bool:  # noqa: ANN001
    """Say whether a step after the first `after` diagnostics drove on a solver solution."""
    return any(d['message'] == REASON_OK and d['source'] == 'solver' and applied(d)[0] > 0.01
               for d in probe.diagnostics[after:])


def errors(probe, node: str, text: str) -> list[str]:  # noqa: ANN001
    """Error lines node logged that contain text."""
    return [line for line in probe.log_lines(node, Log.ERROR) if text in line]


def start_controller(ros, **params) -> tuple[MpcControllerNode, object, SimClock]:  # noqa: ANN001, ANN003
    """A controller in simulated time with a probe that owns the clock; tracking PLAN."""
    overrides = [Parameter('use_sim_time', value=True)]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    node = ros.add(MpcControllerNode(context=ros.context, parameter_overrides=overrides))
    probe = ros.probe(use_sim_time=True)
    clock = SimClock(ros, probe)
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
    'through the obstacle': (lambda: path_message(np.array([WORLD.start, WORLD.goal])),
                             'passes through obstacle 0'),
    'frame odom': (lambda: path_message(PLAN, frame_id='odom'), "frame 'odom' is not 'map'"),
    '100,000 poses': (lambda: dense_plan(100_000),
                      '100000 poses, more than max_plan_poses (10000)'),
}


def check_refusal(ros, probe, clock, prefix: str, text: str,  # noqa: ANN001
                  restore: Callable[[], None]) -> None:
    """The command goes to zero with the problem as the reason; one error; then recovery."""
    first = len(probe.diagnostics)
    began = time.monotonic()

    def refused() -> list[dict]:
        return [d for d in probe.diagnostics[first:]
                if d['message'].startswith(prefix) and text in d['message']]

    # a few refused steps, and the error line from /rosout
    assert clock.run_until(lambda: len(refused()) >= 3
                           and errors(probe, 'mpc_controller', text)), probe.diagnostics[-3:]
    for diag in refused():
        np.testing.assert_array_equal(applied(diag), [0.0, 0.0])
        assert diag['level'] == 2  # DiagnosticStatus.ERROR
    # every step after the first refused one commands zero until the input is fixed
    index = probe.diagnostics.index(refused()[0])
    assert all(not applied(d).any() for d in probe.diagnostics[index:])
    lines = errors(probe, 'mpc_controller', text)
    assert 1 <= len(lines) <= 1 + (time.monotonic() - began) / ERROR_THROTTLE_S, lines
    assert 'zero' in lines[0]

    restore()
    after = len(probe.diagnostics)
    assert clock.run_until(lambda: tracking(probe, after)), probe.diagnostics[-3:]
    check_commands(probe)


@pytest.mark.parametrize('case', list(BAD_ODOMETRY))
def test_bad_odometry_stops_the_robot_with_one_error_and_it_resumes(ros, case: str) -> None:  # noqa: ANN001
    _, probe, clock = start_controller(ros)
    message, text = BAD_ODOMETRY[case]
    clock.odom = message

    def restore() -> None:
        clock.odom = WORLD.start.copy()

    check_refusal(ros, probe, clock, 'invalid odometry', text, restore)
    assert any('odometry is valid again' in line
               for line in probe.log_lines('mpc_controller', Log.INFO))


@pytest.mark.parametrize('case', list(BAD_PLANS))
def test_a_bad_plan_stops_the_robot_with_one_error_and_a_valid_one_resumes(ros, case: str) -> None:  # noqa: ANN001
    _, probe, clock = start_controller(ros)
    make, text = BAD_PLANS[case]
    probe.plan_pub.publish(make())
    check_refusal(ros, probe, clock, 'invalid plan', text,
                  lambda: probe.plan_pub.publish(poses_to_path(PLAN)))


def test_a_plan_with_repeated_points_is_followed_without_them(ros) -> None:  # noqa: ANN001
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
        ros) -> None:  # noqa: ANN001
    _, probe, clock = start_controller(ros)
    clock.odom = None  # the odometry stops
    last = clock.last_odom_stamp
    first = len(probe.diagnostics)

    def stale() -> list[dict]:
        return [d for d in probe.diagnostics[first:] if d['message'] == REASON_STALE_ODOM]

    assert clock.run_until(lambda: bool(stale()))
    # the first step later than odom_timeout after the last odometry commands zero
    assert stale()[0]['stamp'] <= last + ODOM_TIMEOUT + STEP + 1e-6
    np.testing.assert_array_equal(applied(stale()[0]), [0.0, 0.0])
    index = probe.diagnostics.index(stale()[0])
    # until then the robot was driven on odometry at most odom_timeout old
    for diag in probe.diagnostics[first:index]:
        assert diag['stamp'] - last <= ODOM_TIMEOUT + 1e-6
    assert clock.run_until(lambda: len(stale()) >= 3)
    assert all(not applied(d).any() for d in probe.diagnostics[index:])

    clock.odom = WORLD.start.copy()
    after = len(probe.diagnostics)
    assert clock.run_until(lambda: tracking(probe, after))
    check_commands(probe)


def test_odometry_stamped_in_the_future_goes_stale_when_it_stops(ros) -> None:  # noqa: ANN001
    _, probe, clock = start_controller(ros)
    clock.odom = None
    probe.publish_odom(WORLD.start, stamp=clock.t + 3600.0)  # a clock an hour ahead
    stop = clock.t
    first = len(probe.diagnostics)
    assert clock.run_until(lambda: any(d['message'] == REASON_STALE_ODOM
                                       for d in probe.diagnostics[first:]))
    stale = next(d for d in probe.diagnostics[first:] if d['message'] == REASON_STALE_ODOM)
    # timed from its arrival (a few ticks after it was sent, on a loaded machine), not from
    # its stamp an hour ahead
    assert stale['stamp'] <= stop + ODOM_TIMEOUT + STEP + 1.0


def test_simulator_stops_the_robot_when_cmd_vel_stops_for_cmd_timeout(ros) -> None:  # noqa: ANN001
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
def failing_solver(nlp, w0, params, active, solver=None):  # noqa: ANN001, ANN201, ARG001
    """Stand-in for PathReferenceMPC._run_solver: every NLP solve fails (IPOPT's too)."""
    return False, np.asarray(w0, dtype=float), math.inf, 'injected failure', 0, 0.0


def test_injected_solver_failures_apply_the_shifted_candidate_at_most_n_steps_then_stop(
        ros, monkeypatch) -> None:  # noqa: ANN001
    horizon = 10
    ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter('publish_clock', value=True), Parameter('real_time_factor', value=2.0),
        Parameter('initial_pose', value=[float(v) for v in WORLD.start])]))
    node = ros.add(MpcControllerNode(context=ros.context, parameter_overrides=[
        Parameter('use_sim_time', value=True), Parameter('analytic_path', value='paper_sinusoid'),
        Parameter('horizon', value=horizon)]))
    probe = ros.probe(use_sim_time=True)

    def driving_on_the_solver() -> bool:
        out = node.last_output
        solved = sum(d['source'] == 'solver' for d in probe.diagnostics)
        return (solved >= 5 and out is not None and out.solution is not None
                and out.solution.success and out.u[0] > 0.05)

    assert ros.spin_until(driving_on_the_solver, timeout=60.0)
    verified = node.last_output.solution  # the last plan the solver gave
    patched_at = node.get_clock().now().nanoseconds * 1e-9
    failures_before = node.controller.solver_failures
    monkeypatch.setattr(node.controller.mpc, '_run_solver', failing_solver)

    def after_patch() -> list[dict]:
        return [d for d in probe.diagnostics if d['stamp'] > patched_at]

    assert ros.spin_until(lambda: sum(d['message'] == REASON_STOP for d in after_patch()) >= 3,
                          timeout=60.0), after_patch()[-3:]
    steps = after_patch()
    candidates = [d for d in steps if d['source'] == 'candidate' and applied(d).any()]
    # the proof's candidate: the verified inputs shifted by one step per failure...
    assert 1 <= len(candidates) <= horizon
    for k, diag in enumerate(candidates, start=1):
        assert diag['message'] == REASON_CANDIDATE
        assert int(diag['failures']) == k
        np.testing.assert_allclose(applied(diag), verified.u_pred[k], atol=1e-12)
    # ...then it has run out: zero from the N-th failure on, the robot stops
    stop = steps.index(next(d for d in steps if d['message'] == REASON_STOP))
    assert int(steps[stop]['failures']) == horizon + 1
    assert all(not applied(d).any() for d in steps[len(candidates):])
    assert steps[stop]['level'] == 2
    assert int(steps[-1]['failures_total']) >= failures_before + horizon + 1
    assert ros.spin_until(lambda: abs(probe.odoms[-1].twist.twist.linear.x) < 1e-12
                          and abs(probe.odoms[-1].twist.twist.angular.z) < 1e-12)
    assert any(REASON_STOP in line for line in probe.log_lines('mpc_controller', Log.WARN))
    check_commands(probe)

    # the solver is back: the robot drives on
    monkeypatch.undo()
    resumed = len(probe.diagnostics)
    assert ros.spin_until(lambda: tracking(probe, resumed), timeout=30.0)
    check_commands(probe)


def test_a_state_inside_the_obstacle_is_infeasible_the_robot_stops_and_resumes_outside(
        ros) -> None:  # noqa: ANN001
    node, probe, clock = start_controller(ros)
    failures = node.controller.solver_failures
    first = len(probe.diagnostics)
    clock.odom = np.array([1.25, 0.0, 0.0])  # inside the box: no input keeps it clear

    def stopped() -> list[dict]:
        return [d for d in probe.diagnostics[first:] if d['message'] == REASON_STOP]

    assert clock.run_until(lambda: len(stopped()) >= 2)
    for diag in stopped():
        np.testing.assert_array_equal(applied(diag), [0.0, 0.0])
        assert diag['source'] == 'stop' and diag['level'] == 2
        assert int(diag['failures']) >= 1
    assert node.controller.solver_failures >= failures + 2
    assert int(stopped()[-1]['failures_total']) > failures
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
        tmp_path) -> None:  # noqa: ANN001
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
        ros, tmp_path) -> None:  # noqa: ANN001
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


def start_planner(ros) -> tuple[GlobalPlannerNode, object]:  # noqa: ANN001
    planner = ros.add(GlobalPlannerNode(context=ros.context, parameter_overrides=[
        Parameter('world_file', value='paper_obstacle.yaml')]))
    probe = ros.probe()
    assert ros.spin_until(lambda: probe.goal_pub.get_subscription_count() > 0
                          and probe.odom_pub.get_subscription_count() > 0)
    return planner, probe


def refuse_goal(ros, planner, probe, goal: PoseStamped, state: np.ndarray, text: str) -> None:  # noqa: ANN001
    """Send goal with the robot at state: an error that says text, and no plan."""
    plans = planner.plan_count
    probe.goal_pub.publish(goal)

    def refused() -> bool:
        probe.publish_odom(state)
        return bool(errors(probe, 'global_planner', text))

    assert ros.spin_until(refused, timeout=20.0), probe.log_lines('global_planner')
    assert 'no plan' in errors(probe, 'global_planner', text)[-1]
    assert planner.plan_count == plans


def plan_to(ros, planner, probe, goal: np.ndarray, state: np.ndarray) -> np.ndarray:  # noqa: ANN001
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
        ros) -> None:  # noqa: ANN001
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


def test_planner_publishes_no_plan_from_a_start_in_collision_and_plans_once_clear(ros) -> None:  # noqa: ANN001
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
def end_process_group(process: subprocess.Popen) -> None:
    """Stop a process started with start_new_session, and every node it started.

    SIGKILL of closed_loop alone would leave its node processes running (seen once after a
    failed assertion here): SIGINT lets it shut them down, then the group is killed.
    """
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGINT)
        try:
            process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            pass
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass  # the group is gone already
    process.wait()


def child_processes(parent: int, module: str) -> list[int]:
    """Pids of parent's children whose command line runs module (from /proc)."""
    pids = []
    for stat in glob.glob('/proc/[0-9]*/stat'):
        try:
            fields = open(stat, encoding='utf-8').read().rsplit(')', 1)[1].split()
            pid = int(stat.split('/')[2])
            cmdline = open(f'/proc/{pid}/cmdline', 'rb').read().decode(errors='replace')
        except (OSError, IndexError, ValueError):
            continue  # gone meanwhile
        if int(fields[1]) == parent and module in cmdline:
            pids.append(pid)
    return pids


# Simulated seconds a probe's clock may lag the simulator's (rtf 2: 0.125 s of wall time).
LAG = 0.25


def test_a_killed_controller_stops_the_robot_and_a_restarted_one_drives_to_the_target(
        ros, tmp_path) -> None:  # noqa: ANN001
    cmd_timeout, rate = 0.5, 50.0  # the simulator's defaults, as closed_loop runs it
    loop = subprocess.Popen(
        [sys.executable, '-m', 'mpc_local_planner.ros.closed_loop', '--separate-processes',
         '--respawn', '--path', 'rrt', '--rtf', '2', '--timeout', '90', '--out', str(tmp_path)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        start_new_session=True)  # its own process group: the cleanup reaches the nodes too
    try:
        probe = ros.probe(use_sim_time=True)

        def halfway() -> bool:
            return bool(probe.odoms) and probe.odoms[-1].pose.pose.position.x > 1.0 and (
                probe.odoms[-1].twist.twist.linear.x > 0.05)

        assert ros.spin_until(halfway, timeout=60.0)
        assert ros.spin_until(
            lambda: len(child_processes(loop.pid, MODULES['mpc_controller'])) == 1,
            timeout=10.0), child_processes(loop.pid, MODULES['mpc_controller'])
        controllers = child_processes(loop.pid, MODULES['mpc_controller'])
        os.kill(controllers[0], signal.SIGKILL)
        killed_at = probe.now()
        commands = len(probe.cmds)

        # the simulator stops the robot cmd_timeout after the last command it got
        def stopped() -> bool:
            late = [m for m in probe.odoms if stamp(m) > killed_at]
            return len(late) > 5 and all(m.twist.twist.linear.x == 0.0 for m in late[-5:])

        assert ros.spin_until(stopped, timeout=30.0)
        late = [m for m in probe.odoms if stamp(m) > killed_at]
        halted = stamp(next(m for m in late if m.twist.twist.linear.x == 0.0))
        moving = [stamp(m) for m in late if m.twist.twist.linear.x != 0.0
                  and stamp(m) < halted]
        # the killed controller's commands: all arrived before the robot halted (a new
        # controller needs seconds to start); the probe's clock lags the simulator's by
        # the /clock delivery, LAG of simulated time at most
        last_command = max(t for t in probe.cmd_times if t <= halted)
        assert len(probe.cmd_times) >= commands
        assert killed_at <= moving[-1]  # it coasted on the last command...
        assert moving[-1] <= last_command + cmd_timeout + 2.0 / rate + LAG  # ...cmd_timeout

        # closed_loop started a new controller: it gets /plan and drives to the target
        output, _ = loop.communicate(timeout=90)
    finally:
        end_process_group(loop)
    assert loop.returncode == 0, output
    metrics = json.loads((tmp_path / 'metrics.json').read_text())
    assert metrics['reached'] and not metrics['collision'], metrics
    assert [r['node'] for r in metrics['respawns']] == ['mpc_controller']
    assert metrics['messages']['/plan'] == 1  # planned once: the new controller got that plan
    positions = np.array([[m.pose.pose.position.x, m.pose.pose.position.y] for m in probe.odoms])
    for obstacle in WORLD.obstacles:
        assert not np.any(obstacle.contains(positions))
    assert 'started again' in (tmp_path / 'logs' / 'mpc_controller.log').read_text()


def stamp(msg: Odometry) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
