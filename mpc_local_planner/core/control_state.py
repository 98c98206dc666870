# SPDX-License-Identifier: Apache-2.0
"""`ControlState`: what `MpcController`'s last step left in force, as one explicit state.

A verified plan's input holds until the next MPC step's instant (control_frequency above
1 / h); so does the solver's stop when it found no verified input; an in-place turn to the
goal heading is a state too. `Mode` names them and `ControlState.on` holds every
transition, so the rules between calls read in one place. Braking is not a mode: it belongs
to the stop commands of any mode (`Brake`), started from the plan in force; arrival is the
goal checker's (`GoalChecker.arrived`).
"""

from __future__ import annotations

from enum import Enum
import math

from mpc_local_planner.core.control_output import ControlOutput

__all__ = ['ControlState', 'Event', 'Mode']


class Mode(Enum):
    """What is in force between two control calls."""

    IDLE = 'idle'  # nothing: the next call solves (or stops)
    PLAN = 'plan'  # a verified plan's input, until the next step's instant
    STOP = 'stop'  # the solver found no verified input: stopping until the next step's instant
    ROTATE = 'rotate'  # turning in place to the goal heading


class Event(Enum):
    """What happens to the controller between or within its calls."""

    NEW_PLAN = 'new plan'  # a plan set or cleared: the run on it starts over
    DROP = 'drop'  # a step without a plan's input, or new settings: what was held ends
    END_PLAN = 'end plan'  # a stop that keeps the solver's stop in force ends only a plan
    SOLVED = 'solved'  # a verified plan's input applied
    SOLVER_STOP = 'solver stop'  # the solver's verdict: no verified input
    ROTATE = 'rotate'  # an in-place turn to the goal heading given


class ControlState:
    """The mode in force, since when, and the output it holds (PLAN and STOP)."""

    def __init__(self) -> None:
        self.mode = Mode.IDLE
        self.since = -math.inf
        self.output: ControlOutput | None = None

    def on(self, event: Event, *, now: float = -math.inf,
           output: ControlOutput | None = None) -> None:
        """Move to the mode that follows event (the one place where the mode changes).

        Args:
            event: what happened.
            now: when (SOLVED, SOLVER_STOP: the held output's time).
            output: the output to hold (SOLVED, SOLVER_STOP).

        """
        mode = self.mode
        if event in (Event.NEW_PLAN, Event.DROP):
            mode = Mode.IDLE
        elif event is Event.END_PLAN:
            mode = Mode.IDLE if mode is Mode.PLAN else mode
        elif event is Event.SOLVED:
            mode = Mode.PLAN
        elif event is Event.SOLVER_STOP:
            mode = Mode.STOP
        elif event is Event.ROTATE:
            mode = Mode.ROTATE
        self.mode = mode
        if mode in (Mode.PLAN, Mode.STOP):
            if event in (Event.SOLVED, Event.SOLVER_STOP):
                self.since, self.output = now, output
        else:
            self.since, self.output = -math.inf, None

    def plan(self) -> ControlOutput | None:
        """Return the verified plan's output in force (PLAN), else None."""
        return self.output if self.mode is Mode.PLAN else None

    def holding(self, mode: Mode, now: float, period: float) -> ControlOutput | None:
        """Return the output mode holds at now, if mode is in force and its period runs.

        A clock that jumped back (now before the hold began) ends the hold.
        """
        if self.mode is mode and 0.0 <= now - self.since < period:
            return self.output
        return None
