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
"""The full loop over DDS in simulated time, faster than real time, to the paper's target."""

from __future__ import annotations

import json
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter

from mpc_local_planner.core.controller import ControlOutput, Reason
from mpc_local_planner.core.diagnostics import ControllerDiagnostics
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.mpc import PlanSource
from mpc_local_planner.core.paths import wrap_angle
from mpc_local_planner.evaluation.analyze_bag import read_run
from mpc_local_planner.evaluation.trajectory import read_trajectory_csv, TRAJECTORY_COLUMNS
from mpc_local_planner.ros.bag_recorder_node import BagRecorderNode
from mpc_local_planner.ros.closed_loop import (
    _Monitor,
    check_plannable,
    EXIT_NO_PLAN,
    flush_recording,
    LoopOptions,
    main,
    node_parameters,
    run_closed_loop,
)
from mpc_local_planner.ros.qos import DIAGNOSTICS_QOS
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import load_world

WORLD_FILE = resolve_data_file('paper_obstacle.yaml')
WORLD = load_world(WORLD_FILE)


def check_run(out, metrics) -> None:
    rows = read_trajectory_csv(out / 'trajectory.csv')
    assert rows.shape[1] == len(TRAJECTORY_COLUMNS) and len(rows) > 20
    # the last measured pose is at the target, by the metric's and by our own reckoning
    assert metrics['reached'] and not metrics['collision']
    final = rows[-1, 1:4]
    assert np.hypot(*(final[:2] - WORLD.goal[:2])) < 0.05
    assert abs(wrap_angle(final[2] - WORLD.goal[2])) < 0.1
    assert metrics['final_position_error'] < 0.05
    # no sample inside the box (the raw obstacle)
    for obstacle in WORLD.obstacles:
        assert not np.any(obstacle.contains(rows[:, 1:3]))
    # one control step every h = 0.2 s of simulated time
    assert np.median(np.diff(rows[:, 0])) == pytest.approx(0.2, abs=1e-6)
    # the commands respect the bounds
    assert np.all(np.abs(rows[:, 4]) <= 0.31 + 1e-9) and np.all(np.abs(rows[:, 5]) <= 1.9 + 1e-9)
    on_disk = json.loads((out / 'metrics.json').read_text())
    assert on_disk['reached'] is True and on_disk['stop_reason'] == 'goal reached'
    assert on_disk['controller_goal_reached'] is True  # the last diagnostics are in the bag
    assert on_disk['world_name'] == WORLD.name  # from the bag's metadata
    assert (out / 'trajectory.png').stat().st_size > 0
    assert on_disk['messages']['/odom'] > 100 and on_disk['messages']['/plan'] == 1


@pytest.mark.slow
@pytest.mark.parametrize('path', ['analytic', 'rrt'])
def test_closed_loop_in_one_process_reaches_the_paper_target_faster_than_real_time(
        tmp_path, path) -> None:
    options = LoopOptions(world=str(WORLD_FILE), out=str(tmp_path), path=path, rtf=4.0,
                          timeout=90.0)
    result = run_closed_loop(options)
    assert result.success, result.metrics
    assert result.stop_reason == 'goal reached'
    check_run(tmp_path, result.metrics)


@pytest.mark.slow
def test_closed_loop_as_separate_processes_reaches_the_target(tmp_path) -> None:
    code = main(['--out', str(tmp_path), '--path', 'rrt', '--rtf', '4', '--timeout', '90',
                 '--separate-processes'])
    assert code == 0
    check_run(tmp_path, json.loads((tmp_path / 'metrics.json').read_text()))
    assert {p.name for p in (tmp_path / 'logs').iterdir()} == {
        'global_planner.log', 'mpc_controller.log', 'unicycle_simulator.log'}


def test_node_parameters_use_sim_time_and_the_world(tmp_path) -> None:
    params = node_parameters(LoopOptions(path='analytic', rtf=8.0), WORLD_FILE, WORLD)
    assert params['mpc_controller']['use_sim_time'] is True
    assert params['global_planner']['use_sim_time'] is True
    assert params['unicycle_simulator']['publish_clock'] is True
    assert params['unicycle_simulator']['real_time_factor'] == 8.0
    assert params['mpc_controller']['analytic_path'] == 'paper_sinusoid'
    np.testing.assert_allclose(params['unicycle_simulator']['initial_pose'], WORLD.start)


