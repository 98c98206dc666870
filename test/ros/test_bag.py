# SPDX-License-Identifier: Apache-2.0
"""bag_recorder writes an mcap rosbag2 that rosbags reads; analyze_bag reads it back."""

from __future__ import annotations

from pathlib import Path
import re

from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
import numpy as np
import pytest
from rclpy.exceptions import InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores

from mpc_local_planner.evaluation.analyze_bag import main as analyze_main
from mpc_local_planner.evaluation.analyze_bag import read_run, recorded_world
from mpc_local_planner.ros.bag_recorder_node import BagRecorderNode
from mpc_local_planner.ros.bag_recorder_node import main as recorder_main
from mpc_local_planner.ros.conversions import (
    poses_to_path,
    seconds_to_stamp,
    state_to_odometry,
    twist_from_u,
)
from mpc_local_planner.ros.qos import CMD_VEL_QOS, ODOM_QOS, PLAN_QOS
from mpc_local_planner.worlds.data_files import resolve_data_file


def record(ros, bag: Path, odoms: int, cmds: int, world_file: str = '') -> BagRecorderNode:
    recorder = ros.add(BagRecorderNode(context=ros.context, parameter_overrides=[
        Parameter('output', value=str(bag)), Parameter('world_file', value=world_file)]))
    talker = ros.add(Node('talker', context=ros.context))
    odom_pub = talker.create_publisher(Odometry, 'odom', ODOM_QOS)
    cmd_pub = talker.create_publisher(Twist, 'cmd_vel', CMD_VEL_QOS)
    plan_pub = talker.create_publisher(PathMsg, 'plan', PLAN_QOS)
    plan_pub.publish(poses_to_path(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])))
    assert ros.spin_until(lambda: odom_pub.get_subscription_count() > 0
                          and cmd_pub.get_subscription_count() > 0)
    for i in range(odoms):
        odom_pub.publish(state_to_odometry(np.array([0.1 * i, 0.0, 0.0]), np.array([0.1, 0.0]),
                                           stamp=seconds_to_stamp(0.1 * i)))
    for i in range(cmds):
        cmd_pub.publish(twist_from_u([0.01 * i, 0.0]))
    assert ros.spin_until(lambda: recorder.counts['/odom'] == odoms
                          and recorder.counts['/cmd_vel'] == cmds
                          and recorder.counts['/plan'] == 1)
    recorder.close()
    return recorder


@pytest.mark.dds
def test_recorded_bag_is_mcap_readable_by_rosbags_with_topics_and_counts(ros, tmp_path) -> None:
    bag = tmp_path / 'bag'
    record(ros, bag, odoms=25, cmds=7)
    assert list(bag.glob('*.mcap'))
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics == {
            '/odom': 'nav_msgs/msg/Odometry', '/cmd_vel': 'geometry_msgs/msg/Twist',
            '/plan': 'nav_msgs/msg/Path', '/local_plan': 'nav_msgs/msg/Path',
            '/mpc/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
            '/planner/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray'}
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert counts == {'/odom': 25, '/cmd_vel': 7, '/plan': 1, '/local_plan': 0,
                          '/mpc/diagnostics': 0, '/planner/diagnostics': 0}
        xs = []
        for connection, _, data in reader.messages():
            msg = typestore.deserialize_cdr(data, connection.msgtype)
            if connection.topic == '/odom':
                xs.append(msg.pose.pose.position.x)
        np.testing.assert_allclose(xs, 0.1 * np.arange(25))


@pytest.mark.dds
def test_analyze_bag_rebuilds_rows_from_odometry_without_diagnostics(ros, tmp_path) -> None:
    bag = tmp_path / 'bag'
    record(ros, bag, odoms=10, cmds=0)
    run = read_run(bag)
    assert run.rows.shape == (10, 9)
    np.testing.assert_allclose(run.rows[:, 0], 0.1 * np.arange(10), atol=1e-9)
    np.testing.assert_allclose(run.rows[:, 1], 0.1 * np.arange(10), atol=1e-9)
    np.testing.assert_allclose(run.rows[:, 4], 0.1)
    assert run.plan.shape == (2, 3)


@pytest.mark.dds
def test_recorder_refuses_an_unknown_message_type(ros, tmp_path) -> None:
    with pytest.raises(InvalidParameterValueException, match='not available'):
        BagRecorderNode(context=ros.context, parameter_overrides=[
            Parameter('output', value=str(tmp_path / 'bag')),
            Parameter('topics', value=['odom']), Parameter('types', value=['nope_msgs/msg/X'])])


@pytest.mark.dds
def test_recorder_records_the_world_file_and_its_contents_in_the_metadata(ros, tmp_path) -> None:
    bag = tmp_path / 'bag'
    record(ros, bag, odoms=3, cmds=0, world_file='rrt_cluttered')
    world = recorded_world(bag)
    assert world is not None and world.name == 'rrt_cluttered'
    assert len(world.obstacles) == 7 and world.robot_radius == 0.1
    metadata = (bag / 'metadata.yaml').read_text()
    assert str(resolve_data_file('rrt_cluttered.yaml')) in metadata


@pytest.mark.dds
def test_a_bag_recorded_without_a_world_is_refused_without_world(ros, tmp_path, capsys) -> None:
    bag = tmp_path / 'bag'
    record(ros, bag, odoms=5, cmds=0)
    assert recorded_world(bag) is None
    assert analyze_main([str(bag), '--out', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'does not record its world' in err and '--world' in err
    assert analyze_main([str(bag), '--out', str(tmp_path / 'out'), '--world',
                         'paper_obstacle']) == 1  # analysed: the robot never got there


@pytest.mark.dds
def test_recorder_refuses_an_existing_output_folder_and_leaves_it_untouched(ros, tmp_path) -> None:
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'earlier_run.mcap').write_bytes(b'not ours')
    with pytest.raises(FileExistsError, match="output '.*bag' exists: remove it"):
        BagRecorderNode(context=ros.context, parameter_overrides=[
            Parameter('output', value=str(bag))])
    assert [p.name for p in bag.iterdir()] == ['earlier_run.mcap']


def test_recorder_help_lists_its_parameters_and_creates_no_bag(tmp_path, monkeypatch,
                                                               capsys) -> None:
    monkeypatch.chdir(tmp_path)
    assert recorder_main(['bag_recorder', '--help']) == 0
    out = capsys.readouterr().out
    assert out.startswith('usage: bag_recorder')
    assert re.search(r"^  output +'bag'", out, re.MULTILINE), out
    assert list(tmp_path.iterdir()) == []


def test_analyze_bag_reports_a_missing_bag(tmp_path, capsys) -> None:
    assert analyze_main([str(tmp_path / 'missing'), '--out', str(tmp_path / 'out')]) == 2
    assert 'bag not found' in capsys.readouterr().err
