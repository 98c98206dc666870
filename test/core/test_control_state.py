# SPDX-License-Identifier: Apache-2.0
"""ControlState: the controller's hold, stop and turn as one explicit state, alone."""

from __future__ import annotations

import math

import numpy as np

from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.control_state import ControlState, Event, Mode

PLAN = ControlOutput(np.array([0.2, 0.1]), None, Reason.TRACKING)
STOP = ControlOutput(np.zeros(2), None, Reason.STOP)


def test_a_solved_plan_is_held_for_its_period_and_not_after_or_before() -> None:
    state = ControlState()
    assert state.mode is Mode.IDLE and state.plan() is None
    state.on(Event.SOLVED, now=1.0, output=PLAN)
    assert state.mode is Mode.PLAN and state.plan() is PLAN and state.since == 1.0
    assert state.holding(Mode.PLAN, 1.1, 0.175) is PLAN
    assert state.holding(Mode.PLAN, 1.2, 0.175) is None  # the next step solves
    assert state.holding(Mode.PLAN, 0.9, 0.175) is None  # the clock jumped back
    assert state.holding(Mode.STOP, 1.1, 0.175) is None


def test_a_stop_that_keeps_the_solvers_stop_ends_only_a_plan() -> None:
    state = ControlState()
    state.on(Event.SOLVER_STOP, now=2.0, output=STOP)
    state.on(Event.END_PLAN)
    assert state.mode is Mode.STOP and state.holding(Mode.STOP, 2.1, 0.175) is STOP
    assert state.plan() is None
    state.on(Event.SOLVED, now=2.2, output=PLAN)
    state.on(Event.END_PLAN)
    assert state.mode is Mode.IDLE and state.output is None and state.since == -math.inf


def test_drop_a_turn_and_a_new_plan_leave_nothing_held() -> None:
    for event in (Event.DROP, Event.NEW_PLAN, Event.ROTATE):
        for start in (Event.SOLVED, Event.SOLVER_STOP):
            state = ControlState()
            state.on(start, now=0.0, output=PLAN)
            state.on(event)
            assert state.mode is (Mode.ROTATE if event is Event.ROTATE else Mode.IDLE)
            assert state.output is None and state.plan() is None
            assert state.holding(Mode.PLAN, 0.0, 1.0) is None
            assert state.holding(Mode.STOP, 0.0, 1.0) is None
