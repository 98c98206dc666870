# SPDX-License-Identifier: Apache-2.0
"""The MuJoCo plant behaves like a robot: limits, skid-steer, odometry, walls, its laser.

And it is what the suites (run_navigation, evaluate --plant), the simulator node (plant:
mujoco) and closed_loop (--plant) run when asked.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from rclpy.exceptions import ParameterException
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan

from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.evaluation import evaluate
from mpc_local_planner.evaluation import sensing_suites as suites
from mpc_local_planner.evaluation.rollout import Outcome
from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.ros import unicycle_simulator_parameters
from mpc_local_planner.ros.closed_loop_parameters import localized, LoopOptions, node_parameters
from mpc_local_planner.ros.conversions import twist_from_u
from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode
from mpc_local_planner.sim import step_response
from mpc_local_planner.sim.contact import footprint_distances
from mpc_local_planner.sim.laser import SimulatedLaser
from mpc_local_planner.sim.physics.drive import DiffDrive, WheelOdometry
from mpc_local_planner.sim.physics.robots import JACKAL_ROBOT
from mpc_local_planner.sim.reality import Reality
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import Circle, load_world

mujoco = pytest.importorskip('mujoco', reason='the [physics] extra is not installed')

from mpc_local_planner.sim.physics.laser import PhysicsLaser  # noqa: E402 (needs mujoco)
from mpc_local_planner.sim.physics.plant import PhysicsBase  # noqa: E402 (needs mujoco)

JACKAL_MODEL = Unicycle(v_max=2.0, omega_max=4.0)
PERIOD = 0.05  # a controller's 20 Hz


def jackal(shapes: tuple = (), pose: tuple = (0.0, 0.0, 0.0),
           reality: Reality | None = None, odometry: str = 'fused') -> PhysicsBase:
    return PhysicsBase(JACKAL_MODEL, reality or Reality(), pose, robot='jackal',
                       footprint=JACKAL, shapes=shapes, odometry=odometry)


def drive(base: PhysicsBase, u: tuple[float, float], seconds: float) -> list[np.ndarray]:
    """Send u at 20 Hz for seconds; return the body's velocity after each period."""
    velocities = []
    for _ in range(int(round(seconds / PERIOD))):
        base.command(u, base.time)
        base.advance(base.time + PERIOD)
        velocities.append(base.velocity)
    return velocities


def test_the_jackal_reaches_the_commanded_speed_within_its_limits() -> None:
    base = jackal()
    velocities = np.array(drive(base, (2.0, 0.0), 2.0))
    speeds = velocities[:, 0]
    # not at once: the base controller and the floor's friction limit the acceleration
    assert speeds[0] < 0.5
    assert np.all(np.diff(speeds) <= 20.0 * PERIOD + 1e-6)  # the controller's 20 m/s^2
    assert abs(speeds[-1] - 2.0) < 0.02
    assert np.max(speeds) <= 2.0 * 1.02
    assert base.pose[0] > 3.0 and abs(base.pose[1]) < 0.1


def test_the_jackal_turns_in_place_and_its_wheel_odometry_drifts_where_the_fused_does_not(
) -> None:
    wheels, fused = jackal(odometry='wheels'), jackal(odometry='fused')
    velocities = np.array(drive(wheels, (0.0, 4.0), 3.0))
    drive(fused, (0.0, 4.0), 3.0)
    for base in (wheels, fused):  # stopped: odometry (updated at 50 Hz) has caught up
        drive(base, (0.0, 0.0), 1.0)
    # it turns: the body's yaw rate is near the command, it stays where it was
    assert 3.0 < np.mean(velocities[-20:, 1]) < 4.2
    assert np.hypot(*wheels.pose[:2]) < 0.2
    # the four wheels scrub: odometry (the wheels' angles) and the truth part
    turned_true = wheels.pose[2]
    assert turned_true > 8.0
    assert abs(wheels.odom_pose[2] - turned_true) > 0.2
    # the gyro's heading is off by its bias only (at most 4 sigma over the 4 s)
    assert fused.pose[2] == pytest.approx(turned_true)  # the same motion: odometry is apart
    assert abs(fused.odom_pose[2] - turned_true) < 4 * JACKAL_ROBOT.gyro_bias * 4.0


