# SPDX-License-Identifier: Apache-2.0
"""The guard of a control step: which plan is applied, the solver's, the candidate, or none.

The proof's argument (Theorem 1 of the paper) holds if the applied plan is never costlier than
the shifted candidate of the previous one: decide() takes the solver's verified solution only
then, else the candidate, and stops the robot when neither is verified.

The argument covers a step only if the problem is the one the last plan was solved for: the
same obstacles and settings (a new path starts the record over), and the robot where that
plan's first input took it. LyapunovRecord says which steps it covers (LyapunovCase): a V_N
increase on such a step is a defect; on the others the decrease is not promised.
"""

from __future__ import annotations

from enum import Enum
import math

import numpy as np

__all__ = ['Decision', 'LYAPUNOV_TOLERANCE', 'LyapunovCase', 'LyapunovRecord', 'PlanSource',
           'STATE_TOLERANCE', 'decide']

# Slack on the closed-loop decrease check, relative to V_N plus an absolute floor.
LYAPUNOV_TOLERANCE = 1e-6
# How far (m, rad: the largest component) the measured state may be from the state the
# applied plan's first input leads to (the model's own step from the state it was solved
# for) for the proof to cover the step. Arithmetic alone leaves the two within 1e-15 to
# 1e-10 (the ideal simulator integrates the same model); anything physical moves the state
# further (localizer or odometry noise by centimetres, a command taking effect a 0.02 s tick
# late by its change times 0.02 s: 2e-6 to 1e-2 in closed_loop's ideal run). An offset below
# it keeps the shifted candidate within FEASIBILITY_TOLERANCE (1e-5) of its terminal
# equality, so the proof's decrease must hold there; and the decrease does not hang on the
# side of it a step falls (on the paper's route it held at states moved by up to 1e-5).
STATE_TOLERANCE = 1e-6


class PlanSource(str, Enum):
    """Where the applied plan comes from (a str, so logs and diagnostics read the value)."""

    SOLVER = 'solver'  # the NLP solver's verified solution
    CANDIDATE = 'candidate'  # the proof's shifted solution of the previous step
    STOP = 'stop'  # no verified plan: the steady-state input, the robot stands still
    # no verified plan, and stopping would be run into: a move out of a moving obstacle's
    # way, checked against every obstacle (core/evasion.py; the controller's, not the MPC's)
    EVASION = 'evasion'

    def __str__(self) -> str:
        return self.value


class Decision(Enum):
    """What a control step applies, and why (the value is the note added to the status)."""

    SOLVER = ''
    CANDIDATE_CHEAPER = 'candidate cheaper than solver solution'
    CANDIDATE_SOLVER_FAILED = 'applied the shifted candidate'
    CANDIDATE_OFF_PREDICTION = 'applied the shifted candidate; off the prediction'
    CANDIDATE_TIMEOUT = 'applied the shifted candidate; solve time budget spent'
    STOP = 'no feasible candidate: stopping'

    @property
    def source(self) -> PlanSource:
        """The plan this decision applies."""
        if self is Decision.SOLVER:
            return PlanSource.SOLVER
        if self is Decision.STOP:
            return PlanSource.STOP
        return PlanSource.CANDIDATE

    @property
    def is_failure(self) -> bool:
        """The solver gave no verified plan that is applied or beaten by the candidate."""
        return self not in (Decision.SOLVER, Decision.CANDIDATE_CHEAPER)


