# SPDX-License-Identifier: Apache-2.0
"""unicycle_simulator sees the true world: a laser on ``scan``, contacts on ``simulator/contacts``.

The simulator owns simulated time (publish_clock), so scan stamps and rates are checked in
simulated seconds: deterministic, whatever the machine's load. Contacts are counted with the
robot's true footprint: the ``footprint`` parameter, else the world's, else robot_radius.
"""

from __future__ import annotations

import math
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
from rcl_interfaces.msg import Log
from rclpy.exceptions import ParameterException
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan
from std_msgs.msg import UInt32

from mpc_local_planner.core.footprint import Footprint, JACKAL, parse_footprint
from mpc_local_planner.ros.conversions import stamp_to_seconds, twist_from_u
from mpc_local_planner.ros.qos import CONTACTS_QOS, SCAN_QOS
from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode
from mpc_local_planner.ros.unicycle_simulator_parameters import CONTACTS_TOPIC, SCAN_TOPIC

pytestmark = pytest.mark.dds  # topics over DDS

ROOT = Path(__file__).resolve().parents[2]
NARROW_GAP = ROOT / 'config' / 'worlds' / 'narrow_gap.yaml'  # a 0.6 m gap in a wall at x = 2
# Wall seconds before a condition counts as never reached.
TIMEOUT = 30.0
RATE = 50.0  # simulator ticks per simulated second
# Every scan, in order: the test asserts on consecutive stamps.
RELIABLE_SCANS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.VOLATILE)


def box_world(folder: Path) -> Path:
    """Write a world with one box 2 m ahead of the start (its near face at x = 2)."""
    path = folder / 'one_box.yaml'
    path.write_text('bounds: [-1.0, 5.0, -3.0, 3.0]\n'
                    'obstacles:\n  - box: [2.0, -0.5, 3.0, 0.5]\n'
                    'start: [0.0, 0.0, 0.0]\ngoal: [4.0, 2.0, 0.0]\n')
    return path


def simulator(ros, world: Path, **extra) -> UnicycleSimulatorNode:
    values = {'publish_clock': True, 'real_time_factor': 10.0, 'rate': RATE,
              'world_file': str(world), 'initial_pose': [0.0, 0.0, 0.0], **extra}
    return ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter(name, value=value) for name, value in values.items()]))