def test_an_unknown_odometry_source_is_refused_with_the_choices() -> None:
    with pytest.raises(ValueError, match='fused, wheels'):
        jackal(odometry='gps')


def test_a_wall_stops_the_robot_where_its_bumper_touches() -> None:
    wall = ConvexPolygon.from_box(1.0, -2.0, 1.5, 2.0)
    base = jackal(shapes=(wall,))
    drive(base, (1.0, 0.0), 3.0)
    front = JACKAL.vertices[:, 0].max()
    # the engine's contact holds it at the wall: its front at x = 1.0 (a few mm inside)
    assert base.pose[0] + front == pytest.approx(1.0, abs=0.01)
    assert abs(base.velocity[0]) < 0.05
    gap = footprint_distances(TrueGeometry([wall]), JACKAL, base.pose[None, :])[0]
    assert -0.01 < gap <= 0.001


def test_a_non_finite_command_stops_the_robot() -> None:
    base = jackal()
    drive(base, (1.0, 0.0), 1.0)
    assert base.velocity[0] > 0.9
    drive(base, (math.nan, 0.0), 1.0)
    assert abs(base.velocity[0]) < 0.01
    assert np.all(base.target == 0.0)


def test_silence_beyond_the_base_controllers_timeout_brakes_the_robot() -> None:
    base = jackal()
    drive(base, (1.0, 0.0), 1.0)
    base.advance(base.time + JACKAL_ROBOT.drive.cmd_vel_timeout - 0.05)
    assert base.velocity[0] > 0.9  # within the timeout the command holds
    base.advance(base.time + 1.0)
    assert abs(base.velocity[0]) < 0.01


def test_command_latency_of_the_reality_delays_the_start() -> None:
    base = jackal(reality=Reality(latency=0.3))
    base.command((1.0, 0.0), 0.0)
    base.advance(0.28)
    assert base.pose[0] == pytest.approx(0.0, abs=1e-4)
    assert np.all(base.target == 0.0)
    base.advance(0.5)
    assert base.pose[0] > 0.01 and base.target[0] == 1.0


def test_the_engines_laser_sees_a_cylinder_at_the_range_the_exact_laser_gives() -> None:
    shapes = (Circle(3.0, 0.5, 0.3), ConvexPolygon.from_box(-2.0, -1.0, -1.5, 1.0))
    base = jackal(shapes=shapes)
    laser = base.laser(fov=2.0 * math.pi, beams=361, range_min=0.05, range_max=10.0)
    exact = SimulatedLaser(shapes, fov=2.0 * math.pi, beams=361, range_min=0.05,
                           range_max=10.0)
    pose = base.pose
    scan, reference = laser.scan(pose, stamp=1.5), exact.scan(pose, stamp=1.5)
    assert scan.stamp == 1.5 and scan.angle_min == reference.angle_min
    assert scan.angle_increment == reference.angle_increment
    hit = np.isfinite(reference.ranges)
    # the same beams return (REP 117: inf for the others), at the same range; the
    # robot's own body and the floor are not seen
    assert np.array_equal(np.isfinite(scan.ranges), hit)
    assert np.max(np.abs(scan.ranges[hit] - reference.ranges[hit])) < 1e-6
    ahead = int(np.argmin(np.abs(laser.angles() - math.atan2(0.5, 3.0))))
    assert scan.ranges[ahead] == pytest.approx(math.hypot(3.0, 0.5) - 0.3, abs=0.01)


