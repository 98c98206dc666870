# SPDX-License-Identifier: Apache-2.0
"""Solver calls that can be given up: a call that never returns must not freeze the robot.

fatrop's inertia correction (`while (regularity != 0)`, the regularisation times 8 each pass)
has no upper bound, and no fatrop or CasADi option sets one: on a singular KKT system a call
with an iteration limit of 100 was seen not to return at all (docs/safety.md, "A solver call
that never returns"). Python cannot interrupt a compiled call, but CasADi releases the GIL
while a Function runs, so the call can be made on another thread and waited for with a
timeout. A call that has not returned by then is abandoned: its thread is left inside the
solver (a daemon, spinning on one core until the process ends), the caller gets
`SolverHang` at once and goes on with another thread. The solver object must not be used
again (its memory, and the stats that `Function.stats()` reads, are the stuck call's): the
NLP rebuilds it (`Nlp.abandon`).

One worker thread per calling thread, made on first use: a solver call costs a hand-over
(tens of microseconds), not a thread's start.
"""

from __future__ import annotations

import queue
import threading
from typing import Any, Callable

__all__ = ['SolverHang', 'call_guarded']


class SolverHang(RuntimeError):
    """A solver call did not return within its time; it was abandoned on its thread."""


class _Job:
    """One call: what to run, and what it returned or raised."""

    def __init__(self, fn: Callable[..., Any], kwargs: dict[str, Any]) -> None:
        self.fn = fn
        self.kwargs = kwargs
        self.done = threading.Event()
        self.result: Any = None
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            self.result = self.fn(**self.kwargs)
        except BaseException as err:  # handed to the caller, which raises it
            self.error = err
        finally:
            self.done.set()


class _Worker:
    """A daemon thread that runs the jobs it is given, one after another."""

    def __init__(self) -> None:
        self.jobs: queue.SimpleQueue[_Job] = queue.SimpleQueue()
        self.thread = threading.Thread(target=self._serve, name='mpc-solver-call', daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while True:
            self.jobs.get().run()


_local = threading.local()


def call_guarded(fn: Callable[..., Any], timeout: float, **kwargs: Any) -> Any:
    """Return fn(**kwargs), run on this thread's worker, or raise SolverHang after timeout.

    Args:
        fn: The call (a CasADi Function: it releases the GIL while it runs, so the
            caller's thread waits while it computes).
        timeout: Seconds to wait for it; after that the worker is left inside the call and
            the next call gets a new one.
        **kwargs: Its arguments.

    Raises:
        SolverHang: if it has not returned within timeout.
        Exception: whatever fn raised.

    """
    worker: _Worker | None = getattr(_local, 'worker', None)
    if worker is None:
        worker = _local.worker = _Worker()
    job = _Job(fn, kwargs)
    worker.jobs.put(job)
    if not job.done.wait(timeout):
        _local.worker = None  # busy for ever, as far as anyone knows
        msg = f'the solver did not return within {timeout:.1f} s; the call was abandoned'
        raise SolverHang(msg)
    if job.error is not None:
        raise job.error
    return job.result
