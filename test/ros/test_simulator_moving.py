# SPDX-License-Identifier: Apache-2.0
"""unicycle_simulator moves the world's moving obstacles in simulated time.

Its laser sees them where they are at the scan's stamp, RViz gets them on
``simulator/moving_obstacles``, and a contact is counted as active (the robot moving) or
passive (it stood still and an obstacle ran into it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan
from std_msgs.msg import UInt32
from visualization_msgs.msg import Marker, MarkerArray

from mpc_local_planner.ros.conversions import stamp_to_seconds, twist_from_u
from mpc_local_planner.ros.qos import CONTACTS_QOS
from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode
from mpc_local_planner.ros.unicycle_simulator_parameters import (
    ACTIVE_CONTACTS_TOPIC,
    CONTACTS_TOPIC,
    MOVING_OBSTACLES_TOPIC,
    PASSIVE_CONTACTS_TOPIC,
    SCAN_TOPIC,
)
from mpc_local_planner.worlds.world import load_world

pytestmark = pytest.mark.dds  # topics over DDS

TIMEOUT = 30.0
RATE = 50.0
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
RADIUS = 0.3


def walker_world(folder: Path, trajectory: str) -> Path:
    """Write a world with one disk of RADIUS on the given trajectory (a YAML flow mapping)."""
    path = folder / 'walker.yaml'
    path.write_text('bounds: [-3.0, 6.0, -3.0, 3.0]\n'
                    'obstacles:\n  - box: [5.0, 2.0, 6.0, 3.0]\n'
                    'moving_obstacles:\n'
                    f'  - circle: [0.0, 0.0, {RADIUS}]\n'
                    f'    {trajectory}\n'
                    'start: [0.0, 0.0, 0.0]\ngoal: [4.0, 2.0, 0.0]\n')
    return path


def simulator(ros, world: Path, **extra) -> UnicycleSimulatorNode:
    values = {'publish_clock': True, 'real_time_factor': 10.0, 'rate': RATE,
              'world_file': str(world), 'initial_pose': [0.0, 0.0, 0.0],
              'robot_radius': 0.2, 'cmd_timeout': 0.0, **extra}
    return ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter(name, value=value) for name, value in values.items()]))


def test_the_scan_at_a_simulated_time_sees_the_walker_where_it_is_then(ros, tmp_path) -> None:
    # the walker goes back and forth on the laser's forward axis, from x = 2 to x = 4
    world = walker_world(tmp_path, 'waypoints: {points: [[2.0, 0.0], [4.0, 0.0]], speed: 1.0, '
                                   'mode: back_and_forth}')
    walker = load_world(world).moving_obstacles[0]
    beams = 361
    simulator(ros, world, **{'scan.fov': np.pi, 'scan.beams': beams, 'scan.rate': 10.0})
    probe = ros.probe()
    scans: list[LaserScan] = []
    markers: list[MarkerArray] = []
    probe.create_subscription(LaserScan, SCAN_TOPIC, scans.append, RELIABLE)
    probe.create_subscription(MarkerArray, MOVING_OBSTACLES_TOPIC, markers.append, RELIABLE)
    assert ros.spin_until(lambda: len(scans) >= 25 and len(markers) >= 25, timeout=TIMEOUT)

    ahead = beams // 2
    seen = []
    for scan in scans:
        t = stamp_to_seconds(scan.header.stamp)
        expected = walker.position(t)[0] - RADIUS
        assert scan.ranges[ahead] == pytest.approx(expected, abs=1e-5), t
        seen.append(scan.ranges[ahead])
    assert max(seen) - min(seen) > 1.0  # it did move, as far as the scans went
    for array in markers:
        [marker] = array.markers
        t = stamp_to_seconds(marker.header.stamp)
        assert marker.type == Marker.CYLINDER and marker.header.frame_id == 'map'
        assert marker.scale.x == pytest.approx(2 * RADIUS)
        assert [marker.pose.position.x, marker.pose.position.y] == pytest.approx(
            walker.position(t).tolist())


def counts(probe, topic: str) -> list[int]:
    received: list[int] = []
    probe.create_subscription(UInt32, topic, lambda m: received.append(m.data), CONTACTS_QOS)
    return received


def test_a_stopped_robot_hit_by_a_walker_counts_a_passive_contact(ros, tmp_path) -> None:
    # across the robot's position: touching from t = 1.5 (2 - 0.5 m at 1 m/s)
    world = walker_world(tmp_path, 'waypoints: {points: [[0.0, -2.0], [0.0, 2.0]], '
                                   'speed: 1.0, mode: back_and_forth}')
    sim = simulator(ros, world)
    probe = ros.probe()
    total, active, passive = (counts(probe, topic) for topic in
                              (CONTACTS_TOPIC, ACTIVE_CONTACTS_TOPIC, PASSIVE_CONTACTS_TOPIC))
    assert ros.spin_until(lambda: passive[-1:] == [1], timeout=TIMEOUT)
    assert 1.4 < sim.sim_time < 2.0
    assert ros.spin_until(lambda: total[-1:] == [1] and active == [0], timeout=TIMEOUT)
    assert (sim.contacts, sim.active_contacts, sim.passive_contacts) == (1, 0, 1)


def test_a_robot_driving_into_an_obstacle_counts_an_active_contact(ros, tmp_path) -> None:
    # the walker stays far away (its swing is behind the robot); the robot drives into the box
    world = walker_world(tmp_path, 'sinusoid: {centre: [-2.0, -2.0], amplitude: [0.5, 0.0], '
                                   'period: 4.0}')
    sim = simulator(ros, world, initial_pose=[4.0, 1.0, 0.7853981633974483])
    probe = ros.probe()
    total, active, passive = (counts(probe, topic) for topic in
                              (CONTACTS_TOPIC, ACTIVE_CONTACTS_TOPIC, PASSIVE_CONTACTS_TOPIC))

    def drive() -> bool:
        probe.cmd_pub.publish(twist_from_u([0.3, 0.0]))
        return active[-1:] == [1]

    assert ros.spin_until(drive, timeout=TIMEOUT)
    probe.cmd_pub.publish(twist_from_u([0.0, 0.0]))
    assert ros.spin_until(lambda: total[-1:] == [1] and passive == [0], timeout=TIMEOUT)
    assert (sim.contacts, sim.active_contacts, sim.passive_contacts) == (1, 1, 0)


def test_on_the_mujoco_plant_the_engines_laser_sees_the_walker_where_it_is(ros,
                                                                          tmp_path) -> None:
    pytest.importorskip('mujoco', reason='the [physics] extra is not installed')
    world = walker_world(tmp_path, 'waypoints: {points: [[2.0, 0.0], [4.0, 0.0]], speed: 1.0, '
                                   'mode: back_and_forth}')
    walker = load_world(world).moving_obstacles[0]
    beams = 361
    simulator(ros, world, plant='mujoco', **{'scan.fov': np.pi, 'scan.beams': beams,
                                             'scan.rate': 10.0})
    probe = ros.probe()
    scans: list[LaserScan] = []
    probe.create_subscription(LaserScan, SCAN_TOPIC, scans.append, RELIABLE)
    assert ros.spin_until(lambda: len(scans) >= 15, timeout=TIMEOUT)
    for scan in scans:
        t = stamp_to_seconds(scan.header.stamp)
        # the robot's body settles on its wheels (mm): the walker's range to 1 cm
        assert scan.ranges[beams // 2] == pytest.approx(walker.position(t)[0] - RADIUS,
                                                        abs=0.01), t
