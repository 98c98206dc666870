# SPDX-License-Identifier: Apache-2.0
"""Each node against test publishers and subscribers, in its own rclpy context."""

from __future__ import annotations

import math

from conftest import flat_parameters, Probe, SimClock
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from rclpy.lifecycle import LifecycleNode
from rclpy.node import Node
from rclpy.parameter import Parameter

from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.diagnostics import (
    Level,
)
from mpc_local_planner.core.footprint import FROM_WORLD
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.obstacles import segment_collides
from mpc_local_planner.ros.conversions import (
    odometry_to_state,
    path_to_poses,
    poses_to_path,
    stamp_to_seconds,
    u_from_twist,
    yaw_to_quaternion,
)
from mpc_local_planner.ros.global_planner_node import GlobalPlannerNode
from mpc_local_planner.ros.mpc_controller_node import MpcControllerNode
from mpc_local_planner.ros.mpc_controller_outputs import log_line
from mpc_local_planner.ros.mpc_controller_parameters import load_robot
from mpc_local_planner.ros.node_main import autostart
from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode
from mpc_local_planner.worlds.world import paper_world

pytestmark = pytest.mark.dds  # DDS: every test spins nodes in an rclpy context
WORLD = paper_world()
PLAN = np.array([[0.0, 0.0, WORLD.start[2]], [0.8, 1.3, 0.0], [1.7, 1.3, -0.96],
                 [2.5, 0.0, WORLD.goal[2]]])


def started(node: Node) -> Node:
    """Configure and activate a lifecycle node (autostart is true by default), as run_node does."""
    if isinstance(node, LifecycleNode):
        assert autostart(node) is None
    return node


def exact_arc(pose: np.ndarray, v: float, omega: float, t: float) -> np.ndarray:
    x, y, th = pose
    if abs(omega) < 1e-12:
        return np.array([x + v * t * math.cos(th), y + v * t * math.sin(th), th])
    return np.array([x + v / omega * (math.sin(th + omega * t) - math.sin(th)),
                     y - v / omega * (math.cos(th + omega * t) - math.cos(th)),
                     th + omega * t])


# ----------------------------------------------------------------------------- simulator
def run_simulator(ros, command: tuple[float, float], duration: float) -> list[Odometry]:
    sim = ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter('publish_clock', value=True), Parameter('real_time_factor', value=10.0),
        Parameter('rate', value=50.0), Parameter('cmd_timeout', value=0.0),
        Parameter('initial_pose', value=[1.0, 2.0, 0.5])]))
    probe = ros.probe()
    assert ros.spin_until(lambda: probe.cmd_pub.get_subscription_count() > 0)
    twist = Twist()
    twist.linear.x, twist.angular.z = command
    probe.cmd_pub.publish(twist)

    def moving_for(span: float) -> bool:
        moving = [m for m in probe.odoms if m.twist.twist.linear.x != 0.0]
        return bool(moving) and (stamp_to_seconds(moving[-1].header.stamp)
                                 - stamp_to_seconds(moving[0].header.stamp)) >= span

    assert ros.spin_until(lambda: moving_for(duration), timeout=20.0)
    assert sim.sim_time > duration
    return [m for m in probe.odoms if m.twist.twist.linear.x != 0.0]


def check_arc(odoms: list[Odometry], v: float, omega: float) -> None:
    first, last = odoms[0], odoms[-1]
    t = stamp_to_seconds(last.header.stamp) - stamp_to_seconds(first.header.stamp)
    expected = exact_arc(odometry_to_state(first), v, omega, t)
    got = odometry_to_state(last)
    np.testing.assert_allclose(got[:2], expected[:2], atol=1e-6)
    assert math.remainder(got[2] - expected[2], 2 * math.pi) == pytest.approx(0.0, abs=1e-6)
    stamps = np.array([stamp_to_seconds(m.header.stamp) for m in odoms])
    np.testing.assert_allclose(np.diff(stamps), 0.02, atol=1e-6)  # one tick of 1/rate each


