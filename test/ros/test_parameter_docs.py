# SPDX-License-Identifier: Apache-2.0
"""docs/parameters.md is the nodes' parameter tables, as they are now."""

from __future__ import annotations

from pathlib import Path

from mpc_local_planner.ros.parameter_docs import NODES, render

DOCS = Path(__file__).resolve().parents[2] / 'docs' / 'parameters.md'


def test_the_parameter_reference_is_the_nodes_tables():
    assert DOCS.read_text(encoding='utf-8') == render(), (
        'docs/parameters.md is stale: run '
        'python3 -m mpc_local_planner.ros.parameter_docs docs/parameters.md')


def test_every_declared_parameter_has_a_row():
    text = DOCS.read_text(encoding='utf-8')
    for node in NODES:
        assert f'## `{node.executable}`' in text
        for spec in node.parameters:
            assert f'| `{spec.name}` |' in text
    # the ones the hand-written tables had lost
    assert '| `max_solve_time` |' in text
    assert '| `footprint` |' in text.split('## `unicycle_simulator`')[1]


def _range_cells() -> dict[tuple[str, str], str]:
    """Return (node, parameter) -> the range cell of docs/parameters.md."""
    cells, node = {}, ''
    for line in DOCS.read_text(encoding='utf-8').splitlines():
        if line.startswith('## `'):
            node = line.split('`')[1]
        elif line.startswith('| `'):
            columns = [c.strip() for c in line.strip('|').split(' | ')]
            cells[(node, columns[0].strip('`'))] = columns[2]
    return cells


def test_the_range_column_is_filled_where_a_range_exists():
    cells = _range_cells()
    ranged = {
        'mpc_controller': ['max_accel', 'max_decel'],
        'unicycle_simulator': [
            'scan.rate', 'scan.fov', 'scan.beams', 'scan.range_max', 'scan.noise_std',
            'scan.nan_fraction', 'scan.neg_inf_fraction', 'scan.loss_fraction',
            'odom_drift.position', 'odom_drift.heading', 'actuator_lag', 'acceleration_limits',
            'command_latency', 'odom_noise_std'],
    }
    for node, names in ranged.items():
        for name in names:
            assert cells[(node, name)], f'{node} {name}: no range'
    # one marker for "the preset's", outside every override's range
    assert cells[('unicycle_simulator', 'scan.noise_std')] == '-1, or 0 .. 10'
    assert cells[('unicycle_simulator', 'actuator_lag')] == 'each -1, or 0 .. 10'
    assert cells[('mpc_controller', 'max_accel')] == 'each 0, or 0.01 .. 1000'
    assert cells[('unicycle_simulator', 'scan.beams')] == '2 .. 10000'


def test_each_node_says_what_it_does_without_a_pose_in_the_plans_frame():
    def description(node: str, name: str) -> str:
        table = next(n for n in NODES if n.executable == node).parameters
        return next(spec.description for spec in table if spec.name == name)

    for name in ('localization_max_travel', 'transform_tolerance'):
        assert 'the controller stops (no_localization)' in description('mpc_controller', name)
        planner = description('global_planner', name)
        assert 'controller' not in planner
        assert 'a goal waits, nothing is re-planned' in planner
