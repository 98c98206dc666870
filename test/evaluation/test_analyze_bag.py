# SPDX-License-Identifier: Apache-2.0
"""analyze_bag on bags written here with rosbags (no DDS): the world and the goal flag."""

from __future__ import annotations

import json
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

from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.diagnostics import BagKey, ControllerDiagnostics
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.mpc import LyapunovCase, PlanSource
from mpc_local_planner.core.obstacles import min_clearance
from mpc_local_planner.evaluation.analyze_bag import (
    analyze,
    GROUND_TRUTH,
    main,
    read_run,
    recorded_world,
    summary,
)
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import load_world

RRT_WORLD = resolve_data_file('rrt_cluttered')


def steps(count: int, *, arrive: bool, start: tuple[float, float] = (0.0, 1.65)
          ) -> list[ControllerDiagnostics]:
    """Control steps along +x from start (by default between rrt_cluttered's obstacles)."""
    records = []
    for i in range(count):
        last = arrive and i == count - 1
        output = ControlOutput(np.array([0.0 if last else 0.3, 0.0]), None,
                               Reason.GOAL_REACHED if last else Reason.TRACKING)
        record = ControllerDiagnostics.from_output(
            output, state=np.array([start[0] + 0.1 * i, start[1], 0.0]), state_time=0.2 * i,
            failures_total=0)
        records.append(record._replace(source=PlanSource.SOLVER, s=i / count, value=1.0,
                                       solve_ms=2.0))
    return records


def write_bag(bag: Path, records: list[ControllerDiagnostics], *,
              world_file: Path | None = None,
              odometry: list[tuple[float, float, float, float, float]] = (),
              ground_truth: list[tuple[float, float, float, float, float]] = (),
              local_plans: list[tuple[float, list[tuple[float, float]]]] = ()) -> None:
    """Write /mpc/diagnostics as bag_recorder would, with the world in the metadata if given.

    odometry: (t, x, y, theta, v) messages on /odom too; ground_truth: the same on the
    simulator's ground truth; local_plans: (t, [(x, y), ...]) on /local_plan.
    """
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        if world_file is not None:
            writer.set_custom_data(BagKey.WORLD_FILE.value, str(world_file))
            writer.set_custom_data(BagKey.WORLD.value, world_file.read_text())
        connection = writer.add_connection('/mpc/diagnostics',
                                           'diagnostic_msgs/msg/DiagnosticArray',
                                           typestore=typestore)
        for record in records:
            msg = DiagnosticArray()
            msg.header.stamp = stamp(record.state_time)
            msg.status = [DiagnosticStatus(message=record.message, values=[
                KeyValue(key=k, value=v) for k, v in record.to_values()])]
            writer.write(connection, int(record.state_time * 1e9), serialize_message(msg))
        for topic, samples in (('/odom', odometry), ('/' + GROUND_TRUTH, ground_truth)):
            if samples:
                connection = writer.add_connection(topic, 'nav_msgs/msg/Odometry',
                                                   typestore=typestore)
            for t, x, y, theta, v in samples:
                odom = Odometry()
                odom.header.stamp = stamp(t)
                odom.pose.pose.position.x, odom.pose.pose.position.y = x, y
                odom.pose.pose.orientation.z = math.sin(theta / 2)
                odom.pose.pose.orientation.w = math.cos(theta / 2)
                odom.twist.twist.linear.x = v
                writer.write(connection, int(round(t * 1e9)), serialize_message(odom))
        if local_plans:
            connection = writer.add_connection('/local_plan', 'nav_msgs/msg/Path',
                                               typestore=typestore)
        for t, points in local_plans:
            path = PathMsg()
            path.header.stamp = stamp(t)
            for x, y in points:
                pose = PoseStamped()
                pose.pose.position.x, pose.pose.position.y = x, y
                pose.pose.orientation.w = 1.0
                path.poses.append(pose)
            writer.write(connection, int(round(t * 1e9)), serialize_message(path))


