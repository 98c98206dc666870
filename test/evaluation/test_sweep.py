# SPDX-License-Identifier: Apache-2.0
"""Sweeps: the same runs.csv on a Dask cluster as locally, and a killed sweep resumed.

Pure pursuit on the shipped BARN worlds (known map) keeps every run well under a second: the
executors and the table are under test here, not the controllers.
"""

import csv
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest

from mpc_local_planner.evaluation.evaluate import main
from mpc_local_planner.evaluation.suite_runs import CSV_COLUMNS
from mpc_local_planner.evaluation.sweep import CLUSTER_INSTALL_HINT, RunTable

WORLDS = '0-3'
RUNS = 4
SWEEP = ['--suite', 'barn', '--worlds', WORLDS, '--controllers', 'pure_pursuit']
# measured on the machine as loaded: differ between any two runs
TIMING = ('solve_ms_median', 'solve_ms_max', 'step_ms_median', 'step_ms_max', 'plan_s_max')


def _table(folder: Path) -> list[dict[str, str]]:
    """Return runs.csv's rows in file order, without the timing columns."""
    with open(folder / 'runs.csv', newline='') as stream:
        reader = csv.DictReader(stream)
        assert tuple(reader.fieldnames) == CSV_COLUMNS
        return [{k: v for k, v in row.items() if k not in TIMING} for row in reader]


@pytest.fixture(scope='module')
def reference(tmp_path_factory) -> list[dict[str, str]]:
    """The sweep run uninterrupted in this process: the table the others must give."""
    out = tmp_path_factory.mktemp('reference')
    assert main([*SWEEP, '--out', str(out)]) == 0
    rows = _table(out)
    assert len(rows) == RUNS
    return rows


@pytest.mark.dds
@pytest.mark.parametrize('cluster', ['--scheduler', 'LocalCluster of --jobs'])
def test_a_dask_cluster_gives_the_local_table(reference, tmp_path, cluster) -> None:
    distributed = pytest.importorskip('distributed')
    if cluster == '--scheduler':
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      host='127.0.0.1', dashboard_address=None) as running:
            assert main([*SWEEP, '--out', str(tmp_path), '--executor', 'dask',
                         '--scheduler', running.scheduler_address]) == 0
    else:
        assert main([*SWEEP, '--out', str(tmp_path), '--executor', 'dask', '--jobs', '2']) == 0
    assert _table(tmp_path) == reference


def _rows_written(path: Path) -> int:
    """Return the number of complete rows in a runs.csv being written (0 if none yet)."""
    if not path.is_file():
        return 0
    return max(0, path.read_text().count('\n') - 1)


@pytest.mark.dds
def test_a_killed_sweep_resumed_gives_the_uninterrupted_table(reference, tmp_path,
                                                               capsys) -> None:
    command = [sys.executable, '-m', 'mpc_local_planner.evaluation.evaluate', *SWEEP,
               '--out', str(tmp_path)]
    sweep = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             start_new_session=True)
    try:
        deadline = time.monotonic() + 120.0
        while _rows_written(tmp_path / 'runs.csv') < 1 and sweep.poll() is None:
            assert time.monotonic() < deadline, 'no row written within 120 s'
            time.sleep(0.02)
        os.killpg(sweep.pid, signal.SIGKILL)
    finally:
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
        sweep.wait(timeout=30)
    assert sweep.returncode == -signal.SIGKILL, 'the sweep ended before it was killed'
    kept = _table(tmp_path)
    assert 1 <= len(kept) < RUNS
    capsys.readouterr()
    assert main([*SWEEP, '--out', str(tmp_path), '--resume']) == 0
    assert f'resuming: {len(kept)} of {RUNS} runs' in capsys.readouterr().err
    resumed = _table(tmp_path)
    assert resumed == reference
    assert all(row in resumed for row in kept)  # every run finished before the kill stays
    assert f'| pure_pursuit | {RUNS} | {RUNS} |' in (tmp_path / 'summary.md').read_text()


def test_resume_with_other_settings_is_refused_and_leaves_the_table(tmp_path,
                                                                    capsys) -> None:
    one = ['--suite', 'barn', '--worlds', '0', '--controllers', 'pure_pursuit',
           '--out', str(tmp_path)]
    assert main(one) == 0
    before = (tmp_path / 'runs.csv').read_text()
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main([*one, '--resume', '--v-max', '0.5'])
    assert exit_info.value.code == 2
    message = capsys.readouterr().err
    assert 'cannot resume' in message and 'v_max' in message
    assert (tmp_path / 'runs.csv').read_text() == before
    (tmp_path / 'settings.json').unlink()  # a table from before settings.json: not trusted
    with pytest.raises(SystemExit) as exit_info:
        main([*one, '--resume'])
    assert exit_info.value.code == 2
    assert 'settings.json' in capsys.readouterr().err


def test_resume_drops_a_row_cut_short_and_the_errors(tmp_path) -> None:
    columns = ('world', 'controller', 'stop_reason')
    table = RunTable(tmp_path, columns)
    table.start({'seed': 0})
    table.append({'world': 0, 'controller': 'dwa', 'stop_reason': 'reached'})
    table.append({'world': 1, 'controller': 'dwa', 'stop_reason': 'error: KilledWorker'})
    table.close()
    with open(tmp_path / 'runs.csv', 'a') as stream:
        stream.write('2,dwa,rea')  # the kill came mid-row
    kept = RunTable(tmp_path, columns).earlier_rows(
        {'seed': 0}, keep=lambda row: not row['stop_reason'].startswith('error'))
    assert kept == [{'world': '0', 'controller': 'dwa', 'stop_reason': 'reached'}]


def test_dask_executor_without_dask_says_how_to_install_it(tmp_path, monkeypatch,
                                                           capsys) -> None:
    monkeypatch.setitem(sys.modules, 'distributed', None)  # import distributed fails
    with pytest.raises(SystemExit) as exit_info:
        main([*SWEEP, '--out', str(tmp_path), '--executor', 'dask'])
    assert exit_info.value.code == 2
    message = capsys.readouterr().err
    assert CLUSTER_INSTALL_HINT in message and "pip install '.[cluster]'" in message
    assert message.count('\n') == 1
    assert not (tmp_path / 'runs.csv').exists()