def test_diff_drive_limits_the_command_and_times_it_out() -> None:
    drive_ = DiffDrive(JACKAL_ROBOT.drive)
    drive_.receive(np.array([5.0, 0.0]), 0.0)
    left, right = drive_.update(0.0, 0.02)
    # 20 m/s^2 over 0.02 s: 0.4 m/s, on both sides
    assert left == right == pytest.approx(0.4 / JACKAL_ROBOT.drive.wheel_radius)
    for k in range(1, 6):
        drive_.update(0.02 * k, 0.02)
    assert drive_.limited[0] == 2.0  # max_velocity, within the timeout
    drive_.update(0.26, 0.02)
    assert drive_.limited[0] == pytest.approx(2.0 - 0.4)  # timed out: braking at the limit


def test_wheel_odometry_integrates_an_arc_from_the_wheel_angles() -> None:
    limits = JACKAL_ROBOT.drive
    odometry = WheelOdometry(limits, np.zeros(3))
    v, omega, period = 1.0, 1.0, 0.02
    left_rate = (v - omega * limits.wheel_separation / 2) / limits.wheel_radius
    right_rate = (v + omega * limits.wheel_separation / 2) / limits.wheel_radius
    for k in range(51):
        odometry.update(left_rate * period * k, right_rate * period * k, period)
    # 1 s on the arc of radius 1: exact integration
    assert odometry.pose == pytest.approx([math.sin(1.0), 1.0 - math.cos(1.0), 1.0], abs=1e-9)
    assert odometry.twist == pytest.approx([v, omega])


def test_the_small_robot_drives_straight_at_its_speed() -> None:
    base = PhysicsBase(Unicycle(), Reality(), (1.0, 2.0, 0.5), robot='small',
                       footprint=Footprint.circle(0.2))
    velocities = np.array(drive(base, (0.31, 0.0), 2.0))
    assert abs(velocities[-1, 0] - 0.31) < 0.015
    heading = base.pose[2]
    assert heading == pytest.approx(0.5, abs=0.02)
    travelled = np.hypot(base.pose[0] - 1.0, base.pose[1] - 2.0)
    assert 0.5 < travelled < 0.62
    assert np.hypot(*(base.odom_pose[:2] - base.pose[:2])) < 0.03


def test_run_navigation_drives_the_physics_robot_with_the_engines_laser() -> None:
    world = load_world(resolve_data_file('unknown_box.yaml'))
    result = suites.run_navigation(world, 'pure_pursuit', suites.ROBOTS['circle'],
                                   prepare=False, plant='mujoco')
    navigator = result.navigator
    assert isinstance(navigator.base, PhysicsBase) and navigator.base.robot.name == 'small'
    assert isinstance(navigator.laser, PhysicsLaser)
    # the laser showed the unknown box: the planner went around it, without touching it
    assert navigator.log.replans >= 1
    assert result.run.outcome is Outcome.REACHED and result.contacts == 0


def test_an_unknown_plant_is_refused_with_the_known_ones() -> None:
    world = load_world(resolve_data_file('unknown_box.yaml'))
    with pytest.raises(ValueError, match='kinematic, mujoco'):
        suites.run_navigation(world, 'pure_pursuit', suites.ROBOTS['circle'],
                              prepare=False, plant='gazebo')


def test_evaluate_takes_the_plant_for_the_navigation_suites_only(tmp_path) -> None:
    with pytest.raises(SystemExit):
        evaluate.main(['--suite', 'random', '--plant', 'mujoco', '--out', str(tmp_path)])
    with pytest.raises(SystemExit):
        evaluate.main(['--suite', 'unknown', '--plant', 'bullet', '--out', str(tmp_path)])
    assert evaluate.main(['--suite', 'unknown', '--count', '1', '--plant', 'mujoco',
                          '--controllers', 'pure_pursuit', '--out', str(tmp_path)]) == 0
    summary = (tmp_path / 'summary.md').read_text(encoding='utf-8')
    assert 'mujoco plant' in summary


