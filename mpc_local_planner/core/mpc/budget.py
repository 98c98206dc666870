# SPDX-License-Identifier: Apache-2.0
"""The budget of one control step's solving, and what a solver try costs before it runs.

Seconds of a clock (SolverSettings.budget 'wall', the robot's: config.solve_budget(),
max_solve_time, half the period by default, counted from the start of solve()), or solver
iterations ('iterations', the evaluation's: config.solve_iterations(), spent by the
iterations each try makes; the clock is never read, builds are free and a step waits for its
NLP's compilation, so a step does the same on any machine under any load). The other is
unbounded. The first NLP solve gets what is left when it starts (an NLP built mid-step has
spent its share of wall time: MpcBase.prepare() builds them ahead); the retries (a second
start, the IPOPT fallback, further constraint-generation rounds) run only while some is
left. A try's solver may have to be built first (an IPOPT not built ahead): build_time()
says how long that takes, which counts against wall time only. How closely a solver keeps
to its share is backends.py's (run_solver): IPOPT to an iteration, fatrop to its measured
time per iteration (wall) or to an iteration level (iterations).
"""

from __future__ import annotations

import math
from typing import Callable

import casadi as ca

from mpc_local_planner.core.config import BudgetKind, MpcConfig
from mpc_local_planner.core.mpc.backends import Nlp
from mpc_local_planner.core.mpc.tries import Solver

__all__ = ['Budget', 'build_time', 'solver_of']


class Budget:
    """What is left of one control step's solving, and whether the step ran out of it.

    Args:
        clock: the clock of the wall budget (seconds).
        seconds: the wall budget (inf: unbounded).
        iterations: the iteration budget (inf: unbounded).

    """

    def __init__(self, clock: Callable[[], float], *, seconds: float = math.inf,
                 iterations: float = math.inf) -> None:
        self._clock = clock
        self._deadline = clock() + seconds if math.isfinite(seconds) else math.inf
        self.iterations = iterations  # left
        self.timed_out = False  # some solving was cut or left out for lack of budget

    @classmethod
    def of(cls, config: MpcConfig, clock: Callable[[], float]) -> Budget:
        """Return the budget of one step under config."""
        if config.solving.budget is BudgetKind.ITERATIONS:
            return cls(clock, iterations=config.solve_iterations())
        return cls(clock, seconds=config.solve_budget())

    def remaining(self) -> float:
        """Return the seconds left (<= 0 when spent; inf without a time bound)."""
        if math.isinf(self._deadline):
            return math.inf
        return self._deadline - self._clock()

    def spend(self, iterations: int) -> None:
        """Count a solver call's iterations."""
        self.iterations -= iterations

    def allows(self, seconds: float = 0.0) -> bool:
        """Say whether there is budget for more solving; if not, the step has timed out.

        Args:
            seconds: what the work takes before it can be cut (a build), if known; it does
                not count against iterations.

        Ask only where work would otherwise run: a no means it is left out. Once the step
        timed out (a try was cut) the answer is no: a try begun on what is left would be cut
        too and replace the cut one as the solve to go on with at the next step.
        """
        if not self.timed_out and self.remaining() > seconds and self.iterations >= 1:
            return True
        self.timed_out = True
        return False


def solver_of(nlp: Nlp, solver: Solver) -> ca.Function | None:
    """Return the solver function a try runs (None: the NLP's own), building it if need be."""
    if solver is Solver.IPOPT_FALLBACK:
        return nlp.fallback_solver()
    if solver is Solver.IPOPT_COLD:
        return nlp.cold_solver()
    return None


def build_time(nlp: Nlp, solver: Solver) -> float:
    """Return the seconds getting the solver of a try takes before it can run (0: built)."""
    if solver is Solver.IPOPT_FALLBACK:
        return nlp.fallback_build_time
    if solver is Solver.IPOPT_COLD:
        return nlp.cold_build_time
    return 0.0
