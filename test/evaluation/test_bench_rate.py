# SPDX-License-Identifier: Apache-2.0
"""mpc_bench's control-rate rows: compute at 20 Hz, the solving and the holding calls apart.

Interpreted functions and a few calls (main's rate_compile and rate_calls): what is checked
is the section's form and its count of solves and holds, not timings.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mpc_local_planner.evaluation.bench import main, SECTIONS
from mpc_local_planner.evaluation.bench_runs import CONTROL_FREQUENCY, STEP

FIGURES = {'median', 'p99', 'max'}


def test_the_rate_section_times_solving_and_holding_calls_apart(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert 'rate' in SECTIONS
    out = tmp_path / 'bench.json'
    calls = 12  # three steps h of four calls
    assert main(['--sections', 'rate', '--out', str(out)],
                rate_compile=False, rate_calls=calls) == 0
    results = json.loads(out.read_text(encoding='utf-8'))
    assert 'horizons' not in results and 'footprint' not in results  # --sections
    rate = results['rate']
    assert rate['frequency'] == CONTROL_FREQUENCY == 20.0 and rate['step'] == STEP
    assert rate['calls'] == calls and rate['solver'] == 'fatrop'  # interpreted
    per_step = round(STEP * CONTROL_FREQUENCY)  # 4: one solve, three holds
    assert rate['solves'] == calls // per_step
    assert rate['holds'] == calls - calls // per_step
    for key in ('solve_ms', 'hold_ms', 'all_ms'):
        assert set(rate[key]) == FIGURES
        assert rate[key]['median'] <= rate[key]['p99'] <= rate[key]['max']
    printed = capsys.readouterr().out
    for row in ('solving (once per step h)', 'holding the verified plan', '| all '):
        assert row in printed