def test_simulator_integrates_a_constant_twist_as_the_unicycle_arc(ros) -> None:
    odoms = run_simulator(ros, (0.2, 0.5), duration=1.0)
    np.testing.assert_allclose(u_from_twist(odoms[-1].twist.twist), [0.2, 0.5])
    check_arc(odoms, 0.2, 0.5)


def test_simulator_saturates_the_command_at_the_bounds(ros) -> None:
    odoms = run_simulator(ros, (1.0, -5.0), duration=0.5)
    bounds = Unicycle().u_max
    np.testing.assert_allclose(u_from_twist(odoms[-1].twist.twist), [bounds[0], -bounds[1]])
    check_arc(odoms, bounds[0], -bounds[1])


# ----------------------------------------------------------------------------- controller
def make_controller(ros, **params) -> tuple[MpcControllerNode, Probe]:
    # the paper's world, named: the node's default is no world (params may override it)
    overrides = [Parameter('world_file', value='paper_obstacle.yaml')]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    controller = started(ros.add(
        MpcControllerNode(context=ros.context, parameter_overrides=overrides)))
    probe = ros.probe()
    return controller, probe


def test_controller_without_a_plan_commands_zero_and_says_why(ros) -> None:
    _, probe = make_controller(ros)
    assert ros.spin_until(lambda: probe.odom_pub.get_subscription_count() > 0)
    probe.publish_odom(WORLD.start)
    assert ros.spin_until(lambda: any(d.step.reason is Reason.NO_PLAN for d in probe.diagnostics))
    no_plan = next(d for d in probe.diagnostics if d.step.reason is Reason.NO_PLAN)
    assert no_plan.message == 'no plan yet' and no_plan.step.detail == ''
    assert probe.cmds
    assert all(c.linear.x == 0.0 and c.angular.z == 0.0 for c in probe.cmds)


def test_controller_answers_odometry_and_a_plan_with_a_bounded_cmd_vel(ros) -> None:
    _, probe = make_controller(ros)
    assert ros.spin_until(lambda: probe.plan_pub.get_subscription_count() > 0)
    probe.plan_pub.publish(poses_to_path(PLAN))

    def driving() -> bool:
        probe.publish_odom(WORLD.start)
        return any(d.step.source == 'solver' for d in probe.diagnostics)

    assert ros.spin_until(driving, timeout=30.0)
    assert ros.spin_until(lambda: len(probe.local_plans) > 0)
    solved = next(d.step for d in probe.diagnostics if d.step.source == 'solver')
    assert 0.0 <= solved.s <= 1.0
    assert solved.value > 0 and solved.solve_ms > 0 and solved.status
    assert solved.reason is Reason.TRACKING and solved.level is Level.OK
    u_max = Unicycle().u_max
    commands = np.array([u_from_twist(c) for c in probe.cmds])
    assert np.all(np.abs(commands) <= u_max + 1e-9)
    assert np.max(commands[:, 0]) > 0.05  # it drives towards the plan
    prediction = path_to_poses(probe.local_plans[-1])
    assert prediction.shape == (11, 3)
    np.testing.assert_allclose(prediction[0, :2], WORLD.start[:2], atol=1e-6)


def test_controller_applies_a_new_horizon_at_the_next_solve(ros) -> None:
    controller, probe = make_controller(ros, analytic_path='paper_sinusoid')
    result = controller.set_parameters([Parameter('horizon', value=5)])[0]
    assert result.successful, result.reason

    def short_prediction() -> bool:
        probe.publish_odom(WORLD.start)
        return any(len(p.poses) == 6 for p in probe.local_plans)

    assert ros.spin_until(short_prediction, timeout=30.0)
    assert all(len(p.poses) == 6 for p in probe.local_plans)


