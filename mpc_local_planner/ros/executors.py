# SPDX-License-Identifier: Apache-2.0
"""Spin an executor until something holds, with a bound (the only way this package waits)."""

from __future__ import annotations

import time
from typing import Callable

from rclpy.executors import Executor

__all__ = ['spin_until']


def spin_until(executor: Executor, condition: Callable[[], bool], *, timeout_sec: float,
               period_sec: float = 0.05) -> bool:
    """Spin executor until condition() holds or timeout_sec wall seconds pass.

    Args:
        executor: the executor to spin (one callback per spin_once).
        condition: checked before the first spin and after each.
        timeout_sec: wall-clock bound.
        period_sec: the longest a single spin_once waits for work.

    Returns:
        condition() at the end.

    """
    deadline = time.monotonic() + timeout_sec
    while not condition():
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            break
        executor.spin_once(timeout_sec=min(period_sec, remaining))
    return condition()
