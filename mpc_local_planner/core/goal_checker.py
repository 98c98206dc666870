# SPDX-License-Identifier: Apache-2.0
"""`GoalChecker`: whether the robot has arrived, in Nav2's SimpleGoalChecker's shape.

`is_goal_reached(pose, goal, twist)` and `reset()` as nav2_core::GoalChecker has them, with
the stateful xy latch of SimpleGoalChecker: once the position tolerance is met it stays met
until `reset` (a new plan), so that odometry noise during the final in-place turn does not
send the robot back; and arrival itself stays (`arrived`), so that the controller commands
zero after it whatever the measured pose does. The tolerances and the rule are
ControllerSettings' (`goal_check`), the one definition of arrival that analyze_bag judges
recordings with too.
"""

from __future__ import annotations

import numpy as np

from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.paths import wrap_angle

__all__ = ['GoalChecker']


class GoalChecker:
    """Nav2's SimpleGoalChecker: xy and yaw tolerances, the xy latch when stateful.

    Args:
        settings: xy_goal_tolerance, yaw_goal_tolerance and stateful (read at every check,
            so a new value applies from the next one).

    """

    def __init__(self, settings: ControllerSettings | None = None) -> None:
        self.settings = settings or ControllerSettings()
        self._position_met = False
        self._arrived = False

    @property
    def arrived(self) -> bool:
        """The robot arrived since the last reset (kept only when stateful)."""
        return self._arrived

    @property
    def position_met(self) -> bool:
        """The position tolerance was met since the last reset (kept only when stateful)."""
        return self._position_met

    def reset(self) -> None:
        """Forget the latches: a new goal is judged afresh."""
        self._position_met = self._arrived = False

    @staticmethod
    def errors(pose: np.ndarray, goal: np.ndarray) -> tuple[float, float]:
        """Return (distance, |wrapped heading error|) of pose [x, y, yaw] to goal."""
        position = float(np.hypot(pose[0] - goal[0], pose[1] - goal[1]))
        heading = abs(float(wrap_angle(pose[2] - goal[2])))
        return position, heading

    def check(self, pose: np.ndarray, goal: np.ndarray) -> tuple[bool, bool]:
        """Return (position met, arrived) for pose and goal, and latch both when stateful.

        The position is met within xy_goal_tolerance of the goal's position (or, stateful,
        since it was once), and the robot has arrived when, the position met, its heading is
        within yaw_goal_tolerance.
        """
        position, heading = self.errors(pose, goal)
        settings = self.settings
        position_met, arrived = settings.goal_check(position, heading,
                                                    position_met=self._position_met)
        if settings.stateful:
            self._position_met, self._arrived = position_met, arrived
        return position_met, arrived

    def is_goal_reached(self, pose: np.ndarray, goal: np.ndarray,
                        twist: np.ndarray | None = None) -> bool:
        """Say whether pose has arrived at goal (twist: unused, as by SimpleGoalChecker)."""
        return self.check(pose, goal)[1]