@pytest.mark.parametrize(('name', 'value', 'reason'), [
    ('solver', 'no_such_solver', 'solver must be one of'),
    ('weights.v', -1.0, ''),  # outside the declared range
    ('world_file', 'no_such_world.yaml', 'not found'),
    ('analytic_path', 'no_such_path', 'unknown analytic path'),
    ('xy_goal_tolerance', -0.1, 'out of range'),  # the declared range
    ('yaw_goal_tolerance', math.nan, 'out of range'),
    ('xy_goal_tolerance', math.inf, 'out of range'),
    ('control_frequency', 0.0, 'out of range'),
    ('control_frequency', -20.0, 'out of range'),
    ('control_frequency', math.nan, 'out of range'),
    ('control_frequency', math.inf, 'out of range'),
    ('max_accel', [2.0], 'max_accel must be [v, omega]'),
    ('max_accel', [2.0, 0.0], 'or [0.0, 0.0] for none'),  # off is both or neither
    ('max_accel', [math.nan, 3.0], 'two finite numbers > 0'),
    ('max_decel', [-2.0, -3.0], 'magnitudes'),  # Nav2's velocity_smoother writes them < 0
    ('max_decel', [math.inf, 3.0], 'max_decel must be [v, omega]'),
    ('max_decel', [2.0, 3.0, 0.0], 'max_decel must be [v, omega]'),
    ('max_accel', [2000.0, 6.0], 'max_accel must be 0, or 0.01 .. 1000 each'),  # its range
    ('max_decel', [2.0, 0.001], 'max_decel must be 0, or 0.01 .. 1000 each'),
    ('input_hold', 'linear', 'input_hold must be one of'),
    ('input_hold', 'first_order', 'needs max_accel'),  # max_accel is off by default
    ('actuation_delay', -0.1, 'out of range'),
])
def test_controller_refuses_invalid_parameters_with_a_reason(ros, name, value, reason) -> None:
    controller, _ = make_controller(ros)
    before = controller.get_parameter(name).value
    result = controller.set_parameters([Parameter(name, value=value)])[0]
    assert not result.successful
    assert reason in result.reason
    assert controller.get_parameter(name).value == before


def test_controller_takes_nav2s_goal_checker_parameters_at_run_time(ros) -> None:
    controller, _ = make_controller(ros)
    settings = controller.controller.settings
    assert (settings.xy_goal_tolerance, settings.yaw_goal_tolerance) == (0.1, 0.15)
    assert settings.stateful is True
    results = controller.set_parameters([Parameter('xy_goal_tolerance', value=0.25),
                                         Parameter('yaw_goal_tolerance', value=0.3),
                                         Parameter('stateful', value=False)])
    assert all(r.successful for r in results), [r.reason for r in results]
    settings = controller.controller.settings
    assert (settings.xy_goal_tolerance, settings.yaw_goal_tolerance) == (0.25, 0.3)
    assert settings.stateful is False


def test_controller_takes_the_first_order_hold_and_its_lead_at_run_time(ros) -> None:
    controller, _ = make_controller(ros)
    assert controller.controller.config.input_hold == 'zero'
    result = controller.set_parameters_atomically([
        Parameter('max_accel', value=[2.0, 6.0]), Parameter('input_hold', value='first_order'),
        Parameter('actuation_delay', value=0.15)])
    assert result.successful, result.reason
    assert controller.controller.config.input_hold == 'first_order'
    assert controller.controller.config.max_accel == (2.0, 6.0)
    assert controller.controller.settings.actuation_delay == 0.15