def test_analytic_path_on_a_world_without_one_is_refused(tmp_path) -> None:
    code = main(['--world', 'corridor_turn.yaml', '--path', 'analytic', '--out', str(tmp_path)])
    assert code == 2


def write_world(folder: Path, name: str, obstacles: str, goal: str) -> Path:
    path = folder / f'{name}.yaml'
    path.write_text(f'bounds: [-1.0, 5.0, -1.0, 5.0]\nobstacles:\n{obstacles}'
                    f'start: [0.0, 0.0, 0.0]\ngoal: {goal}\n')
    return path


def test_a_goal_inside_the_inflated_obstacles_is_refused_before_anything_starts(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # outside the box, inside it grown by the planner's clearance (0.1 m)
    world = write_world(tmp_path, 'near_box', '  - box: [1.0, 1.0, 2.0, 2.0]\n',
                        '[2.05, 1.5, 0.0]')
    code = main(['--world', str(world), '--path', 'rrt', '--out', str(tmp_path / 'out')])
    assert code == EXIT_NO_PLAN == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1, err
    assert 'no plan can come' in err and 'goal (2.05, 1.5) is in collision' in err
    assert 'robot_radius + clearance' in err
    assert not (tmp_path / 'out' / 'bag').exists()
    # the planner's robot radius counts as well as its clearance
    with pytest.raises(PlanningError, match='goal'):
        check_plannable(load_world(world), {'clearance': 0.01, 'robot_radius': 0.1})


@pytest.mark.slow
def test_a_walled_off_goal_ends_the_run_when_the_planner_says_so_with_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    walls = '  - box: [3.0, 3.0, 5.0, 3.2]\n  - box: [3.0, 3.0, 3.2, 5.0]\n'
    world = write_world(tmp_path, 'walled_off', walls, '[4.0, 4.0, 0.0]')
    code = main(['--world', str(world), '--path', 'rrt', '--out', str(tmp_path / 'out'),
                 '--timeout', '600', '--time-limit', '3600'])
    assert code == EXIT_NO_PLAN
    err = capsys.readouterr().err
    assert err.count('\n') == 1, err
    assert err.startswith('closed_loop: walled_off: no plan came: no plan to (4, 4)')
    assert 'RRT* found no collision-free path' in err
    assert not (tmp_path / 'out' / 'metrics.json').exists()


def test_a_world_named_without_its_suffix_is_found(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    # found (else 'not found'); refused for the analytic path it lacks, before any DDS
    assert main(['--world', 'rrt_cluttered', '--path', 'analytic',
                 '--out', str(tmp_path)]) == 2
    assert 'rrt_cluttered names no analytic path' in capsys.readouterr().err


@pytest.mark.slow
def test_the_diagnostics_that_stop_the_run_reach_the_bag(ros, tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    monitor = ros.add(_Monitor(context=ros.context))
    # subscribed, but not spun until the monitor has seen the goal: the worst case of the
    # executor running the monitor's callbacks before the recorder's
    recorder = BagRecorderNode(context=ros.context, parameter_overrides=[
        Parameter('output', value=str(bag))])
    talker = ros.add(Node('talker', context=ros.context))
    publisher = talker.create_publisher(DiagnosticArray, 'mpc/diagnostics', DIAGNOSTICS_QOS)
    assert ros.spin_until(lambda: publisher.get_subscription_count() >= 2)
    for reason in (Reason.TRACKING, Reason.TRACKING, Reason.GOAL_REACHED):
        record = ControllerDiagnostics.from_output(
            ControlOutput(np.zeros(2), None, reason), state=np.zeros(3), state_time=1.0,
            failures_total=0)._replace(source=PlanSource.SOLVER)
        publisher.publish(DiagnosticArray(status=[DiagnosticStatus(values=[
            KeyValue(key=k, value=v) for k, v in record.to_values()])]))
    # closed_loop's loop: spin until the monitor sees the goal, then stop
    assert ros.spin_until(lambda: monitor.goal_reached)
    ros.add(recorder)
    assert flush_recording(ros.executor, recorder, monitor)
    recorder.close()
    assert read_run(bag).goal_reached
    assert recorder.counts['/mpc/diagnostics'] == monitor.messages == 3
