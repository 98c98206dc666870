# SPDX-License-Identifier: Apache-2.0
"""GoalChecker: Nav2's SimpleGoalChecker, alone."""

from __future__ import annotations

import math

import numpy as np

from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.goal_checker import GoalChecker

GOAL = np.array([2.0, 1.0, 0.5])


def test_arrival_needs_both_tolerances_and_the_heading_wraps() -> None:
    checker = GoalChecker(ControllerSettings(xy_goal_tolerance=0.1, yaw_goal_tolerance=0.15))
    assert not checker.is_goal_reached(GOAL + [0.2, 0.0, 0.0], GOAL, np.zeros(2))
    assert not checker.is_goal_reached(GOAL + [0.05, 0.0, 0.3], GOAL, None)
    assert checker.is_goal_reached(GOAL + [0.05, 0.0, 2 * math.pi + 0.1], GOAL)
    np.testing.assert_allclose(GoalChecker.errors(GOAL + [0.3, 0.4, -0.2], GOAL), (0.5, 0.2))


def test_stateful_the_position_once_met_stays_met_until_reset() -> None:
    checker = GoalChecker(ControllerSettings(xy_goal_tolerance=0.1, yaw_goal_tolerance=0.15))
    assert checker.check(GOAL + [0.08, 0.0, 1.0], GOAL) == (True, False)
    assert checker.position_met and not checker.arrived
    # noise carries the position out: still met, only the heading is left
    assert checker.check(GOAL + [0.3, 0.0, 1.0], GOAL) == (True, False)
    assert checker.check(GOAL + [0.3, 0.0, 0.1], GOAL) == (True, True)
    assert checker.arrived
    checker.reset()
    assert not checker.position_met and not checker.arrived
    assert checker.check(GOAL + [0.3, 0.0, 0.1], GOAL) == (False, False)


def test_not_stateful_each_check_judges_the_pose_afresh() -> None:
    checker = GoalChecker(ControllerSettings(stateful=False))
    assert checker.check(GOAL + [0.05, 0.0, 1.0], GOAL) == (True, False)
    assert checker.check(GOAL + [0.3, 0.0, 0.0], GOAL) == (False, False)
    assert checker.check(GOAL, GOAL) == (True, True)
    assert not checker.position_met and not checker.arrived


def test_new_settings_apply_from_the_next_check() -> None:
    checker = GoalChecker()
    assert not checker.is_goal_reached(GOAL + [0.2, 0.0, 0.0], GOAL)
    checker.settings = ControllerSettings(xy_goal_tolerance=0.25)
    assert checker.is_goal_reached(GOAL + [0.2, 0.0, 0.0], GOAL)
