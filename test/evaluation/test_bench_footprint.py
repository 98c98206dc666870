# SPDX-License-Identifier: Apache-2.0
"""mpc_bench's polygon footprint rows: the Jackal on the paper's box and BARN world 0.

The rows run with interpreted functions (compile_functions=False, main's footprint_compile):
compiling a polygon NLP with gcc takes about a minute per shape, far beyond a unit test;
what is checked here is the rows' form and that they say what they measured, not timings.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.evaluation.bench import FOOTPRINT_HEADER, main
from mpc_local_planner.evaluation.bench_runs import (
    bench_footprint,
    FOOTPRINT_SCENARIOS,
    TARGET_FOOTPRINT_SOLVE_MS,
    TARGET_FOOTPRINT_STEP_MS,
)

ROW_KEYS = {
    'scenario', 'label', 'world', 'footprint', 'horizon', 'solver', 'obstacles', 'reference',
    'max_steps', 'warmup_s', 'target_solve_ms', 'target_step_ms', 'solve_verdict',
    'step_verdict', 'steps', 'solve_ms', 'step_ms', 'reached', 'goal_distance',
    'not_solved_steps', 'timed_out_steps', 'contact_steps', 'in_reach_median', 'active_max',
}
FIGURES = {'median', 'p95', 'max'}


def test_footprint_rows_appear_in_the_json_with_their_keys(tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]
                                                           ) -> None:
    out = tmp_path / 'bench.json'
    assert main(['--quick', '--sections', 'footprint', '--out', str(out)],
                footprint_compile=False, footprint_steps=3) == 0
    results = json.loads(out.read_text(encoding='utf-8'))
    rows = results['footprint']
    assert [r['scenario'] for r in rows] == list(FOOTPRINT_SCENARIOS)
    assert {'paper', 'barn'} <= set(FOOTPRINT_SCENARIOS)  # the two
    assert 'horizons' not in results and 'perception' not in results  # --sections
    assert len(results['machine']['load_average_before']) == 3
    for row in rows:
        assert ROW_KEYS <= set(row)
        assert FIGURES <= set(row['solve_ms']) and FIGURES <= set(row['step_ms'])
        assert row['horizon'] == 10 and row['solver'] == 'fatrop'  # interpreted
        np.testing.assert_allclose(row['footprint'], JACKAL.vertices)
        # the plan is made for the footprint, and the row says so (not the sinusoid)
        assert row['reference'].startswith('RRT* plan for the footprint')
        assert 'RRT*' in row['label']
        assert 1 <= row['steps'] <= row['max_steps'] == 3
        assert row['target_solve_ms'] == TARGET_FOOTPRINT_SOLVE_MS == 2.0
        assert row['target_step_ms'] == TARGET_FOOTPRINT_STEP_MS == 5.0
        assert row['solve_verdict'] == (
            'met' if row['solve_ms']['median'] <= 2.0 else 'MISSED')
        assert row['step_verdict'] == (
            'met' if row['step_ms']['median'] <= 5.0 else 'MISSED')
        assert row['contact_steps'] == 0
    assert {r['scenario']: r['obstacles'] for r in rows} == {
        'paper': 'known', 'barn': 'scan', 'barn_map': 'known'}
    printed = capsys.readouterr().out
    assert FOOTPRINT_HEADER in printed
    for row in rows:
        assert row['label'] in printed


def test_footprint_row_of_an_unknown_scenario_is_refused() -> None:
    with pytest.raises(ValueError, match='unknown footprint scenario'):
        bench_footprint('corridor', 1, compile_functions=False)
