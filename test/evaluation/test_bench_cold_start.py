# SPDX-License-Identifier: Apache-2.0
"""mpc_bench's cold_start section: the first BARN run from an empty compile cache, then warm.

The test runs the section's form on the DWA (no NLP to compile: seconds, not minutes); what is
checked is that it runs the command twice with a temporary cache and reports both, not timings.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mpc_local_planner.evaluation.bench import main
from mpc_local_planner.evaluation.bench_runs import COLD_START_ARGS, TARGET_COLD_START_S


def test_cold_start_section_reports_cold_and_warm(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str],
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    own_cache = tmp_path / 'own_cache'
    monkeypatch.setenv('MPC_LOCAL_PLANNER_CACHE', str(own_cache))
    out = tmp_path / 'bench.json'
    assert main(['--quick', '--sections', 'cold_start', '--out', str(out)],
                cold_start_controllers='dwa') == 0
    result = json.loads(out.read_text(encoding='utf-8'))['cold_start']
    assert result['repeats'] == 1
    assert result['target_cold_s'] == TARGET_COLD_START_S
    assert result['command'].endswith('--controllers dwa')
    assert ' '.join(COLD_START_ARGS) in result['command']
    for key in ('cold_s', 'warm_s'):
        assert set(result[key]) == {'median', 'p95', 'max'}
        assert result[key]['median'] > 0.0
    assert result['success']
    assert result['libraries_after_cold'] == [0]  # the DWA compiles nothing
    assert not own_cache.exists()  # a temporary cache folder, not the caller's
    printed = capsys.readouterr().out
    assert 'cold (empty cache)' in printed and 'warm (cache present)' in printed
