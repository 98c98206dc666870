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

import numpy as np
import pytest

from mpc_local_planner.core.paths import wrap_angle
from mpc_local_planner.evaluation.trajectory import read_trajectory_csv, TRAJECTORY_COLUMNS
from mpc_local_planner.ros.closed_loop import LoopOptions, main, node_parameters, run_closed_loop
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import load_world

WORLD_FILE = resolve_data_file('paper_obstacle.yaml')
WORLD = load_world(WORLD_FILE)


def check_run(out, metrics) -> None:  # noqa: ANN001
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
    assert (out / 'trajectory.png').stat().st_size > 0
    assert on_disk['messages']['/odom'] > 100 and on_disk['messages']['/plan'] == 1


@pytest.mark.parametrize('path', ['analytic', 'rrt'])
def test_closed_loop_in_one_process_reaches_the_paper_target_faster_than_real_time(
        tmp_path, path) -> None:  # noqa: ANN001
    options = LoopOptions(world=str(WORLD_FILE), out=str(tmp_path), path=path, rtf=4.0,
                          timeout=90.0)
    result = run_closed_loop(options)
    assert result.success, result.metrics
    assert result.stop_reason == 'goal reached'
    check_run(tmp_path, result.metrics)


def test_closed_loop_as_separate_processes_reaches_the_target(tmp_path) -> None:  # noqa: ANN001
    code = main(['--out', str(tmp_path), '--path', 'rrt', '--rtf', '4', '--timeout', '90',
                 '--separate-processes'])
    assert code == 0
    check_run(tmp_path, json.loads((tmp_path / 'metrics.json').read_text()))
    assert {p.name for p in (tmp_path / 'logs').iterdir()} == {
        'global_planner.log', 'mpc_controller.log', 'unicycle_simulator.log'}


def test_node_parameters_use_sim_time_and_the_world(tmp_path) -> None:  # noqa: ANN001
    params = node_parameters(LoopOptions(path='analytic', rtf=8.0), WORLD_FILE, WORLD)
    assert params['mpc_controller']['use_sim_time'] is True
    assert params['global_planner']['use_sim_time'] is True
    assert params['unicycle_simulator']['publish_clock'] is True
    assert params['unicycle_simulator']['real_time_factor'] == 8.0
    assert params['mpc_controller']['analytic_path'] == 'paper_sinusoid'
    np.testing.assert_allclose(params['unicycle_simulator']['initial_pose'], WORLD.start)


def test_analytic_path_on_a_world_without_one_is_refused(tmp_path) -> None:  # noqa: ANN001
    code = main(['--world', 'corridor_turn.yaml', '--path', 'analytic', '--out', str(tmp_path)])
    assert code == 2
