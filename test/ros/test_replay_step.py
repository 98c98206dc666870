# SPDX-License-Identifier: Apache-2.0
"""replay_step: a recorded step's state rebuilt from the bag, and the controller run on it."""

from __future__ import annotations

import math
from pathlib import Path

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores
from sensor_msgs.msg import LaserScan

from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.ros.replay_step import main, parameter_values, read_recording, replay
from mpc_local_planner.worlds.data_files import resolve_data_file

PARAMS = [str(resolve_data_file('mpc_controller.yaml')), str(resolve_data_file('jackal.yaml'))]
WALL_X = 2.0  # m: a wall across +x
SPEED = 0.5  # m/s along +x: the scans must be placed with the pose at their stamp
SCANS_UNTIL = 0.5  # s: the laser's last scan (then the robot drives on, blind)
STEP_TIME = 1.0  # the recorded step's state time


def stamp(t: float) -> Time:
    nanoseconds = int(round(t * 1e9))
    return Time(sec=nanoseconds // 10**9, nanosec=nanoseconds % 10**9)


def wall_scan(t: float) -> LaserScan:
    """A scan of the wall at WALL_X from the robot at x = SPEED t."""
    scan = LaserScan()
    scan.header.stamp, scan.header.frame_id = stamp(t), 'base_link'
    scan.angle_min, scan.angle_max, scan.angle_increment = -1.0, 1.0, 0.01
    scan.range_min, scan.range_max = 0.05, 10.0
    angles = scan.angle_min + scan.angle_increment * np.arange(201)
    scan.ranges = ((WALL_X - SPEED * t) / np.cos(angles)).astype(np.float32).tolist()
    return scan


def write_run(bag: Path, *, message: str = 'no feasible input, stopping') -> None:
    """A run along +x towards a wall: odometry at 20 Hz, scans at 10 Hz, a plan, one step."""
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        topics = {name: writer.add_connection(name, kind, typestore=typestore) for name, kind in (
            ('/odom', 'nav_msgs/msg/Odometry'), ('/scan', 'sensor_msgs/msg/LaserScan'),
            ('/plan', 'nav_msgs/msg/Path'),
            ('/mpc/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray'))}
        plan = PathMsg()
        for x in (0.0, 3.0):
            pose = PoseStamped()
            pose.pose.position.x, pose.pose.orientation.w = x, 1.0
            plan.poses.append(pose)
        writer.write(topics['/plan'], 0, serialize_message(plan))
        for k in range(21):
            t = 0.05 * k
            odom = Odometry()
            odom.header.stamp = stamp(t)
            odom.pose.pose.position.x, odom.pose.pose.orientation.w = SPEED * t, 1.0
            odom.twist.twist.linear.x = SPEED
            writer.write(topics['/odom'], int(round(t * 1e9)) + 1, serialize_message(odom))
            if k % 2 == 1 and t <= SCANS_UNTIL:
                writer.write(topics['/scan'], int(round(t * 1e9)) + 2,
                             serialize_message(wall_scan(t)))
        values = {'state_time': STEP_TIME, 'x': SPEED * STEP_TIME, 'y': 0.0, 'theta': 0.0,
                  'v': 0.0, 'omega': 0.0, 'status': 'Infeasible_Problem_Detected'}
        array = DiagnosticArray()
        array.header.stamp = stamp(STEP_TIME)
        array.status = [DiagnosticStatus(message=message, values=[
            KeyValue(key=k, value=str(v)) for k, v in values.items()])]
        writer.write(topics['/mpc/diagnostics'], int(STEP_TIME * 1e9) + 3,
                     serialize_message(array))


def test_the_memory_is_rebuilt_with_each_scan_placed_where_the_robot_was(tmp_path) -> None:
    # placed with the pose at its stamp, every scan puts the wall at WALL_X; placed with
    # the step's pose (0.25 m further on than at the last scan) it would lie 0.25 m further
    bag = tmp_path / 'bag'
    write_run(bag)
    lines = replay(read_recording(bag), 0, parameter_values(PARAMS, []))
    assert lines[0].startswith('step 0 at 1.00 s, recorded: no feasible input, stopping')
    nearest = float(lines[1].split(' m from the nearest')[0].rsplit(' ', 1)[1])
    front = float(JACKAL.vertices[:, 0].max())
    assert nearest == pytest.approx(WALL_X - (SPEED * STEP_TIME + front), abs=0.03)
    assert lines[2].startswith('replayed solve 0: ')


def test_a_setting_can_be_changed_for_the_replay_and_a_typo_is_refused() -> None:
    assert parameter_values(PARAMS, ['collision_margin=0.0'])['collision_margin'] == 0.0
    with pytest.raises(ValueError, match='collision_margn'):
        parameter_values(PARAMS, ['collision_margn=0.0'])
    with pytest.raises(ValueError, match='name=value'):
        parameter_values(PARAMS, ['collision_margin'])


def test_a_bag_or_step_that_is_not_there_is_one_line_and_exit_code_2(tmp_path, capsys) -> None:
    assert main([str(tmp_path / 'none'), '--step', '0']) == 2
    assert 'bag not found' in capsys.readouterr().err
    bag = tmp_path / 'bag'
    write_run(bag)
    assert main([str(bag), '--step', '5', *sum((['--params-file', p] for p in PARAMS), [])]) == 2
    assert capsys.readouterr().err.strip() == 'replay_step: no step 5 in the bag'


def test_the_command_line_prints_the_recorded_and_the_replayed_step(tmp_path, capsys) -> None:
    bag = tmp_path / 'bag'
    write_run(bag)
    args = [str(bag), '--step', '-1', '--solves', '2']
    assert main(args + sum((['--params-file', p] for p in PARAMS), [])) == 0
    out = capsys.readouterr().out.splitlines()
    assert [line.split(':')[0] for line in out[2:]] == ['replayed solve 0', 'replayed solve 1']
    assert math.isfinite(float(out[1].split(' m from the nearest')[0].rsplit(' ', 1)[1]))
