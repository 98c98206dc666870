# SPDX-License-Identifier: Apache-2.0
"""call_guarded: a call is answered, its error raised, or given up after its timeout."""

from __future__ import annotations

import threading

import pytest

from mpc_local_planner.core.mpc.hang_guard import call_guarded, SolverHang


def test_a_call_returns_its_result_and_raises_its_error() -> None:
    assert call_guarded(lambda a, b: a + b, 60.0, a=2, b=3) == 5

    def fails() -> None:
        raise ValueError('bad input')

    with pytest.raises(ValueError, match='bad input'):
        call_guarded(fails, 60.0)


def test_a_call_that_never_returns_is_given_up_and_the_next_call_runs() -> None:
    release = threading.Event()
    stuck_on = []

    def stuck() -> None:
        stuck_on.append(threading.current_thread())
        release.wait()

    first = call_guarded(threading.current_thread, 60.0)
    assert first is not threading.current_thread()  # made on a worker thread
    try:
        with pytest.raises(SolverHang, match='did not return'):
            call_guarded(stuck, 0.05)
        # the next call is made on another thread: the stuck one is still busy
        assert call_guarded(threading.current_thread, 60.0) is not stuck_on[0]
    finally:
        release.set()