def decide(*, solver_verified: bool, solver_value: float, candidate_ok: bool,
           candidate_value: float, has_previous_plan: bool,
           candidate_collision_free: bool, timed_out: bool = False,
           candidate_binds: bool = True) -> Decision:
    """Choose what is applied: the solver's plan, the shifted candidate, or a stop.

    Args:
        solver_verified: the solver's solution passed verification.
        solver_value: its cost V_N.
        candidate_ok: the shifted candidate passed verification (it ends on the path).
        candidate_value: its cost (ignored unless candidate_ok).
        has_previous_plan: there is a previous plan, so the candidate's inputs were verified
            one step ago.
        candidate_collision_free: the candidate's rollout from the measured state clears
            every reachable obstacle.
        timed_out: the step's solve time budget ran out before its solving was done.
        candidate_binds: the candidate's value bounds the solver's: a plan of the solver's
            has been applied since the MPC was reset (a new path, a stop). Before that the
            candidate stands the robot still where it is, a safe stop rather than a plan of
            the MPC's; the proof's decrease starts with the first plan the solver gives, as
            the paper's closed loop starts with the optimum at k = 0.

    Returns:
        SOLVER when the solver's plan is verified and not costlier than a verified candidate
        (with LYAPUNOV_TOLERANCE), whether or not time ran out; else the candidate:
        CANDIDATE_CHEAPER when it is verified and beats a verified solution,
        CANDIDATE_TIMEOUT when it is verified and the solver gave no verified solution in
        the time, CANDIDATE_SOLVER_FAILED when it is verified and the solver gave none with
        time to spare; CANDIDATE_OFF_PREDICTION when it is not
        (the measured state left the prediction, so it no longer ends on the path) but it
        follows a previous plan and is collision-free (the shift runs out after N steps,
        all u_s, which stops the robot); else STOP.

    """
    bound = candidate_value if candidate_ok and candidate_binds else math.inf
    if solver_verified and solver_value <= bound + LYAPUNOV_TOLERANCE * (1 + abs(bound)):
        return Decision.SOLVER
    if candidate_ok:
        if solver_verified:
            return Decision.CANDIDATE_CHEAPER
        return Decision.CANDIDATE_TIMEOUT if timed_out else Decision.CANDIDATE_SOLVER_FAILED
    if has_previous_plan and candidate_collision_free:
        return Decision.CANDIDATE_OFF_PREDICTION
    return Decision.STOP


class LyapunovCase(str, Enum):
    """Whether Theorem 1 covers a step's V_N check, and if not, what changed since the last.

    A str, so diagnostics and metrics read the value. The first that applies, in this order.
    """

    SETTINGS_CHANGED = 'settings_changed'  # the MPC's settings (weights, bounds...) changed
    OBSTACLES_CHANGED = 'obstacles_changed'  # other obstacles (new scans, a new map)
    STATE_OFF_PREDICTION = 'state_off_prediction'  # the state is off by > STATE_TOLERANCE
    COVERED = 'covered'  # the same problem, the state where the plan took it: V_N must fall

    def __str__(self) -> str:
        return self.value


class LyapunovRecord:
    """The last applied plan's value V_N and first stage cost: what the next value must keep.

    The proof's decrease (the paper's Theorem 1): V_N(k+1) <= V_N(k) - l(x_0, u_0), checked
    within LYAPUNOV_TOLERANCE relative to the bound. A reset of the MPC starts a new record.
    The record also keeps what the proof assumes of the next step (the state the plan's first
    input leads to, and the problem it was solved for: the versions of the obstacles and
    settings), so that case() says whether the proof covers it.
    """

    def __init__(self) -> None:
        self.value: float | None = None
        self.stage = 0.0
        self.predicted: np.ndarray | None = None
        self.problem: tuple[int, int] = (0, 0)

    def case(self, state: np.ndarray, problem: tuple[int, int], angle_index: int
             ) -> LyapunovCase | None:
        """Say whether the proof covers a step from state (None: no plan applied before).

        Args:
            state: the measured state, its heading unwrapped near the prediction's.
            problem: the versions (obstacles, settings) of the problem the step solves.
            angle_index: the heading's index in the state (compared modulo 2 pi).

        """
        if self.value is None or self.predicted is None:
            return None
        if problem[1] != self.problem[1]:
            return LyapunovCase.SETTINGS_CHANGED
        if problem[0] != self.problem[0]:
            return LyapunovCase.OBSTACLES_CHANGED
        off = np.abs(np.asarray(state, dtype=float) - self.predicted)
        off[angle_index] = abs(math.remainder(float(off[angle_index]), 2.0 * math.pi))
        if not float(np.max(off)) <= STATE_TOLERANCE:  # NaN counts as off
            return LyapunovCase.STATE_OFF_PREDICTION
        return LyapunovCase.COVERED

    def check(self, value: float) -> bool | None:
        """Say whether value keeps the decrease (None: no plan applied before)."""
        if self.value is None:
            return None
        bound = self.value - self.stage
        return value <= bound + LYAPUNOV_TOLERANCE * (1 + abs(bound))

    def keep(self, value: float, stage: float, *, predicted: np.ndarray | None = None,
             problem: tuple[int, int] = (0, 0)) -> None:
        """Record the plan applied now: its value, its first stage cost, what it assumes.

        Args:
            value: its cost V_N.
            stage: its first stage cost l(x_0, u_0).
            predicted: the state its first input leads to (None: no step is covered).
            problem: the versions (obstacles, settings) of the problem it was solved for.

        """
        self.value, self.stage = float(value), float(stage)
        self.predicted = None if predicted is None else np.array(predicted, dtype=float)
        self.problem = problem