# ----------------------------------------------------------------------------- planner
def test_controller_takes_its_rate_and_the_bases_limits_at_run_time(ros) -> None:
    controller, _ = make_controller(ros)
    # the defaults: 20 Hz, no limits ([0.0, 0.0] is none: a double array cannot be None)
    assert controller.control_period_ns == 50_000_000
    assert controller.controller.settings.control_frequency == 20.0
    assert controller.controller.settings.max_decel == (math.inf, math.inf)
    assert controller.controller.config.max_accel is None
    results = controller.set_parameters([Parameter('control_frequency', value=10.0),
                                         Parameter('max_accel', value=[2.0, 3.0]),
                                         Parameter('max_decel', value=[1.5, 2.5])])
    assert all(r.successful for r in results), [r.reason for r in results]
    assert controller.control_period_ns == 100_000_000  # the timer was restarted
    assert controller.controller.settings.control_frequency == 10.0
    assert controller.controller.settings.max_decel == (1.5, 2.5)
    assert controller.controller.config.max_accel == (2.0, 3.0)  # the NLPs rebuild
    result = controller.set_parameters([Parameter('step', value=0.1)])[0]
    assert result.successful, result.reason
    assert controller.control_period_ns == 100_000_000  # control_frequency's, not step's
    result = controller.set_parameters([Parameter('max_accel', value=[0.0, 0.0])])[0]
    assert result.successful, result.reason
    assert controller.controller.config.max_accel is None


class StandingClock(SimClock):
    """Simulated time in which the robot stands at a pose: odometry at each tick."""

    pose = PLAN[-1]

    def publish(self) -> None:
        self.probe.publish_odom(self.pose, stamp=self.t)


def test_goal_reached_is_each_control_steps_verdict_also_after_a_new_plan_to_the_same_goal(
        ros) -> None:
    controller, _ = make_controller(ros, use_sim_time=True)
    probe = ros.probe(use_sim_time=True)
    clock = StandingClock(ros, probe)
    assert ros.spin_until(lambda: probe.plan_pub.get_subscription_count() > 0
                          and probe.odom_pub.get_subscription_count() > 0)
    probe.plan_pub.publish(poses_to_path(PLAN))  # the robot stands at its end
    assert clock.run_until(lambda: controller.goal_reached)
    assert controller.last_output.reason is Reason.GOAL_REACHED
    controller.plan_callback(poses_to_path(PLAN))  # a new plan, to the same goal
    assert not controller.goal_reached  # not until a control step says so
    steps = controller.control_steps
    assert clock.run_until(lambda: controller.control_steps > steps)
    assert controller.last_output.reason is Reason.GOAL_REACHED
    assert controller.goal_reached  # the step's verdict, though its log line is unchanged


def test_planner_path_starts_at_odometry_ends_at_goal_and_is_collision_free(ros) -> None:
    goal = [float(v) for v in WORLD.goal]
    planner = started(ros.add(GlobalPlannerNode(context=ros.context, parameter_overrides=[
        Parameter('goal', value=goal), Parameter('world_file', value='paper_obstacle.yaml')])))
    probe = ros.probe()
    start = np.array([0.1, -0.2, 0.3])

    def planned() -> bool:
        probe.publish_odom(start)
        return len(probe.plans) > 0

    assert ros.spin_until(planned, timeout=20.0)
    poses = path_to_poses(probe.plans[-1])
    assert probe.plans[-1].header.frame_id == 'map'
    np.testing.assert_allclose(poses[0], start, atol=1e-9)
    np.testing.assert_allclose(poses[-1], goal, atol=1e-9)
    clearance = planner.get_parameter('clearance').value
    inflated = [o.inflate(0.99 * clearance) for o in WORLD.obstacles]
    for a, b in zip(poses[:-1], poses[1:], strict=True):
        assert not segment_collides(inflated, a, b)

    # RViz's 2D Goal Pose: a re-plan from the current odometry
    new_goal = PoseStamped()
    new_goal.header.frame_id = 'map'
    new_goal.pose.position.x, new_goal.pose.position.y = 2.5, 1.5
    new_goal.pose.orientation = yaw_to_quaternion(1.0)
    probe.goal_pub.publish(new_goal)
    assert ros.spin_until(lambda: len(probe.plans) > 1, timeout=20.0)
    poses = path_to_poses(probe.plans[-1])
    np.testing.assert_allclose(poses[-1], [2.5, 1.5, 1.0], atol=1e-9)
    np.testing.assert_allclose(poses[0], start, atol=1e-9)
    for a, b in zip(poses[:-1], poses[1:], strict=True):
        assert not segment_collides(inflated, a, b)