def test_the_laser_sees_the_box_ahead_has_inf_elsewhere_and_scans_at_its_rate_in_sim_time(
        ros, tmp_path) -> None:
    fov, beams = math.pi, 361
    sim = simulator(ros, box_world(tmp_path), **{'scan.fov': fov, 'scan.beams': beams,
                                                  'scan.rate': 10.0})
    probe = ros.probe()
    scans: list[LaserScan] = []
    best_effort: list[LaserScan] = []
    probe.create_subscription(LaserScan, SCAN_TOPIC, scans.append, RELIABLE_SCANS)
    # the readers' QoS (best effort) matches the simulator's reliable writer
    probe.create_subscription(LaserScan, SCAN_TOPIC, best_effort.append, SCAN_QOS)
    assert ros.spin_until(lambda: len(scans) >= 12 and best_effort, timeout=TIMEOUT)

    scan = scans[-1]
    assert scan.header.frame_id == 'base_link'
    assert scan.angle_min == pytest.approx(-fov / 2)
    assert scan.angle_increment == pytest.approx(fov / (beams - 1))
    assert scan.angle_max == pytest.approx(fov / 2)
    assert len(scan.ranges) == beams
    assert scan.range_min == pytest.approx(0.05) and scan.range_max == pytest.approx(10.0)
    ranges = np.array(scan.ranges)
    # the middle beam looks straight ahead at the box's near face, 2 m away (the robot
    # stands still: no cmd_vel)
    assert ranges[beams // 2] == pytest.approx(2.0, abs=1e-5)
    assert np.all(np.isinf(ranges[:beams // 4]))  # to the right: nothing, inf (REP 117)
    assert np.all(np.isinf(ranges[-beams // 4:]))  # to the left: nothing
    assert np.all(ranges[np.isfinite(ranges)] >= 2.0 - 1e-5)

    # ten scans per simulated second, stamped on the simulator's ticks
    stamps = np.array([stamp_to_seconds(s.header.stamp) for s in scans])
    np.testing.assert_allclose(np.diff(stamps), 0.1, atol=1e-6)
    ticks = stamps * RATE
    np.testing.assert_allclose(ticks, np.round(ticks), atol=1e-6)
    assert stamps[-1] <= sim.sim_time + 1e-9


def test_driving_into_a_box_counts_one_contact_episode_and_logs_one_error(
        ros, tmp_path) -> None:
    sim = simulator(ros, box_world(tmp_path), robot_radius=0.2, cmd_timeout=0.0)
    probe = ros.probe()
    counts: list[int] = []
    probe.create_subscription(UInt32, CONTACTS_TOPIC, lambda m: counts.append(m.data),
                              CONTACTS_QOS)
    # latched: the count at start is 0
    assert ros.spin_until(lambda: counts == [0], timeout=TIMEOUT)
    assert sim.contacts == 0 and sim.robot_radius == 0.2

    def drive_to(x: float) -> bool:
        probe.cmd_pub.publish(twist_from_u([0.3, 0.0]))
        return sim.state[0] >= x

    # through the box (x from 2 to 3) and out the other side: touching all along, so one
    # episode
    assert ros.spin_until(lambda: drive_to(3.3), timeout=TIMEOUT)
    probe.cmd_pub.publish(twist_from_u([0.0, 0.0]))
    assert ros.spin_until(lambda: counts[-1:] == [1]
                          and probe.log_lines('unicycle_simulator', Log.ERROR),
                          timeout=TIMEOUT)
    t = sim.sim_time
    assert ros.spin_until(lambda: sim.sim_time > t + 0.5, timeout=TIMEOUT)
    assert sim.contacts == 1 and counts == [0, 1]
    [error] = probe.log_lines('unicycle_simulator', Log.ERROR)
    assert 'contact' in error and 'radius 0.2 m' in error


def test_robot_radius_replaces_the_worlds_even_smaller_and_minus_one_takes_it(
        ros, tmp_path) -> None:
    world = tmp_path / 'radius.yaml'
    world.write_text(box_world(tmp_path).read_text() + 'robot_radius: 0.3\n')
    assert simulator(ros, world, robot_radius=0.1).robot_radius == 0.1
    assert simulator(ros, world).robot_radius == 0.3  # the default, -1: the world's


# 0.64 m wide: wider than the gap, where the Jackal (0.43 m) fits
WIDE = '[[0.3, 0.32], [-0.3, 0.32], [-0.3, -0.32], [0.3, -0.32]]'


@pytest.mark.parametrize(('footprint', 'expected'), [('', 0), (WIDE, 1)],
                         ids=['world Jackal', 'wide parameter'])
def test_contacts_through_the_narrow_gap_are_counted_with_the_true_footprint(
        ros, footprint: str, expected: int) -> None:
    # robot_radius as closed_loop sets it (the world's covering radius): that circle would
    # touch the gap's sides, but a polygon footprint takes precedence
    sim = simulator(ros, NARROW_GAP, cmd_timeout=0.0, footprint=footprint,
                    robot_radius=JACKAL.radius, initial_pose=[1.2, 0.0, 0.0])
    probe = ros.probe()
    counts: list[int] = []
    probe.create_subscription(UInt32, CONTACTS_TOPIC, lambda m: counts.append(m.data),
                              CONTACTS_QOS)
    polygon = parse_footprint(footprint).vertices if footprint else JACKAL.vertices
    np.testing.assert_allclose(sim.footprint.vertices, polygon)
    assert ros.spin_until(lambda: counts == [0], timeout=TIMEOUT)

    def drive_to(x: float) -> bool:
        probe.cmd_pub.publish(twist_from_u([0.3, 0.0]))
        return sim.state[0] >= x

    # straight through the gap (the wall spans x from 1.9 to 2.1) and out the other side
    assert ros.spin_until(lambda: drive_to(2.8), timeout=TIMEOUT)
    probe.cmd_pub.publish(twist_from_u([0.0, 0.0]))
    assert ros.spin_until(lambda: counts[-1:] == [expected], timeout=TIMEOUT)
    t = sim.sim_time
    assert ros.spin_until(lambda: sim.sim_time > t + 0.5, timeout=TIMEOUT)
    assert sim.contacts == expected and counts == list(range(expected + 1))
    assert sim.state[1] == 0.0 and sim.state[2] == 0.0  # it really drove straight
    # /rosout is a topic of its own: wait for its lines, then count them
    assert ros.spin_until(lambda: len(probe.log_lines('unicycle_simulator', Log.ERROR))
                          >= expected, timeout=TIMEOUT)
    errors = probe.log_lines('unicycle_simulator', Log.ERROR)
    assert len(errors) == expected
    if expected:
        assert 'contact' in errors[0] and 'footprint [[0.3, 0.32]' in errors[0]


def test_footprint_precedence_parameter_then_world_then_robot_radius(ros, tmp_path) -> None:
    box = box_world(tmp_path)
    parameter = simulator(ros, NARROW_GAP, footprint=WIDE, robot_radius=0.5)
    np.testing.assert_allclose(parameter.footprint.vertices, parse_footprint(WIDE).vertices)
    world = simulator(ros, NARROW_GAP, footprint='[]', robot_radius=0.5)
    np.testing.assert_allclose(world.footprint.vertices, JACKAL.vertices)
    assert world.robot_radius == JACKAL.radius
    radius = simulator(ros, box, robot_radius=0.25)
    assert radius.footprint == Footprint.circle(0.25) and radius.robot_radius == 0.25
    polygon_in_a_world_without_one = simulator(ros, box, footprint=str(JACKAL.vertices.tolist()))
    np.testing.assert_allclose(polygon_in_a_world_without_one.footprint.vertices,
                               JACKAL.vertices)

    # at run time: a valid footprint replaces the polygon, '' falls back to the world's
    [result] = parameter.set_parameters([Parameter('footprint', value='[[0.1, 0.1], [-0.1, '
                                                   '0.1], [0.0, -0.1]]')])
    assert result.successful and len(parameter.footprint.vertices) == 3
    [result] = parameter.set_parameters([Parameter('footprint', value='')])
    assert result.successful
    np.testing.assert_allclose(parameter.footprint.vertices, JACKAL.vertices)
    [result] = radius.set_parameters([Parameter('robot_radius', value=0.35)])
    assert result.successful and radius.footprint == Footprint.circle(0.35)


BAD_FOOTPRINTS = ['[[0.2, 0.1], [-0.2, 0.1]]', '[[0.2, 0.1], [0, 0], [-0.2, 0.1], [0, -0.3]]',
                  '[[0.2, 0.1], [-0.2, 0.1]', 'wide']


@pytest.mark.parametrize('value', BAD_FOOTPRINTS,
                         ids=['two vertices', 'not convex', 'unclosed', 'a word'])
def test_bad_footprints_are_refused_at_start_and_at_run_time(ros, value: str) -> None:
    with pytest.raises(ParameterException, match='footprint'):
        UnicycleSimulatorNode(context=ros.context,
                              parameter_overrides=[Parameter('footprint', value=value)])
    sim = ros.add(UnicycleSimulatorNode(context=ros.context))
    [result] = sim.set_parameters([Parameter('footprint', value=value)])
    assert not result.successful and 'footprint' in result.reason
    assert sim.get_parameter('footprint').value == '' and sim.footprint == Footprint.circle(0.0)


BAD_SCAN_PARAMETERS = [('scan.beams', 0), ('scan.beams', -5), ('scan.fov', 0.0),
                       ('scan.fov', 2 * math.pi + 0.01), ('scan.range_max', 0.0),
                       ('scan.range_max', -1.0), ('scan.noise_std', -0.1)]


@pytest.mark.parametrize(('name', 'value'), BAD_SCAN_PARAMETERS,
                         ids=[f'{n}={v:g}' for n, v in BAD_SCAN_PARAMETERS])
def test_bad_scan_parameters_are_refused_at_start_and_at_run_time(ros, name, value) -> None:
    with pytest.raises(ParameterException, match=name):
        UnicycleSimulatorNode(context=ros.context,
                              parameter_overrides=[Parameter(name, value=value)])
    sim = ros.add(UnicycleSimulatorNode(context=ros.context))
    [result] = sim.set_parameters([Parameter(name, value=value)])
    assert not result.successful and name in result.reason
    # the laser still works with the old value
    assert sim.get_parameter(name).value != value


def test_a_bad_scan_parameter_on_the_command_line_exits_2_with_one_line() -> None:
    command = [sys.executable, '-m', 'mpc_local_planner.ros.unicycle_simulator_node',
               '--ros-args', '-p', 'scan.beams:=0']
    result = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 2, result.stderr
    assert result.stderr.count('\n') == 1, result.stderr
    assert result.stderr.startswith('unicycle_simulator: refusing to start: ')
    # the range is the descriptor's, which rclpy enforces (docs/parameters.md shows it)
    assert 'scan.beams out of range. Min: 2, Max: 10000' in result.stderr
