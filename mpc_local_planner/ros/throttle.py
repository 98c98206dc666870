# SPDX-License-Identifier: Apache-2.0
"""Log a problem on an input channel once, then at most every period while it lasts."""

from __future__ import annotations

import time
from typing import Callable

__all__ = ['ERROR_THROTTLE_S', 'ProblemThrottle', 'steady_clock']

# Seconds between two error logs of an input problem that persists (the nodes' default).
ERROR_THROTTLE_S = 2.0


def steady_clock() -> float:
    """Return the throttles' default time in seconds, from a steady clock.

    ProblemThrottle looks it up at each report, so a test can put every node's throttle on
    a clock it controls.
    """
    return time.monotonic()


class ProblemThrottle:
    """Say when to log a problem on an input channel ('odom', 'plan', ...).

    rclpy's own ``throttle_duration_sec`` keys on the call site and never resets, so a
    second bad episode right after a good message would go unreported; this one resets when
    the channel is valid again. The clock is a steady one by default (a log throttle has no
    business following simulated time).

    Args:
        period: seconds between two reports of a problem that persists.
        clock: returns seconds; ``steady_clock`` (time.monotonic) by default.

    """

    def __init__(self, period: float = 2.0, *,
                 clock: Callable[[], float] | None = None) -> None:
        self.period = float(period)
        self._clock = clock
        self._last: dict[str, float] = {}

    def report(self, channel: str) -> bool:
        """Note a problem on channel; return True if it should be logged now."""
        now = self._clock() if self._clock is not None else steady_clock()
        last = self._last.get(channel)
        if last is not None and now - last < self.period:
            return False
        self._last[channel] = now
        return True

    def resolve(self, channel: str) -> bool:
        """Note that channel is valid again; return True if it had a problem."""
        return self._last.pop(channel, None) is not None