def test_planner_says_on_its_diagnostics_why_no_plan_comes_and_when_one_does(ros) -> None:
    planner = started(ros.add(GlobalPlannerNode(context=ros.context, parameter_overrides=[
        Parameter('world_file', value='paper_obstacle')])))
    probe = ros.probe()
    assert ros.spin_until(lambda: probe.odom_pub.get_subscription_count() > 0)
    probe.publish_odom(WORLD.start)
    assert ros.spin_until(lambda: planner.robot_pose is not None)
    # outside the box, inside it as the planner inflates it (robot radius + clearance)
    assert planner.set_parameters([Parameter('goal', value=[1.55, 0.0, 0.0])])[0].successful
    assert ros.spin_until(lambda: len(probe.planner_outcomes) == 1)
    failed = probe.planner_outcomes[0]
    assert not failed.planned and failed.level is Level.ERROR
    assert 'no plan to (1.55, 0)' in failed.detail and 'inflated by 0.1 m' in failed.detail
    assert not probe.plans
    assert planner.set_parameters([Parameter('goal', value=[float(v) for v in WORLD.goal])]
                                  )[0].successful
    assert ros.spin_until(lambda: len(probe.planner_outcomes) == 2 and probe.plans)
    planned = probe.planner_outcomes[1]
    assert planned.planned and planned.poses == len(probe.plans[-1].poses) and planned.length > 0


def test_nodes_find_world_files_named_without_a_suffix(ros) -> None:
    controller = started(ros.add(MpcControllerNode(context=ros.context)))
    planner = started(ros.add(GlobalPlannerNode(context=ros.context)))
    for node in (controller, planner):
        result = node.set_parameters([Parameter('world_file', value='rrt_cluttered')])[0]
        assert result.successful, result.reason
    obstacles, footprint = load_robot('rrt_cluttered')
    assert len(obstacles) == 7 and footprint.radius == 0.1


def test_the_candidate_log_line_says_its_input_is_applied() -> None:
    output = ControlOutput(np.array([0.2, -0.5]), None, Reason.CANDIDATE)
    level, line = log_line(output, failures=4, goal_error=(1.0, 0.1))
    assert level is Level.WARN
    assert 'cmd_vel is zero' not in line
    assert line.startswith(Reason.CANDIDATE.text)
    assert 'v = 0.200 m/s, omega = -0.500 rad/s' in line and 'failures so far: 4' in line
    for reason in (Reason.STOP, Reason.STALE_ODOM):
        level, line = log_line(ControlOutput(np.zeros(2), None, reason), failures=4,
                               goal_error=(1.0, 0.1))
        assert level is Level.WARN and 'cmd_vel is zero' in line
    evading = ControlOutput(np.array([-1.5, 0.0]), None, Reason.EVADE,
                            'stopping would meet a moving obstacle in 0.4 s')
    level, line = log_line(evading, failures=4, goal_error=(1.0, 0.1))
    assert level is Level.WARN and 'cmd_vel is zero' not in line
    assert line.startswith(f'{Reason.EVADE.text}: stopping would meet')
    assert 'v = -1.500 m/s, omega = 0.000 rad/s' in line


def test_planner_refuses_a_malformed_goal(ros) -> None:
    planner = started(ros.add(GlobalPlannerNode(context=ros.context)))
    result = planner.set_parameters([Parameter('goal', value=[1.0, 2.0])])[0]
    assert not result.successful
    assert 'goal must be [x, y, theta]' in result.reason


