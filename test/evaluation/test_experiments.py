# SPDX-License-Identifier: Apache-2.0
"""The paper's three experiments, run through their command line (no ROS)."""

import json

import pytest

from mpc_local_planner.evaluation.experiments import main
from mpc_local_planner.evaluation.trajectory import read_trajectory_csv, TRAJECTORY_COLUMNS


@pytest.fixture(scope='module')
def experiments_out(tmp_path_factory):
    """All three experiments, interpreted: the compiled runs' numbers, without gcc's wait."""
    out = tmp_path_factory.mktemp('experiments')
    cache = tmp_path_factory.mktemp('compile_cache')
    with pytest.MonkeyPatch.context() as env:
        env.setenv('MPC_LOCAL_PLANNER_CACHE', str(cache))
        assert main(['all', '--out', str(out), '--no-compile']) == 0
    assert not list(cache.iterdir())  # --no-compile: nothing was compiled
    return out


def _metrics(folder):
    return json.loads((folder / 'metrics.json').read_text())


def test_obstacle_experiment_writes_both_runs_and_one_figure(experiments_out) -> None:
    folder = experiments_out / 'obstacle'
    assert (folder / 'obstacle.png').stat().st_size > 10_000
    proposed, baseline = _metrics(folder / 'proposed'), _metrics(folder / 'tracking_baseline')
    assert proposed['reached'] and not proposed['collision']
    assert proposed['lyapunov_nonincreasing']
    assert not baseline['reached'] and baseline['max_x'] < 1.0
    # the tracking baseline's checks are told by case, as the proposed MPC's
    assert baseline['lyapunov_by_case'] is not None
    assert sum(c['checks'] for c in baseline['lyapunov_by_case'].values()) \
        == baseline['lyapunov_checks'] > 0
    with open(folder / 'proposed' / 'trajectory.csv') as stream:
        assert stream.readline().strip() == ','.join(TRAJECTORY_COLUMNS)
    rows = read_trajectory_csv(folder / 'proposed' / 'trajectory.csv')
    assert rows.shape == (proposed['steps'], 9)


def test_horizon_experiment_reaches_the_target_for_all_nine_horizons(experiments_out) -> None:
    folder = experiments_out / 'horizon'
    runs = [_metrics(p.parent) for p in folder.glob('N*_h*/metrics.json')]
    assert len(runs) == 9
    assert all(run['reached'] for run in runs)
    assert '| N | h [s] |' in (folder / 'table.md').read_text()
    shortest_horizon = min(runs, key=lambda r: r['horizon'] * r['step'])
    longest_horizons = [r for r in runs if r['horizon'] * r['step'] >= 4.0]
    # the paper's effect: a long horizon cuts the corner, the shortest one follows the path
    assert all(r['path_length'] < shortest_horizon['path_length'] for r in longest_horizons)
    assert all(r['path_length'] < r['reference_length'] for r in longest_horizons)


def test_rrt_experiment_drives_a_shorter_route_than_the_rrt_path(experiments_out) -> None:
    metrics = _metrics(experiments_out / 'rrt' / 'proposed')
    assert metrics['reached'] and not metrics['collision']
    assert metrics['path_length'] < metrics['reference_length']
    assert metrics['rrt_waypoints'] > 2
