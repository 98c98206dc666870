# SPDX-License-Identifier: Apache-2.0
"""mpc_bench's tables say how each run ended and what each target is, from given figures."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from mpc_local_planner.evaluation import bench
from mpc_local_planner.evaluation.bench import (
    _footprint_lines,
    _perception_lines,
    _rate_lines,
    _row,
    CLOSED_LOOP_STEPS,
    HEADER,
)


def figures(median: float) -> dict[str, float]:
    return {'median': median, 'p95': median, 'p99': median, 'max': median}


def loop_row(outcome: str, **extra: Any) -> dict[str, Any]:
    """A closed_loop result as bench_runs.closed_loop returns it."""
    return {'solver': 'fatrop+compiled', 'horizon': 10, 'obstacles': 1, 'in_reach_max': 1,
            'active_max': 1, 'solve_ms': figures(0.5), 'iterations_median': 10.0,
            'step_ms': figures(1.0), 'reached': outcome == 'reached', 'outcome': outcome,
            'path_length': 3.398, 'failures': 0, 'steps': 72, **extra}


def cell(line: str, column: str) -> str:
    """Return the cell of a table row under the header's column."""
    names = [c.strip() for c in HEADER.split('\n')[0].strip('|').split('|')]
    return [c.strip() for c in line.strip('|').split('|')][names.index(column)]


def test_the_closed_loop_table_says_how_each_run_ended_not_a_bare_no() -> None:
    assert 'hit' not in HEADER.split('\n')[0]
    assert cell(_row(loop_row('reached'), None), 'end') == 'goal'
    assert cell(_row(loop_row('time limit'), None), 'end') == 'cap'
    assert cell(_row(loop_row('stalled'), None), 'end') == 'stall'
    assert cell(_row(loop_row('collision'), None), 'end') == 'contact'


def test_quick_closed_loops_run_to_the_goal_as_the_full_ones_do(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    caps = []

    def fake(solver: str, horizon: int, obstacles: list, *, max_steps: int,
             compile_functions: bool = True) -> dict[str, Any]:
        caps.append(max_steps)
        return loop_row('reached', solver=solver, horizon=horizon)

    monkeypatch.setattr(bench, 'closed_loop', fake)
    assert bench.main(['--quick', '--sections', 'horizons', '--backends', 'fatrop',
                       '--out', str(tmp_path / 'bench.json')]) == 0
    # the paper's scenario takes 72-76 steps: a cap of 60 had cut every quick row short
    assert caps and set(caps) == {CLOSED_LOOP_STEPS} and CLOSED_LOOP_STEPS >= 100
    printed = capsys.readouterr().out
    assert 'end: how the run ended' in printed and '|    goal |' in printed


def perception(step_ms: float) -> tuple[dict, dict, dict]:
    laser = {'scan_ms': figures(0.2), 'target_ms': 2.0}
    scan = {'scan_to_obstacles_ms': figures(1.0), 'memory_update_ms': figures(2.5),
            'target_ms': 2.0, 'scans': 50, 'obstacles_per_scan_median': 30.0,
            'remembered_median': 30.0, 'remembered_max': 39}
    control = {'step_ms': figures(step_ms), 'memory_update_ms': figures(4.75),
               'set_and_solve_ms': figures(2.25), 'target_ms': 5.0, 'horizon': 10,
               'solver': 'fatrop', 'reference': 'RRT*', 'steps': 60, 'max_steps': 60,
               'reached': False, 'goal_distance': 6.47, 'remembered_median': 40.0,
               'in_reach_median': 0.0, 'in_reach_max': 20, 'contact_steps': 0,
               'not_solved_steps': 0}
    return laser, scan, control


def test_the_perception_table_names_its_targets_and_why_one_is_missed() -> None:
    lines = _perception_lines(*perception(7.134))
    memory = next(line for line in lines if 'ObstacleMemory.update' in line)
    # no target of its own (2.5 ms would have read MISSED against scan_to_obstacles' 2 ms)
    assert 'MISSED' not in memory and '2.0' not in memory
    assert any(line.startswith('targets (medians') for line in lines)
    [missed] = [line for line in lines if line.startswith('missed:')]
    assert 'control step' in missed and '7.134 ms > 5 ms' in missed
    assert 'memory update 4.750 ms' in missed and 'set + solve 2.250 ms' in missed
    control = next(line for line in lines if line.startswith('control:'))
    assert 'stopped at the cap of 60 steps, short of the goal' in control
    assert not [line for line in _perception_lines(*perception(4.0))
                if line.startswith('missed:')]


def test_capped_footprint_and_rate_rows_say_cap_not_no() -> None:
    row = {'label': 'BARN world 0, scans, RRT* for it', 'scenario': 'barn', 'steps': 60,
           'max_steps': 60, 'reached': False, 'solve_ms': figures(0.9),
           'step_ms': figures(7.6), 'solve_verdict': 'met', 'step_verdict': 'MISSED',
           'target_solve_ms': 2.0, 'target_step_ms': 5.0, 'not_solved_steps': 0,
           'obstacles': 'scan', 'memory_update_ms': figures(5.0),
           'set_and_solve_ms': figures(2.4), 'solver': 'fatrop+compiled',
           'reference': 'RRT* plan', 'goal_distance': 6.49, 'in_reach_median': 0.0,
           'in_reach_max': 18, 'active_median': 0.0, 'active_max': 0, 'contact_steps': 0,
           'timed_out_steps': 0, 'warmup_s': 0.4}
    lines = _footprint_lines([row])
    assert '|  cap |' in lines[2] and ' NO ' not in lines[2]
    [missed] = [line for line in lines if line.startswith('missed:')]
    assert 'the whole step, median 7.600 ms > 5 ms' in missed and '5.000 ms' in missed
    rate = {'frequency': 20.0, 'horizon': 10, 'solver': 'fatrop', 'step': 0.2, 'calls': 240,
            'max_calls': 240, 'reached': False, 'solves': 60, 'holds': 180,
            'solve_ms': figures(1.0), 'hold_ms': figures(0.05), 'all_ms': figures(0.05)}
    assert 'stopped at the cap of 240 calls, short of the goal' in _rate_lines(rate)[-1]
