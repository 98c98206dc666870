# SPDX-License-Identifier: Apache-2.0
"""Run many independent closed-loop runs somewhere, and keep every finished one on disk.

A sweep (hundreds of worlds x controllers) takes hours, so two things matter beyond the runs
themselves: where they run, and what survives when the sweep is stopped.

Where: `open_executor` hands the tasks to this process (``jobs <= 1``), to local worker
processes (`concurrent.futures.ProcessPoolExecutor`) or to a Dask cluster (``distributed``: a
`LocalCluster`, or the scheduler at an address that workers on any number of machines
joined), and yields ``(index, result)`` as runs finish. The caller assembles by index, so
completion order, which differs between executors and between runs, never reaches the
table. A worker process keeps its module-level caches (the MPCs and their compiled NLPs)
across the tasks it gets, with either pool; a Dask worker must run one task at a time
(``--nthreads 1``), as those caches are not shared between threads.

What survives: `RunTable` appends each finished row to the CSV at once (flushed and synced),
records the settings that determine the rows beside it (``settings.json``), and on resume
keeps the rows already there and refuses a table made with other settings, so rows from
different settings never mix.
"""

from __future__ import annotations

from concurrent.futures import as_completed, ProcessPoolExecutor
from contextlib import contextmanager, ExitStack
import csv
import json
import multiprocessing
import os
from pathlib import Path
import sys
from typing import Any, Callable, Iterable, Iterator, Sequence, TypeVar
import uuid

from mpc_local_planner.process_ties import tie_to_parent

__all__ = [
    'CLUSTER_INSTALL_HINT',
    'EXECUTORS',
    'ExecutorUnavailable',
    'import_distributed',
    'open_executor',
    'Runner',
    'RunTable',
    'SettingsMismatch',
]

EXECUTORS = ('local', 'dask')
CLUSTER_INSTALL_HINT = "--executor dask needs Dask: pip install '.[cluster]' (dask[distributed])"

T = TypeVar('T')
R = TypeVar('R')
Outcome = Any  # a task's result, or the exception it raised in a worker
CONNECT_TIMEOUT = '30s'  # to reach a --scheduler


class ExecutorUnavailable(RuntimeError):
    """The chosen executor's package is not installed."""


class SettingsMismatch(RuntimeError):
    """A resumed table was written with other settings."""


# ----------------------------------------------------------------------------- executors


Runner = Callable[[Callable[[T], R], Sequence[T]], Iterator[tuple[int, Outcome]]]


@contextmanager
def open_executor(executor: str = 'local', *, jobs: int = 1,
                  scheduler: str | None = None) -> Iterator[Runner]:
    """Start (or connect to) the executor; give a runner of tasks on it, stopped at the end.

    The runner, ``run(fn, tasks)``, yields ``(index in tasks, result)`` as each task
    finishes. ``fn`` and the tasks must pickle by reference (module-level, imported by module
    name) for the worker processes. In a worker, an exception is yielded as the result (one
    failed run does not end the sweep); in this process (local, ``jobs <= 1``) it propagates.

    Args:
        executor: 'local' (this process, or ``jobs`` processes) or 'dask'.
        jobs: local processes, or the worker processes of the Dask LocalCluster started
            when ``scheduler`` is None.
        scheduler: a Dask scheduler's address (tcp://host:8786) to run on its workers.

    Raises:
        ExecutorUnavailable: for 'dask' when distributed is not installed or the scheduler
            cannot be reached.
        ValueError: for an unknown executor.

    """
    if executor == 'dask':
        with _dask(jobs=jobs, scheduler=scheduler) as run:
            yield run
    elif executor != 'local':
        msg = f'unknown executor {executor!r}; choose from {EXECUTORS}'
        raise ValueError(msg)
    elif jobs <= 1:
        yield lambda fn, tasks: ((index, fn(task)) for index, task in enumerate(tasks))
    else:
        context = multiprocessing.get_context('spawn')
        # a worker ends with this process, even one killed outright (process_ties)
        with ProcessPoolExecutor(max_workers=jobs, mp_context=context,
                                 initializer=tie_to_parent) as pool:
            yield lambda fn, tasks: _outcomes(
                {pool.submit(fn, task): i for i, task in enumerate(tasks)}, as_completed)


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