def shipped_params(name: str) -> dict:
    """Return config/<name>.yaml's parameters, groups flattened to dotted names."""
    import yaml

    from mpc_local_planner.worlds.data_files import resolve_data_file

    text = resolve_data_file(f'{name}.yaml').read_text()
    return flat_parameters(yaml.safe_load(text)[name]['ros__parameters'])


def test_shipped_params_files_mirror_the_defaults_the_nodes_take_from_the_dataclasses() -> None:
    from mpc_local_planner.core.planner import PlannerConfig
    from mpc_local_planner.ros.mpc_controller_parameters import DEFAULTS

    controller = shipped_params('mpc_controller')
    assert controller == DEFAULTS  # every parameter, each with its default
    assert MpcConfig().horizon == DEFAULTS['horizon'] and Unicycle().v_max == DEFAULTS['v_max']
    planner = shipped_params('global_planner')
    defaults = PlannerConfig()
    for field in ('iterations', 'time_limit', 'seed', 'range', 'clearance', 'simplify'):
        assert planner[field] == getattr(defaults, field), field
    assert planner['robot_radius'] == FROM_WORLD  # the world file's, as every node's default


def test_robot_radius_is_the_robots_even_smaller_than_the_worlds_and_minus_one_the_worlds(
        ros) -> None:
    world = 'unknown_box'  # robot_radius 0.2
    nodes = {}
    for radius in (0.1, FROM_WORLD):
        given = [Parameter('world_file', value=world), Parameter('robot_radius', value=radius)]
        nodes[radius] = (
            started(ros.add(GlobalPlannerNode(context=ros.context, parameter_overrides=given))),
            started(ros.add(MpcControllerNode(context=ros.context, parameter_overrides=given))),
            ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=given)))
    for radius, expected in ((0.1, 0.1), (FROM_WORLD, 0.2)):
        planner, controller, simulator = nodes[radius]
        assert planner.planner.config.robot_radius == pytest.approx(expected)
        assert controller.controller.config.robot_radius == pytest.approx(expected)
        assert simulator.robot_radius == pytest.approx(expected)
    # between -1 and 0 is no radius and not the marker: refused
    planner, controller, simulator = nodes[0.1]
    for node in (planner, controller, simulator):
        [result] = node.set_parameters([Parameter('robot_radius', value=-0.5)])
        assert not result.successful and 'robot_radius must be -1, or 0 .. 10' in result.reason


@pytest.mark.parametrize(('name', 'module'), [
    ('bag_recorder', 'bag_recorder_node'), ('global_planner', 'global_planner_parameters'),
    ('mpc_controller', 'mpc_controller_parameters'),
    ('unicycle_simulator', 'unicycle_simulator_parameters')])
def test_shipped_params_files_set_only_declared_parameters_with_their_types(
        name: str, module: str) -> None:
    # ROS ignores a key no node declares: a misspelt one would silently do nothing
    from importlib import import_module

    given = shipped_params(name)
    specs = {spec.name: spec for spec in
             import_module(f'mpc_local_planner.ros.{module}').PARAMETERS}
    assert set(given) <= set(specs), f'undeclared: {sorted(set(given) - set(specs))}'
    for key, value in given.items():
        default = specs[key].default
        if isinstance(default, type) or hasattr(default, 'value'):
            continue  # no default (a Parameter.Type): nothing to compare the type with
        assert isinstance(value, type(default)), f'{key}: {value!r} is not a {type(default)}'


@pytest.mark.parametrize(('name', 'node_class'), [
    ('mpc_controller', MpcControllerNode),
    ('global_planner', GlobalPlannerNode),
    ('unicycle_simulator', UnicycleSimulatorNode),
])
def test_shipped_params_files_load_and_hold_the_paper_values(name, node_class) -> None:
    import rclpy
    from rclpy.context import Context

    from mpc_local_planner.worlds.data_files import resolve_data_file

    context = Context()
    rclpy.init(args=['node', '--ros-args', '--params-file',
                     str(resolve_data_file(f'{name}.yaml'))], context=context)
    node = None
    try:
        node = node_class(context=context)
        if name == 'mpc_controller':
            assert node.get_parameter('horizon').value == 10
            assert node.get_parameter('weights.heading').value == 0.1
            assert node.get_parameter('offset_weight').value == 1000.0
        elif name == 'global_planner':
            assert node.get_parameter('iterations').value == 1000
        else:
            np.testing.assert_allclose(node.get_parameter('initial_pose').value, WORLD.start)
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


