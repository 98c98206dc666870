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

"""Run many independent closed-loop runs somewhere, and keep every finished one on disk.

A sweep (hundreds of worlds x controllers) takes hours, so two things matter beyond the runs
themselves: where they run, and what survives when the sweep is stopped.

Where: `run_tasks` hands the tasks to this process (``jobs <= 1``), to local worker processes
(`concurrent.futures.ProcessPoolExecutor`) or to a Dask cluster (``distributed``: a
`LocalCluster`, or the scheduler at an address that workers on any number of machines joined),
and yields ``(index, result)`` as runs finish. The caller assembles by index, so completion
order, which differs between executors and between runs, never reaches the table. A worker
process keeps its module-level caches (the MPCs and their compiled NLPs) across the tasks it
gets, with either pool; a Dask worker must run one task at a time (``--nthreads 1``), as
those caches are not shared between threads.

What survives: `RunTable` appends each finished row to the CSV at once (flushed and synced),
records the settings that determine the rows beside it (``settings.json``), and on resume
keeps the rows already there and refuses a table made with other settings, so rows from
different settings never mix.
"""

from __future__ import annotations

from concurrent.futures import as_completed, Future, ProcessPoolExecutor
import csv
import json
import multiprocessing
import os
from pathlib import Path
import sys
from typing import Any, Callable, Iterable, Iterator, Sequence, TypeVar

__all__ = [
    'CLUSTER_INSTALL_HINT',
    'EXECUTORS',
    'ExecutorUnavailable',
    'RunTable',
    'SettingsMismatch',
    'run_tasks',
]

EXECUTORS = ('local', 'dask')
CLUSTER_INSTALL_HINT = "--executor dask needs Dask: pip install '.[cluster]' (dask[distributed])"

T = TypeVar('T')
R = TypeVar('R')
Outcome = Any  # a task's result, or the exception it raised in a worker


class ExecutorUnavailable(RuntimeError):
    """The chosen executor's package is not installed."""


class SettingsMismatch(RuntimeError):
    """A resumed table was written with other settings."""


# ----------------------------------------------------------------------------- executors


def run_tasks(fn: Callable[[T], R], tasks: Sequence[T], *, executor: str = 'local',
              jobs: int = 1, scheduler: str | None = None) -> Iterator[tuple[int, Outcome]]:
    """Run ``fn(task)`` for every task; yield ``(index in tasks, result)`` as each finishes.

    ``fn`` and the tasks must pickle by reference (module-level, imported by module name) for
    the worker processes. In a worker, an exception is yielded as the result (one failed run
    does not end the sweep); with ``jobs <= 1`` and the local executor it propagates.

    Args:
        fn: the task function.
        tasks: the tasks, in the order their indices refer to.
        executor: 'local' (this process, or ``jobs`` processes) or 'dask'.
        jobs: local processes, or the worker processes of the Dask LocalCluster started
            when ``scheduler`` is None.
        scheduler: a Dask scheduler's address (tcp://host:8786) to run on its workers.

    Raises:
        ExecutorUnavailable: for 'dask' when distributed cannot be imported.
        ValueError: for an unknown executor.

    """
    if executor == 'dask':
        return _run_dask(fn, tasks, jobs=jobs, scheduler=scheduler)
    if executor != 'local':
        msg = f'unknown executor {executor!r}; choose from {EXECUTORS}'
        raise ValueError(msg)
    if jobs <= 1:
        return ((index, fn(task)) for index, task in enumerate(tasks))
    return _run_pool(fn, tasks, jobs)


def import_distributed() -> Any:
    """Return the ``distributed`` module.

    Raises:
        ExecutorUnavailable: if it is not installed (the package's ``cluster`` extra).

    """
    try:
        import distributed
    except ImportError as err:
        raise ExecutorUnavailable(CLUSTER_INSTALL_HINT) from err
    return distributed


def _outcomes(futures: dict[Any, int], completed: Callable[[Iterable[Any]], Iterable[Any]]
              ) -> Iterator[tuple[int, Outcome]]:
    """Yield ``(index, result or exception)`` of futures in the order they complete."""
    for future in completed(futures):
        try:
            result = future.result()
        except Exception as err:  # a failed run is a row, not the end of the sweep
            result = err
        yield futures[future], result


def _run_pool(fn: Callable[[T], R], tasks: Sequence[T], jobs: int
              ) -> Iterator[tuple[int, Outcome]]:
    context = multiprocessing.get_context('spawn')
    with ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
        futures: dict[Future, int] = {pool.submit(fn, task): i for i, task in enumerate(tasks)}
        yield from _outcomes(futures, as_completed)


def _run_dask(fn: Callable[[T], R], tasks: Sequence[T], *, jobs: int, scheduler: str | None
              ) -> Iterator[tuple[int, Outcome]]:
    distributed = import_distributed()  # here, not in the generator: fail before the sweep
    return _dask_outcomes(distributed, fn, tasks, jobs=jobs, scheduler=scheduler)


def _dask_outcomes(distributed: Any, fn: Callable[[T], R], tasks: Sequence[T], *, jobs: int,
                   scheduler: str | None) -> Iterator[tuple[int, Outcome]]:
    cluster = None
    if scheduler is None:
        # one single-threaded process per job, on loopback, no dashboard (no extra port)
        cluster = distributed.LocalCluster(
            n_workers=max(1, jobs), threads_per_worker=1, processes=True, host='127.0.0.1',
            dashboard_address=None)
        scheduler = cluster.scheduler_address
    try:
        with distributed.Client(scheduler) as client:
            _warn_threaded_workers(client)
            # pure=False: each run is its own task even if two tasks compare equal
            futures = {client.submit(fn, task, pure=False, key=f'run-{i}'): i
                       for i, task in enumerate(tasks)}
            yield from _outcomes(futures, distributed.as_completed)
    finally:
        if cluster is not None:
            cluster.close()