@pytest.mark.dds
def test_the_simulator_node_on_the_mujoco_plant_publishes_odometry_and_scans(ros) -> None:
    world = resolve_data_file('unknown_box.yaml')
    sim = ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter('plant', value='mujoco'), Parameter('physics.robot', value='jackal'),
        Parameter('world_file', value=str(world)), Parameter('v_max', value=2.0),
        Parameter('publish_clock', value=True), Parameter('real_time_factor', value=10.0)]))
    assert isinstance(sim._base, PhysicsBase) and isinstance(sim._laser, PhysicsLaser)
    probe = ros.probe()
    scans: list[LaserScan] = []
    probe.create_subscription(LaserScan, 'scan', scans.append, qos_profile_sensor_data)
    assert ros.spin_until(lambda: probe.cmd_pub.get_subscription_count() > 0, timeout=20.0)

    def moved() -> bool:
        probe.cmd_pub.publish(twist_from_u([1.0, 0.0]))
        return bool(probe.odoms) and probe.odoms[-1].pose.pose.position.x > 0.5

    assert ros.spin_until(moved, timeout=20.0)
    # the wheels' odometry and the body agree on a straight run, within the wheels' slip
    assert sim.state[0] == pytest.approx(probe.odoms[-1].pose.pose.position.x, abs=0.15)
    assert probe.odoms[-1].twist.twist.linear.x > 0.5
    # the engine's laser sees the unknown box ahead (REP 117: inf where nothing is hit)
    assert ros.spin_until(lambda: len(scans) >= 2, timeout=20.0)
    ranges = np.array(scans[-1].ranges)
    assert np.any(np.isfinite(ranges)) and np.any(np.isinf(ranges))


def test_the_simulator_refuses_an_unknown_plant_and_mujoco_when_it_is_missing(
        ros, monkeypatch) -> None:
    reason = unicycle_simulator_parameters.validate_simulator_parameters({'plant': 'gazebo'})
    assert reason is not None and 'kinematic|mujoco' in reason
    reason = unicycle_simulator_parameters.validate_simulator_parameters(
        {'physics.robot': 'husky'})
    assert reason is not None and 'jackal|small' in reason
    monkeypatch.setattr(unicycle_simulator_parameters, 'mujoco_missing',
                        lambda: 'MuJoCo is not installed: pip install ...[physics]')
    with pytest.raises(ParameterException, match='MuJoCo is not installed'):
        UnicycleSimulatorNode(context=ros.context,
                              parameter_overrides=[Parameter('plant', value='mujoco')])


def test_closed_loop_passes_the_plant_to_the_simulator_and_runs_localized() -> None:
    world_file = resolve_data_file('unknown_box.yaml')
    world = load_world(world_file)
    options = LoopOptions(path='rrt', plant='mujoco')
    params = node_parameters(options, world_file, world)['unicycle_simulator']
    assert params['plant'] == 'mujoco' and params['physics.robot'] == 'small'
    # odometry from the wheels is not the pose in map: a localizer says where the robot is
    assert localized(options) and params['odom_frame'] == 'odom'
    plain = node_parameters(LoopOptions(path='rrt'), world_file, world)['unicycle_simulator']
    assert plain['plant'] == 'kinematic' and not localized(LoopOptions())


def test_step_response_prints_what_its_docstring_table_says(capsys, monkeypatch) -> None:
    assert step_response.main(['--robot', 'jackal']) == 0
    printed = capsys.readouterr().out
    assert '90 % of v_max after 0.375 s' in printed and '3.738 rad/s held' in printed
    lines = step_response.__doc__.splitlines()
    at = [i for i, line in enumerate(lines) if line.startswith('jackal ')][0]
    jackal_row, fused_row = lines[at], lines[at + 1]
    result = step_response.measure('jackal')
    assert f'{result.t90_linear:.3f} s' in jackal_row
    assert f'{result.omega_held:.2f} of 4.0' in jackal_row
    assert f'{math.degrees(result.turn_heading_error):.1f} d' in jackal_row
    assert fused_row.startswith('(fused)')
    assert f'{100 * result.fused_arc_position_error:.1f} cm' in fused_row
    # without MuJoCo: the reason, no traceback
    monkeypatch.setattr(step_response, 'mujoco_missing', lambda: 'MuJoCo is not installed')
    assert step_response.main(['--robot', 'small']) == 2
    assert 'MuJoCo is not installed' in capsys.readouterr().err
