# SPDX-License-Identifier: Apache-2.0
"""evaluate --through-nodes: the world a run writes, the command it runs, its DDS domain."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mpc_local_planner.evaluation import sensing_suites as suites
from mpc_local_planner.evaluation.through_nodes import claimed_domain, node_command, world_yaml
from mpc_local_planner.ros.closed_loop_parameters import file_parameters
from mpc_local_planner.worlds.data_files import BARN_DIR
from mpc_local_planner.worlds.world import Circle, load_world, world_from_dict


def test_a_barn_world_written_for_the_nodes_reads_back_as_the_suites_world(tmp_path) -> None:
    robot = suites.ROBOTS['jackal']
    world = suites.barn_sensing_world(BARN_DIR / 'world_007.json', robot)
    back = load_world(world_yaml(world, tmp_path / 'world.yaml'))
    # every cylinder unknown, each still a disk of its radius; the robot is the Jackal
    assert back.obstacles == () and len(back.unknown_obstacles) == len(world.unknown_obstacles)
    assert all(isinstance(shape, Circle) for shape in back.true_shapes)
    assert back.true_shapes == world.true_shapes
    np.testing.assert_array_equal(back.footprint.vertices, robot.footprint.vertices)
    np.testing.assert_array_equal(back.start, world.start)
    np.testing.assert_array_equal(back.goal, world.goal)
    assert back.bounds == world.bounds


def test_moving_obstacles_written_for_the_nodes_move_as_in_the_suites(tmp_path) -> None:
    world = load_world(Path(__file__).resolve().parents[2] / 'config' / 'worlds'
                       / 'moving_crossing.yaml')
    polygon = world_from_dict({
        'bounds': [0.0, 10.0, 0.0, 4.0], 'start': [0.5, 2.0, 0.0], 'goal': [9.0, 2.0, 0.0],
        'moving_obstacles': [{'polygon': [[-0.5, -0.5], [0.5, -0.5], [0.0, 0.5]],
                              'constant_velocity': {'start': [5.0, 2.0],
                                                    'velocity': [1.0, 0.5]}}]}, name='p')
    for original in (world, polygon):
        back = load_world(world_yaml(original, tmp_path / f'{original.name}.yaml'))
        assert len(back.moving_obstacles) == len(original.moving_obstacles)
        for t in (0.0, 1.3, 7.7, 31.0):
            for a, b in zip(original.shapes_at(t), back.shapes_at(t), strict=True):
                if isinstance(a, Circle):
                    assert a == b
                else:
                    assert np.array_equal(a.vertices, b.vertices)


def test_the_run_is_the_users_files_as_shipped_with_only_the_runs_wiring_added() -> None:
    command = node_command(Path('w.yaml'), Path('out'), robot='jackal', v_max=2.0,
                           omega_max=4.0, time_limit=100.0, goal_tolerance=1.0,
                           stall_seconds=20.0, seed=3, reality='real', budget='iterations',
                           plant='mujoco', recoveries=True)
    assert command[command.index('--plant') + 1] == 'mujoco'  # the suite's plant, not a default
    files = [command[i + 1] for i, arg in enumerate(command) if arg == '--params-file']
    assert [Path(f).name for f in files] == ['mpc_controller.yaml', 'jackal.yaml']
    params = [command[i + 1] for i, arg in enumerate(command) if arg == '--param']
    # the controller's tuning is the files'; the run only sets the motors, the budget,
    # whether the suite runs recoveries (the node's default is on, the suites' off) and
    # whether both nodes track moving clusters (off in both unless asked)
    assert params == ['unicycle_simulator.v_max:=2.0', 'unicycle_simulator.omega_max:=4.0',
                      'mpc_controller.budget:=iterations', 'mpc_controller.recoveries:=true',
                      'mpc_controller.track_moving:=false', 'global_planner.track_moving:=false']
    for flag in ('--lockstep', '--separate-processes', '--sensing', '--no-localizer'):
        assert flag in command
    circle = node_command(Path('w.yaml'), Path('out'), robot='circle', v_max=0.31,
                          omega_max=1.9, time_limit=100.0, goal_tolerance=0.1,
                          stall_seconds=20.0, seed=0, reality='ideal', budget='wall',
                          track_moving=True)
    assert 'jackal.yaml' not in ' '.join(circle) and 'budget:=' not in ' '.join(circle)
    assert circle[circle.index('--plant') + 1] == 'kinematic'
    assert 'mpc_controller.recoveries:=false' in circle
    assert {'mpc_controller.track_moving:=true', 'global_planner.track_moving:=true'} <= set(
        circle)


def test_each_run_holds_a_dds_domain_no_other_run_holds() -> None:
    with claimed_domain() as first, claimed_domain() as second:
        assert first != second
    with claimed_domain() as again:
        assert again == first  # released, so taken again


def test_a_params_files_sections_reach_the_nodes_they_name(tmp_path) -> None:
    path = tmp_path / 'p.yaml'
    path.write_text('/**:\n  ros__parameters:\n    use_sim_time: true\n'
                    'mpc_controller:\n  ros__parameters:\n    weights: {position: 2.0}\n'
                    '    v_max: 1.5\n', encoding='utf-8')
    assert file_parameters(str(path), 'mpc_controller') == {
        'use_sim_time': True, 'weights.position': 2.0, 'v_max': 1.5}
    assert file_parameters(str(path), 'global_planner') == {'use_sim_time': True}
