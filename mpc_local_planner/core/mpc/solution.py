# SPDX-License-Identifier: Apache-2.0
"""What a control step returns (MpcSolution), and what its solving found on the way.

SolveAttempt is one NLP solve's answer after verification; Rounds the outcome of a step's
constraint generation.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mpc_local_planner.core.models import held_input
from mpc_local_planner.core.mpc.backends import Nlp
from mpc_local_planner.core.mpc.candidate import Plan
from mpc_local_planner.core.mpc.decision import LyapunovCase, PlanSource
from mpc_local_planner.core.mpc.tries import Try
from mpc_local_planner.core.obstacles import ConvexPolygon

__all__ = ['MpcSolution', 'Rounds', 'SolveAttempt']


class MpcSolution(NamedTuple):
    """Result of one control step.

    Attributes:
        u0: the input to apply now (always within the model's bounds).
        x_pred: (N+1, nx) predicted states.
        u_pred: (N, nu) predicted inputs.
        s: path progress s_k of the artificial steady state (nan for TrackingMPC).
        value: V_N, the cost of what is applied (the Lyapunov function).
        success: the applied plan is the solver's (source is PlanSource.SOLVER).
        status: the solver's return status, and why the candidate was used or the robot stops.
        solve_time_s: wall time of the NLP solves (the solver calls; solve() as a whole, with
            its verification and any NLP built mid-step, is bounded by the budget: timed_out).
        iterations: solver iterations.
        source: the solver's plan, the proof's shifted candidate, or a stop.
        lyapunov_ok: V_N(x_k) <= V_N(x_{k-1}) - l(x_{k-1}, u_{k-1}) + tolerance, or None at
            the first step after a reset.
        lyapunov_case: whether the proof covers that check (LyapunovCase.COVERED: the same
            obstacles and settings, the state where the last plan took it), or what changed;
            None with lyapunov_ok None.
        failures: consecutive steps on which the solver gave no verified solution (a verified
            one that the candidate beat is not a failure: see solver_verified).
        obstacles_in_reach: obstacles the horizon can reach (all checked geometrically).
        obstacles_active: those the NLP held as Farkas constraints (see MpcBase.solve()).
        rounds: NLP solves this step (more than one when obstacles had to be added).
        solver_verified: the solver returned a verified solution, applied or not.
        timed_out: the step's budget (config.solve_budget()) ran out before its solving was
            done: a solve was cut or not started, or a retry or a constraint-generation round
            was left out. What is applied is verified all the same (the solver's plan only if
            it cleared every reachable obstacle), else the robot stops.
        tries: the solver tries the step made, in order, over all its rounds (see tries.py:
            solver_tries() gives them; the budget may leave some out).
        u_before: with a first-order hold (MpcConfig.input_hold), the velocity the plan
            starts from (its q_0 = u_prev): the velocity ramps from it to u_pred[0] over the
            first step, then through u_pred (see velocity_at); None with a zero hold.

    """

    u0: np.ndarray
    x_pred: np.ndarray
    u_pred: np.ndarray
    s: float
    value: float
    success: bool
    status: str
    solve_time_s: float
    iterations: int
    source: PlanSource
    lyapunov_ok: bool | None
    failures: int
    obstacles_in_reach: int = 0
    obstacles_active: int = 0
    rounds: int = 1
    solver_verified: bool = False
    timed_out: bool = False
    tries: tuple[Try, ...] = ()
    u_before: np.ndarray | None = None
    lyapunov_case: LyapunovCase | None = None

    def velocity_at(self, t: float, step: float) -> np.ndarray:
        """Return the plan's input t seconds after its start (steps of length step).

        A zero hold: u_pred[l] over step l. A first-order hold (u_before set): the linear
        ramp through the knots u_before, u_pred[0], ..., u_pred[N-1]. Past the horizon: the
        last input (0 for a first-order hold, whose plans end at rest).
        """
        u = np.asarray(self.u_pred, dtype=float)
        if not len(u):
            return np.asarray(self.u0, dtype=float).copy()
        held = held_input(u, max(float(t), 0.0) / step, self.u_before)
        return u[-1].copy() if held is None else held


class SolveAttempt(NamedTuple):
    """The solver's answer after verification."""

    verified: bool  # converged, finite, and within FEASIBILITY_TOLERANCE of every constraint
    w: np.ndarray  # the decision vector it returned
    value: float  # its cost (inf unless verified)
    status: str  # the solver's return status
    iterations: int
    seconds: float
    cut: bool = False  # the budget stopped the solver before it converged
    origin: Try | None = None  # the try that began the verified solve (None: none verified)


class Rounds(NamedTuple):
    """The outcome of constraint generation: the last NLP, its candidate and its solution."""

    nlp: Nlp
    params: np.ndarray
    candidate: Plan  # with the last round's multipliers
    w_candidate: np.ndarray
    candidate_ok: bool
    candidate_value: float
    attempt: SolveAttempt  # the last round's, with the iterations and time of all rounds
    active: list[ConvexPolygon]
    rounds: int
