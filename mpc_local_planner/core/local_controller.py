# SPDX-License-Identifier: Apache-2.0
"""The one interface every local controller implements (nav2_core::Controller's shape).

The controller node and every suite drive a controller only through these five calls, so
what the suites measure is what the node runs, and a new controller needs no adapter:
`set_plan` (a new global plan), `set_obstacles` (what the robot knows now, as sensed, not
inflated), `compute` (the command for the robot's pose and measured twist at time `now`),
`reset` (forget the run: plan, arrival, held inputs) and `set_speed_limit` (Nav2's
speed-limit topic: a cap on |v|, None lifts it).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable, Sequence

import numpy as np

from mpc_local_planner.core.control_output import ControlOutput
from mpc_local_planner.core.obstacles import ConvexPolygon

__all__ = ['LocalController']


@runtime_checkable
class LocalController(Protocol):
    """A local controller: plan and obstacles in, a command with its reason out."""

    def set_plan(self, poses: np.ndarray) -> None:
        """Follow the plan of (M, 3) poses [x, y, theta] from the robot's projection onto it.

        Raises:
            ValueError: if the plan cannot be followed (not finite, too short, too long).

        """

    def set_obstacles(self, obstacles: Sequence[ConvexPolygon]) -> None:
        """Avoid these obstacles (as sensed; the controller grows them by its footprint).

        A controller whose class says ``predicts_motion = True`` (the MPC) may be given
        moving ones too (core/moving_obstacles.py `MovingPolygon`); the others are given
        what the laser shows of them.
        """

    def compute(self, pose: np.ndarray | None, twist: np.ndarray | None,
                now: float) -> ControlOutput:
        """Return the command for pose [x, y, theta] and measured twist [v, omega] at now.

        pose None means there is no usable pose (the answer is a stop with its reason);
        twist None means the base reports no velocity.
        """

    def reset(self) -> None:
        """Forget the run: plan, arrival, held inputs; obstacles and settings stay."""

    def set_speed_limit(self, v_max: float | None) -> None:
        """Cap |v| at v_max (m/s, > 0) from the next compute; None lifts the cap."""