def _warn_threaded_workers(client: Any) -> None:
    """Say so when a worker runs tasks in threads: the per-process MPC caches are not shared."""
    workers = client.scheduler_info().get('workers', {})
    threaded = [address for address, info in workers.items() if info.get('nthreads', 1) > 1]
    if threaded:
        print(f'warning: Dask workers {threaded[:3]} run several tasks at once in threads; '
              'start them with --nthreads 1 (and --nworkers N for N cores)',
              file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------- the table


class RunTable:
    """A CSV of runs that grows one flushed row per finished run, resumable.

    ``folder/runs.csv`` holds the rows, ``folder/settings.json`` what made them.

    Args:
        folder: the output folder (created).
        columns: the CSV's columns.
        key: a row's identity (the run it is of); used to skip finished runs on resume.

    """

    def __init__(self, folder: Path, columns: Sequence[str],
                 key: Callable[[dict[str, Any]], Any]) -> None:
        self.folder = Path(folder)
        self.columns = tuple(columns)
        self.key = key
        self.csv_path = self.folder / 'runs.csv'
        self.settings_path = self.folder / 'settings.json'
        self._stream: Any = None
        self._writer: csv.DictWriter | None = None

    def start(self, settings: dict[str, Any], *, resume: bool,
              keep: Callable[[dict[str, Any]], bool] = lambda row: True
              ) -> list[dict[str, Any]]:
        """Open the table for appending; return the rows kept from an earlier sweep.

        Without ``resume`` the table starts empty (an existing one is overwritten). With it,
        the rows of an earlier sweep with the same settings for which ``keep`` is true are
        kept (a row cut off by a kill is dropped); none if there is no earlier table.

        Raises:
            SettingsMismatch: if the earlier table's settings differ or are missing.

        """
        self.folder.mkdir(parents=True, exist_ok=True)
        settings = json.loads(json.dumps(settings))  # as it reads back: lists, not tuples
        rows = self._earlier_rows(settings) if resume else []
        rows = [row for row in rows if keep(row)]
        self.settings_path.write_text(json.dumps(settings, indent=1, sort_keys=True) + '\n',
                                      encoding='utf-8')
        self._stream = open(self.csv_path, 'w', newline='', encoding='utf-8')
        self._writer = csv.DictWriter(self._stream, fieldnames=self.columns)
        self._writer.writeheader()
        self._writer.writerows(rows)
        self._sync()
        return rows

    def append(self, row: dict[str, Any]) -> None:
        """Write one finished run's row to disk now."""
        assert self._writer is not None, 'start() the table first'
        self._writer.writerow(row)
        self._sync()

    def finish(self, rows: Sequence[dict[str, Any]]) -> None:
        """Rewrite the table with all its rows in their final order, and close it."""
        self.close()
        tmp = self.csv_path.with_suffix('.csv.tmp')
        with open(tmp, 'w', newline='', encoding='utf-8') as stream:
            writer = csv.DictWriter(stream, fieldnames=self.columns)
            writer.writeheader()
            writer.writerows(rows)
        os.replace(tmp, self.csv_path)  # a kill now leaves the old table or the new, whole

    def close(self) -> None:
        """Close the appending stream (rows written so far stay)."""
        if self._stream is not None:
            self._stream.close()
            self._stream = self._writer = None

    def _sync(self) -> None:
        self._stream.flush()
        os.fsync(self._stream.fileno())

    def _earlier_rows(self, settings: dict[str, Any]) -> list[dict[str, Any]]:
        """Return the rows of the earlier sweep in the folder, checked against its settings."""
        if not self.csv_path.is_file():
            return []
        if not self.settings_path.is_file():
            msg = (f'cannot resume: {self.csv_path} has no {self.settings_path.name} beside '
                   'it (written before --resume existed?); run without --resume to start over')
            raise SettingsMismatch(msg)
        earlier = json.loads(self.settings_path.read_text(encoding='utf-8'))
        differ = sorted(k for k in set(earlier) | set(settings)
                        if earlier.get(k) != settings.get(k))
        if differ:
            shown = '; '.join(f'{k}: {earlier.get(k)!r} there, {settings.get(k)!r} now'
                              for k in differ[:4])
            msg = (f'cannot resume: {self.folder} holds runs with other settings ({shown}); '
                   'use another --out or the same arguments, or drop --resume to overwrite')
            raise SettingsMismatch(msg)
        return _read_complete_rows(self.csv_path, self.columns)


def _read_complete_rows(path: Path, columns: Sequence[str]) -> list[dict[str, Any]]:
    """Return the rows of a CSV, without a last line a kill cut short."""
    text = path.read_text(encoding='utf-8')
    if not text.endswith('\n'):
        text = text[:text.rfind('\n') + 1]
    reader = csv.DictReader(text.splitlines(keepends=True))
    if reader.fieldnames is not None and tuple(reader.fieldnames) != tuple(columns):
        msg = f'cannot resume: {path} has other columns than this version writes'
        raise SettingsMismatch(msg)
    return [row for row in reader if None not in row.values() and None not in row]