@contextmanager
def _dask(*, jobs: int, scheduler: str | None) -> Iterator[Runner]:
    """Connect a Dask client to the scheduler, or to a LocalCluster of ``jobs`` processes."""
    distributed = import_distributed()
    with ExitStack() as stack:
        if scheduler is None:
            # one single-threaded process per job, on loopback, no dashboard (no extra port)
            cluster = stack.enter_context(distributed.LocalCluster(
                n_workers=max(1, jobs), threads_per_worker=1, processes=True,
                host='127.0.0.1', dashboard_address=None))
            scheduler = cluster.scheduler_address
        try:
            client = stack.enter_context(distributed.Client(scheduler, timeout=CONNECT_TIMEOUT))
        except OSError as err:  # includes the connection's TimeoutError
            msg = f'cannot reach the Dask scheduler at {scheduler}: {err}'
            raise ExecutorUnavailable(msg) from err
        _warn_threaded_workers(client)
        # keys: this sweep's own (a scheduler may serve several), readable on a dashboard
        sweep = uuid.uuid4().hex[:8]

        def run(fn: Callable[[T], R], tasks: Sequence[T]) -> Iterator[tuple[int, Outcome]]:
            futures = {client.submit(fn, task, pure=False, key=f'run-{sweep}-{i}'): i
                       for i, task in enumerate(tasks)}
            return _outcomes(futures, distributed.as_completed)

        yield run


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

    """

    def __init__(self, folder: Path, columns: Sequence[str]) -> None:
        self.folder = Path(folder)
        self.columns = tuple(columns)
        self.csv_path = self.folder / 'runs.csv'
        self.settings_path = self.folder / 'settings.json'
        self._stream: Any = None
        self._writer: csv.DictWriter | None = None

    def earlier_rows(self, settings: dict[str, Any],
                     keep: Callable[[dict[str, Any]], bool] = lambda row: True
                     ) -> list[dict[str, Any]]:
        """Return the rows of an earlier sweep in the folder to keep on resume; writes nothing.

        Those with the same settings for which ``keep`` is true (a row cut off by a kill is
        dropped); none if the folder holds no table.

        Raises:
            SettingsMismatch: if the earlier table's settings differ or are missing.

        """
        if not self.csv_path.is_file():
            return []
        if not self.settings_path.is_file():
            msg = (f'cannot resume: {self.csv_path} has no {self.settings_path.name} beside '
                   'it (written before --resume existed?); run without --resume to start over')
            raise SettingsMismatch(msg)
        earlier = json.loads(self.settings_path.read_text(encoding='utf-8'))
        settings = _as_json(settings)
        differ = sorted(k for k in set(earlier) | set(settings)
                        if earlier.get(k) != settings.get(k))
        if differ:
            shown = '; '.join(f'{k}: {earlier.get(k)!r} there, {settings.get(k)!r} now'
                              for k in differ[:4])
            msg = (f'cannot resume: {self.folder} holds runs with other settings ({shown}); '
                   'use another --out or the same arguments, or drop --resume to overwrite')
            raise SettingsMismatch(msg)
        return [row for row in _read_complete_rows(self.csv_path, self.columns) if keep(row)]

    def start(self, settings: dict[str, Any], rows: Sequence[dict[str, Any]] = ()) -> None:
        """Write the settings and a table of ``rows`` (kept ones, or none), open to append.

        An earlier table in the folder is replaced.
        """
        self.folder.mkdir(parents=True, exist_ok=True)
        self.settings_path.write_text(
            json.dumps(_as_json(settings), indent=1, sort_keys=True) + '\n', encoding='utf-8')
        self._write_whole(rows)  # a kill while it is written leaves the earlier rows
        self._stream = open(self.csv_path, 'a', newline='', encoding='utf-8')
        self._writer = csv.DictWriter(self._stream, fieldnames=self.columns)

    def append(self, row: dict[str, Any]) -> None:
        """Write one finished run's row to disk now."""
        assert self._writer is not None, 'start() the table first'
        self._writer.writerow(row)
        self._sync()

    def finish(self, rows: Sequence[dict[str, Any]]) -> None:
        """Rewrite the table with all its rows in their final order, and close it."""
        self.close()
        self._write_whole(rows)

    def close(self) -> None:
        """Close the appending stream (rows written so far stay)."""
        if self._stream is not None:
            self._stream.close()
            self._stream = self._writer = None

    def _write_whole(self, rows: Sequence[dict[str, Any]]) -> None:
        """Replace the table by one of these rows at once: a kill leaves the old or the new."""
        tmp = self.csv_path.with_suffix('.csv.tmp')
        with open(tmp, 'w', newline='', encoding='utf-8') as stream:
            writer = csv.DictWriter(stream, fieldnames=self.columns)
            writer.writeheader()
            writer.writerows(rows)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(tmp, self.csv_path)

    def _sync(self) -> None:
        self._stream.flush()
        os.fsync(self._stream.fileno())


def _as_json(settings: dict[str, Any]) -> dict[str, Any]:
    """Return the settings as settings.json reads back (lists, not tuples)."""
    return json.loads(json.dumps(settings))


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