# ----------------------------------------------------------------------------- safe defaults
def test_no_node_and_no_shipped_params_file_names_a_goal_a_world_or_a_map() -> None:
    # started as docs/nodes.md says, nothing may drive off or plan around a demo's obstacles
    import yaml

    from mpc_local_planner.ros import (
        bag_recorder_node,
        global_planner_parameters,
        map_server_node,
        mpc_controller_parameters,
        unicycle_simulator_parameters,
    )
    from mpc_local_planner.worlds.data_files import resolve_data_file

    tables = {module.__name__: {spec.name: spec.default for spec in module.PARAMETERS}
              for module in (bag_recorder_node, global_planner_parameters, map_server_node,
                             mpc_controller_parameters, unicycle_simulator_parameters)}
    for table, defaults in tables.items():
        assert defaults.get('world_file', '') == '', table
    assert tables[global_planner_parameters.__name__]['goal'] is Parameter.Type.DOUBLE_ARRAY
    assert tables[map_server_node.__name__]['yaml_filename'] is Parameter.Type.STRING
    config = resolve_data_file('mpc_controller.yaml').parent
    files = sorted(config.glob('*.yaml'))
    assert {f.stem for f in files} >= {'global_planner', 'mpc_controller', 'jackal'}
    for path in files:
        for node, section in yaml.safe_load(path.read_text()).items():
            values = section['ros__parameters']
            assert 'goal' not in values, (path.name, node)
            assert values.get('world_file', '') == '', (path.name, node)
            assert 'yaml_filename' not in values, (path.name, node)


def test_a_planner_started_with_the_shipped_file_plans_nothing_until_a_goal_pose_comes(
        ros) -> None:
    from mpc_local_planner.worlds.data_files import resolve_data_file

    shipped = str(resolve_data_file('global_planner.yaml'))
    planner = started(ros.add(GlobalPlannerNode(
        context=ros.context, cli_args=['--ros-args', '--params-file', shipped])))
    probe = ros.probe()
    assert ros.spin_until(lambda: probe.odom_pub.get_subscription_count() > 0
                          and probe.goal_pub.get_subscription_count() > 0)
    start = np.array([0.5, -0.3, 0.4])
    probe.publish_odom(start)
    assert ros.spin_until(lambda: planner.robot_pose is not None)
    # the odometry is in, and a goal in force would have been planned from it at once
    ros.settle()
    assert planner.plan_count == 0 and planner.last_outcome is None and not probe.plans
    # a goal outside the paper world's bounds, behind its box: no world, no bounds, no box
    goal = PoseStamped()
    goal.header.frame_id = 'map'
    goal.pose.position.x, goal.pose.position.y = 4.0, 3.0
    goal.pose.orientation = yaw_to_quaternion(1.0)
    probe.goal_pub.publish(goal)
    assert ros.spin_until(lambda: probe.plans, timeout=20.0)
    poses = path_to_poses(probe.plans[-1])
    np.testing.assert_allclose(poses[0], start, atol=1e-9)
    np.testing.assert_allclose(poses[-1], [4.0, 3.0, 1.0], atol=1e-9)
    # every pose on the straight line from the start to the goal
    direction = np.array([3.5, 3.3]) / np.hypot(3.5, 3.3)
    offsets = poses[:, :2] - start[:2]
    np.testing.assert_allclose(offsets[:, 0] * direction[1] - offsets[:, 1] * direction[0],
                               0.0, atol=1e-9)
