# SPDX-License-Identifier: Apache-2.0
"""What the controller answers at each step: the command, and why (`Reason`, an Enum).

`ControlOutput` is every local controller's answer (`LocalController.compute`); `Reason`
says why the command is what it is (its value is the diagnostics' word, its `text` the
words for logs); `Blockage` is `MpcController.path_blockage`'s answer, where the remaining
plan first meets an obstacle.
"""

from __future__ import annotations

from enum import Enum
import math
from typing import NamedTuple

import numpy as np

from mpc_local_planner.core.mpc import MpcSolution

__all__ = ['Blockage', 'ControlOutput', 'Reason']


class Reason(Enum):
    """Why the controller commands what it commands (the value is the diagnostics' word).

    Only TRACKING and CANDIDATE apply an MPC input, ROTATE_TO_HEADING an in-place turn,
    RECOVERY a recovery's motion (or its wait, a zero command) and EVADE a move out of a
    predicted moving obstacle's way;
    every other reason stops the robot: a zero command, or, for a moving robot with
    ControllerSettings.max_decel, the braking command along the last verified plan. Free
    text about the case (what was wrong with a plan, an exception's message) travels
    separately, in `ControlOutput.detail`.
    """

    TRACKING = 'tracking'
    # The input is the proof's shifted candidate, not a fresh solver solution (verified all
    # the same; it runs out after N steps). Mostly the solver failed; rarely it converged to
    # a solution costlier than the candidate.
    CANDIDATE = 'candidate'
    NO_PLAN = 'no_plan'
    NO_ODOM = 'no_odom'
    STALE_ODOM = 'stale_odom'
    INVALID_ODOM = 'invalid_odom'
    INVALID_PLAN = 'invalid_plan'
    GOAL_REACHED = 'goal_reached'
    # Within xy_goal_tolerance of the goal, off its heading: the robot turns in place (Nav2
    # RPP's rotate to heading) instead of the MPC manoeuvring for the last centimetres.
    ROTATE_TO_HEADING = 'rotate_to_heading'
    STOP = 'stop'
    ERROR = 'error'
    # The laser is a source of obstacles and its latest valid scan is older than scan_timeout
    # (malformed scans are dropped, so only bad ones coming also ends here), or none came yet.
    STALE_SCAN = 'stale_scan'
    NO_SCAN = 'no_scan'
    # The map is a source of obstacles and no valid map came yet: what it would show is
    # unknown, as the scan's before the first one.
    NO_MAP = 'no_map'
    # Odometry is there but no pose in the plan's frame: a localizer is expected and none
    # (usable) came, or tf2 has no transform from the plan's frame to the robot's.
    NO_LOCALIZATION = 'no_localization'
    # The robot made no progress and a recovery runs (core/recoveries.py): it backs out along
    # its own trail, spins in place or waits for a new plan; ControlOutput.detail says which.
    RECOVERY = 'recovery'
    # The MPC found no verified plan and a moving obstacle is predicted to reach the robot
    # where it would stop: it moves out of the way along a checked move (core/evasion.py).
    EVADE = 'evade'

    @property
    def text(self) -> str:
        """Say it in words, for logs and DiagnosticStatus.message."""
        return _REASON_TEXT[self]

    @property
    def applies_input(self) -> bool:
        """Whether the command is an input (the MPC's, or the turn to the goal heading)."""
        return self in (Reason.TRACKING, Reason.CANDIDATE, Reason.ROTATE_TO_HEADING,
                        Reason.RECOVERY, Reason.EVADE)


_REASON_TEXT = {
    Reason.TRACKING: 'tracking',
    Reason.CANDIDATE: 'applying the shifted candidate (no cheaper verified solver solution)',
    Reason.NO_PLAN: 'no plan yet',
    Reason.NO_ODOM: 'no odometry yet',
    Reason.STALE_ODOM: 'odometry is stale',
    Reason.INVALID_ODOM: 'invalid odometry',
    Reason.INVALID_PLAN: 'invalid plan',
    Reason.GOAL_REACHED: 'goal reached',
    Reason.ROTATE_TO_HEADING: 'at the goal position, turning in place to the goal heading',
    Reason.STOP: 'no feasible input, stopping',
    Reason.ERROR: 'error',
    Reason.STALE_SCAN: 'scan is stale',
    Reason.NO_SCAN: 'no scan yet',
    Reason.NO_MAP: 'no valid map yet',
    Reason.NO_LOCALIZATION: "no pose in the plan's frame",
    Reason.RECOVERY: 'no progress, recovering',
    Reason.EVADE: 'no feasible input, moving out of the way of a moving obstacle',
}


class Blockage(NamedTuple):
    """Where the remaining plan first meets an obstacle the controller knows.

    Attributes:
        blocked: whether the plan, from the robot's projection on, meets a grown obstacle.
        at: arc length (m) along the plan from the robot's projection to the first blocked
            point; NaN when the plan is clear (or there is no plan or state).

    """

    blocked: bool = False
    at: float = math.nan


class ControlOutput(NamedTuple):
    """What to command now, and why.

    Attributes:
        u: (2,) input (v, omega) within the model's bounds; zero unless reason.applies_input.
        solution: the MPC's solution when it ran, else None.
        reason: why the command is what it is.
        detail: free text about the case ('' when the reason says it all), e.g. what is
            wrong with a refused plan, or an exception's message.
        fresh: the MPC solved at this call; False between solves (control_frequency above
            1 / step), where u is the input the last verified plan gives for now, or where a
            stop brakes along it (u then need not be zero: see `Brake`).
        progress: how far along its plan the controller is, in [0, 1], for a controller
            without an MPC solution (a path follower: its projection's arc length over the
            plan's length); NaN where it does not say (the MPCs' is solution.s).
        compute_time_s: the controller's own time for this answer, seconds, for a
            controller without an MPC solution (the MPCs' is solution.solve_time_s); NaN
            where it does not say.

    """

    u: np.ndarray
    solution: MpcSolution | None
    reason: Reason
    detail: str = ''
    fresh: bool = True
    progress: float = math.nan
    compute_time_s: float = math.nan

    @property
    def message(self) -> str:
        """Return the reason in words, followed by ': detail' when there is one."""
        return f'{self.reason.text}: {self.detail}' if self.detail else self.reason.text