def stamp(t: float) -> Time:
    """Return t seconds as a builtin_interfaces Time."""
    nanoseconds = int(round(t * 1e9))
    return Time(sec=nanoseconds // 10**9, nanosec=nanoseconds % 10**9)


def test_the_world_recorded_in_the_bag_gives_the_true_clearance(tmp_path: Path) -> None:
    world_copy = tmp_path / 'rrt_cluttered.yaml'
    world_copy.write_text(RRT_WORLD.read_text())
    bag = tmp_path / 'bag'
    write_bag(bag, steps(20, arrive=True), world_file=world_copy)
    world_copy.unlink()  # the contents travel in the bag

    recorded = recorded_world(bag)
    assert recorded is not None and recorded.name == 'rrt_cluttered'
    metrics = analyze(bag, tmp_path / 'out')
    world = load_world(RRT_WORLD)
    rows = read_run(bag).rows
    truth = min_clearance(list(world.obstacles), rows[:, 1:3]) - world.robot_radius
    assert metrics['world_name'] == 'rrt_cluttered'
    assert metrics['min_clearance'] == pytest.approx(truth)
    # --world takes precedence (the paper's box is elsewhere: a wrong, larger clearance)
    paper = analyze(bag, tmp_path / 'paper', world_file='paper_obstacle')
    assert paper['min_clearance'] > metrics['min_clearance'] + 0.1


def test_with_the_ground_truth_recorded_the_clearance_is_the_truths(tmp_path: Path) -> None:
    # on the MuJoCo plant the odometry drifts: the controller's poses ran through a cylinder
    # the robot never touched (BARN 290 through the nodes: -13 mm by odometry, 78 mm true).
    # Here the steps run through rrt_cluttered's first obstacle; the truth stays on y = 1.65
    world = load_world(RRT_WORLD)
    centre = np.mean(world.obstacles[0].vertices, axis=0)
    records = steps(10, arrive=False, start=(float(centre[0]) - 0.5, float(centre[1])))
    truth = [(0.2 * i, 0.1 * i, 1.65, 0.0, 0.5) for i in range(10)]
    bag = tmp_path / 'bag'
    write_bag(bag, records, ground_truth=truth)
    metrics = analyze(bag, tmp_path / 'out', world_file=str(RRT_WORLD))
    true_clearance = min_clearance(list(world.obstacles),
                                  np.array(truth)[:, 1:3]) - world.robot_radius
    assert metrics['min_clearance'] == pytest.approx(true_clearance)
    assert metrics['min_clearance'] > 0 and not metrics['collision']
    assert metrics['min_clearance_estimate'] < 0  # what the odometry said


def test_a_moving_obstacle_counts_where_it_was_at_each_rows_time(tmp_path: Path) -> None:
    # the steps run along y = 1.65 from x = 0, 0.1 m per 0.2 s: at x = 1 at t = 2, when the
    # walker crossing x = 1 at 1 m/s is on that line too
    world_file = tmp_path / 'walker.yaml'
    world_file.write_text('bounds: [-1.0, 3.0, -1.0, 4.0]\n'
                          'start: [0.0, 1.65, 0.0]\ngoal: [2.5, 1.65, 0.0]\n'
                          'robot_radius: 0.2\n'
                          'moving_obstacles:\n'
                          '  - circle: [0.0, 0.0, 0.25]\n'
                          '    waypoints: {points: [[1.0, -0.35], [1.0, 3.65]], speed: 1.0}\n')
    bag = tmp_path / 'bag'
    write_bag(bag, steps(20, arrive=True), world_file=world_file)
    metrics = analyze(bag, tmp_path / 'out')
    assert metrics['collision'] is True
    assert metrics['min_clearance'] == pytest.approx(-0.45)


def test_a_bag_without_its_world_is_refused_in_one_line_unless_given_one(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / 'bag'
    write_bag(bag, steps(5, arrive=False))
    assert main([str(bag), '--out', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('analyze_bag: ') and '--world' in err
    assert not (tmp_path / 'out' / 'metrics.json').exists()
    with pytest.raises(ValueError, match='does not record its world'):
        analyze(bag, tmp_path / 'out')
    assert main([str(bag), '--out', str(tmp_path / 'out'), '--world', 'rrt_cluttered']) == 1


def test_the_goal_flag_comes_from_the_last_step_when_only_it_says_so(tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    write_bag(bag, steps(10, arrive=True), world_file=RRT_WORLD)
    assert read_run(bag).goal_reached
    metrics = analyze(bag, tmp_path / 'out')
    assert json.loads((tmp_path / 'out' / 'metrics.json').read_text())[
        'controller_goal_reached'] is True
    assert metrics['controller_goal_reached'] is True
    unfinished = tmp_path / 'unfinished'
    write_bag(unfinished, steps(9, arrive=False), world_file=RRT_WORLD)
    assert not read_run(unfinished).goal_reached


def test_a_bag_with_nothing_to_analyse_is_refused_not_crashed(tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    write_bag(bag, [], world_file=RRT_WORLD)
    with pytest.raises(ValueError, match='nothing to analyse'):
        analyze(bag, tmp_path / 'out')


NARROW_GAP = resolve_data_file('narrow_gap')


def test_clearance_is_the_true_footprints_and_the_metrics_say_which(tmp_path: Path) -> None:
    # straight through the 0.60 m gap: the 0.43 m wide Jackal keeps 0.085 m to each side;
    # its circumscribed circle (0.333 m) would overlap the wall
    bag = tmp_path / 'bag'
    write_bag(bag, steps(20, arrive=True, start=(1.0, 0.0)), world_file=NARROW_GAP)
    metrics = analyze(bag, tmp_path / 'out')
    assert metrics['min_clearance'] == pytest.approx(0.085)
    assert metrics['collision'] is False
    assert metrics['footprint']['shape'] == 'polygon'
    np.testing.assert_allclose(metrics['footprint']['vertices'], JACKAL.vertices)
    on_disk = json.loads((tmp_path / 'out' / 'metrics.json').read_text())
    assert on_disk['footprint'] == metrics['footprint']
    # --footprint takes precedence: a rectangle 0.70 m wide does not fit the gap
    wide = '[[0.25, 0.35], [-0.25, 0.35], [-0.25, -0.35], [0.25, -0.35]]'
    assert main([str(bag), '--out', str(tmp_path / 'wide'), '--footprint', wide]) == 1
    wide_metrics = json.loads((tmp_path / 'wide' / 'metrics.json').read_text())
    assert wide_metrics['collision'] is True and wide_metrics['min_clearance'] < 0
    np.testing.assert_allclose(np.abs(wide_metrics['footprint']['vertices']),
                               [[0.25, 0.35]] * 4)
    assert main([str(bag), '--out', str(tmp_path / 'bad'), '--footprint', '[[0, 0]]']) == 2
    # a round robot's record
    round_metrics = analyze(bag, tmp_path / 'round', world_file=RRT_WORLD)
    assert round_metrics['footprint'] == {'shape': 'circle', 'radius': 0.1}


def test_a_solves_v_n_check_counts_once_not_on_every_row_that_holds_its_plan(
        tmp_path: Path) -> None:
    # control_frequency 20 Hz, h = 0.2 s: one solve, then three rows that apply its plan and
    # repeat its figures (solved false); the solve broke the decrease once
    records = steps(8, arrive=False)
    for i, record in enumerate(records):
        records[i] = record._replace(solved=i % 4 == 0,
                                     lyapunov_ok=None if i < 4 else False)
    bag = tmp_path / 'bag'
    write_bag(bag, records, world_file=RRT_WORLD)
    run = read_run(bag)
    assert run.lyapunov_ok == [None] * 4 + [False, None, None, None]
    metrics = analyze(bag, tmp_path / 'out')
    assert metrics['lyapunov_checks'] == 1 and metrics['lyapunov_violations'] == 1


def test_the_summary_says_which_v_n_violations_the_proof_covers(tmp_path: Path) -> None:
    covered, off = LyapunovCase.COVERED, LyapunovCase.STATE_OFF_PREDICTION
    flags = [None, (True, covered), (False, off), (True, off), (True, covered)]
    records = [record._replace(solved=True, lyapunov_ok=None if flag is None else flag[0],
                               lyapunov_case=None if flag is None else flag[1])
               for record, flag in zip(steps(5, arrive=True), flags, strict=True)]
    bag = tmp_path / 'bag'
    write_bag(bag, records, world_file=RRT_WORLD)
    assert read_run(bag).lyapunov_cases == [None, covered, off, off, covered]
    metrics = analyze(bag, tmp_path / 'out')
    assert metrics['lyapunov_covered_violations'] == 0
    assert summary(metrics).splitlines()[4] == (
        'V_N violations: 0 of 2 checks the proof covers; 1 of 2 where the problem changed '
        '(state off prediction 1/2)')


def approach(count: int, *, last_off: float) -> list[ControllerDiagnostics]:
    """Control steps toward rrt_cluttered's goal (4, 3, 0) along -x, the last last_off short.

    Only the last says goal_reached: the controller's verdict at that step.
    """
    records = steps(count, arrive=True)
    xs = np.linspace(4.0 - last_off - 0.1 * (count - 1), 4.0 - last_off, count)
    return [record._replace(x=float(x), y=3.0, theta=0.0) for record, x in zip(
        records, xs, strict=True)]


def test_arrival_is_the_controllers_verdict_within_its_own_tolerance(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # a real robot's controller (xy_goal_tolerance 0.1 m) arrives 0.09 m from the goal: the
    # bag says reached, when it says so, whatever a fixed tolerance of the analysis would say
    bag = tmp_path / 'bag'
    write_bag(bag, approach(10, last_off=0.09), world_file=RRT_WORLD)
    assert main([str(bag), '--out', str(tmp_path / 'out')]) == 0
    metrics = json.loads((tmp_path / 'out' / 'metrics.json').read_text())
    assert metrics['reached'] is True and metrics['time_to_target'] == pytest.approx(1.8)
    assert metrics['final_position_error'] == pytest.approx(0.09)
    assert metrics['arrival'] == "the controller's goal_reached"
    assert 'reached: True' in capsys.readouterr().out
    # the controller not (yet) arrived at 0.01 m: not reached
    unfinished = tmp_path / 'unfinished'
    records = approach(10, last_off=0.01)
    records[-1] = steps(10, arrive=False)[-1]._replace(x=3.99, y=3.0)
    write_bag(unfinished, records, world_file=RRT_WORLD)
    metrics = analyze(unfinished, tmp_path / 'unfinished_out')
    assert metrics['reached'] is False and metrics['time_to_target'] is None


def test_an_odometry_only_bag_is_judged_by_the_controllers_rule_and_defaults(
        tmp_path: Path) -> None:
    # no diagnostics (ros2 bag record of /odom alone): the controller's goal check with the
    # node's defaults (0.1 m, 0.15 rad), stateful as the node runs it
    bag = tmp_path / 'bag'
    odometry = [(0.1 * k, 3.0 + 0.1 * k, 3.0, 0.0, 1.0) for k in range(10)]  # to 3.9 m
    odometry[-1] = (0.9, 3.91, 3.0, 0.0, 0.0)  # 0.09 m short, stopped
    write_bag(bag, [], world_file=RRT_WORLD, odometry=odometry)
    metrics = analyze(bag, tmp_path / 'out')
    assert metrics['reached'] is True and metrics['time_to_target'] == pytest.approx(0.9)
    assert 'xy_goal_tolerance 0.1 m' in metrics['arrival']


def test_the_path_length_is_the_odometrys_distance_not_the_noise_of_the_poses(
        tmp_path: Path) -> None:
    # 20 Hz control steps at 0.5 m/s for 1.8 s toward the goal; the controller's poses (a
    # localizer's, corrected every few steps) jump by a centimetre or so, while the
    # odometry's twist says what the wheels drove
    rng = np.random.default_rng(1)
    records = [record._replace(x=3.01 + 0.025 * i + float(rng.normal(0.0, 0.01)),
                               y=3.0 + float(rng.normal(0.0, 0.01)), theta=0.0,
                               state_time=0.05 * i)
               for i, record in enumerate(steps(37, arrive=True))]
    odometry = [(0.02 * k, 3.01 + 0.01 * k, 3.0, 0.0, 0.5) for k in range(91)]
    bag = tmp_path / 'bag'
    write_bag(bag, records, world_file=RRT_WORLD, odometry=odometry)
    metrics = analyze(bag, tmp_path / 'out')
    assert metrics['path_length'] == pytest.approx(0.9)
    assert metrics['path_length_source'] == 'odometry speed'
    rows = read_run(bag).rows
    assert np.sum(np.hypot(*np.diff(rows[:, 1:3], axis=0).T)) > 1.0  # what it had counted


def test_read_run_gives_the_ground_truth_when_asked_and_every_stream_on_the_rows_clock(
        tmp_path: Path) -> None:
    # the run starts 10 s into the bag's clock; each solve's local plan has its stamp
    records = [record._replace(state_time=10.0 + 0.2 * i)
               for i, record in enumerate(steps(5, arrive=False))]
    odometry = [(10.0 + 0.1 * k, 0.1 * k, 1.65, 0.0, 0.5) for k in range(10)]
    truth = [(10.05 + 0.1 * k, 0.1 * k, 1.7, 0.1, 0.5) for k in range(10)]
    plans = [(10.0 + 0.2 * i, [(0.1 * i, 1.65), (0.1 * i + 0.1, 1.65)]) for i in range(5)]
    bag = tmp_path / 'bag'
    write_bag(bag, records, odometry=odometry, ground_truth=truth, local_plans=plans)

    assert read_run(bag).ground_truth.shape == (0, 4)  # read only when asked
    run = read_run(bag, ground_truth_topic='/' + GROUND_TRUTH)
    assert run.start == pytest.approx(10.0)
    np.testing.assert_allclose(run.rows[:, 0], [0.0, 0.2, 0.4, 0.6, 0.8], atol=1e-9)
    np.testing.assert_allclose(run.ground_truth, [(t - 10.0, x, y, theta)
                                                  for t, x, y, theta, _ in truth], atol=1e-9)
    np.testing.assert_allclose(run.odometry_poses, [(t - 10.0, x, y, theta)
                                                    for t, x, y, theta, _ in odometry],
                               atol=1e-9)
    np.testing.assert_allclose(run.prediction_times, run.rows[:, 0], atol=1e-9)
    assert [step.state_time for step in run.steps] == [r.state_time for r in records]
    assert all(step.source is PlanSource.SOLVER for step in run.steps)
