# SPDX-License-Identifier: Apache-2.0
"""Velocity commands on their way to a plant's motors: latency, saturation, safe stop.

Every plant (the kinematic `base.Base`, the physics plant) receives its commands through a
`CommandQueue`, so a command reaches either one at the same instant and in the same form.
"""

from __future__ import annotations

from collections import deque
from typing import Sequence, TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mpc_local_planner.core.models import Unicycle

__all__ = ['CommandQueue']

# Rounding slack when comparing arrival times with the plant's time (s).
_EPS = 1e-9


class CommandQueue:
    """The commands sent to a plant and not yet in force, and the one in force.

    A command sent at t arrives at t + latency, saturated to the model's bounds (the motor
    drivers' saturation). A command that is not two finite numbers is a broken sender: it is
    taken as zero (stop), as the simulator node does. Model and latency are passed with each
    command because the simulator node may change them while others are on their way.
    Before any command has arrived the one in force is zero.
    """

    def __init__(self) -> None:
        self._pending: deque[tuple[float, np.ndarray]] = deque()
        self._applied = np.zeros(2)

    def send(self, u: Sequence[float], sent: float, model: Unicycle, latency: float) -> None:
        """Queue the command u sent at time sent: it arrives at sent + latency.

        Args:
            u: (v, omega); a longer sequence is cut to its first two entries.
            sent: When it was sent, seconds (the plant's time).
            model: The unicycle whose bounds saturate it.
            latency: The reality's command latency, seconds.

        """
        u = np.asarray(u, dtype=float).reshape(-1)[:2]
        if len(u) != 2 or not np.all(np.isfinite(u)):
            u = np.zeros(2)
        self._pending.append((float(sent) + latency, model.saturate(u)))

    @property
    def next_arrival(self) -> float | None:
        """When the earliest command on its way arrives (None: none is on its way)."""
        return self._pending[0][0] if self._pending else None

    @property
    def applied(self) -> np.ndarray:
        """The command in force: the latest one that has arrived (zero before any)."""
        return self._applied.copy()

    def take(self, now: float) -> list[tuple[float, np.ndarray]]:
        """Make the latest command that has arrived by now the one in force.

        Returns:
            The commands that arrived since the last call, in order, as (arrival, u).

        """
        arrived = []
        while self._pending and self._pending[0][0] <= now + _EPS:
            arrived.append(self._pending.popleft())
        if arrived:
            self._applied = arrived[-1][1]
        return arrived
