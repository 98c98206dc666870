# SPDX-License-Identifier: Apache-2.0
"""The solver strategy of one NLP solve as a table: a situation in, the ordered tries out.

A try is a start (where the solver begins) and a solver (the NLP's backend, or one of its two
IPOPTs). solver_tries() is pure: it says which tries are worth making, most promising first,
and nothing else. step.py's loop (MpcBase._optimise) makes them in that order while the
step's budget lasts and stops at the first verified solution, as Nav2 MPPI's fallback does.

The order, and why (the runs behind each rule: docs/design/mpc.md, section "Solver tries
(tries.py)"):

- after a plan that moves: the backend from the candidate, then the IPOPT fallback from it;
- without one, or after a plan that stands still (a step from rest that did not solve applied
  it), with obstacles in the NLP: IPOPT with cold-start options from the previous
  constraint-generation round's solution (else from the start rolled out along the path),
  then from the candidate (the one feasible start), then the backend and the fallback from
  the candidate. From such states fatrop tends to fail
  from every start while IPOPT converges, and a failing first try would spend each step's
  budget and keep the robot standing;
- without one and without obstacles: IPOPT with cold-start options from the candidate, then
  the backend from it, then from the rolled-out start the fallback and the backend. "Stay
  put" zeroes every derivative of the quartic stage cost, so Newton steps from it are badly
  scaled; IPOPT with its cold options (a larger initial barrier, which the flat cost needs)
  copes with it best.

A try the budget cut at the last step goes on first, from its last iterate
(Start.CONTINUATION), when the step may continue it (same NLP, same state: the robot stood
still meanwhile): an IPOPT try with the same IPOPT, a cut fatrop try with the warm IPOPT
when the NLP has one. fatrop restarts from scratch at every call, so going on with it makes
no progress across steps, while the warm IPOPT finishes from the same iterate. Without a
continuation a solve longer than one step's budget would start over at every step and never
finish.

A try that failed at an earlier step from the same state (the robot stood still since) goes
last: it failed outright, it was cut before it converged in
continuation.MAX_CONTINUED_ITERATIONS, or its verified solution lost to the candidate. The
same first try at every step of a standing robot is the same failure at every step, and the
robot would never move again.

An NLP whose backend is IPOPT has no fallback: its fallback tries are left out.
"""

from __future__ import annotations

from dataclasses import dataclass
import enum
from typing import NamedTuple

__all__ = ['Situation', 'Solver', 'Start', 'Try', 'solver_tries']


class Start(enum.Enum):
    """Where a try starts the solver."""

    CANDIDATE = 'candidate'  # the proof's shifted candidate: feasible by construction
    PREVIOUS_ROUND = 'previous round'  # the last constraint-generation round's solution
    GUIDED = 'guided'  # rolled out along the path at half speed: infeasible, informative
    CONTINUATION = 'continuation'  # the last iterate of the try the budget cut last step


class Solver(enum.Enum):
    """Which solver of the NLP a try runs."""

    BACKEND = 'backend'  # config.solver (or IPOPT for a shape beyond fatrop_stage_limit)
    IPOPT_FALLBACK = 'IPOPT fallback'  # IPOPT with the warm-start options
    IPOPT_COLD = 'IPOPT cold start'  # IPOPT with the cold-start options

    @property
    def label(self) -> str:
        """Return what a status solved by this solver gets appended ('' for the backend)."""
        return '' if self is Solver.BACKEND else f' ({self.value})'


class Try(NamedTuple):
    """One solve: from a start, with a solver."""

    start: Start
    solver: Solver


@dataclass(frozen=True, kw_only=True)
class Situation:
    """What the choice of tries depends on.

    Attributes:
        plan_moves: the plan in force moves the robot now: its first input is not zero (a
            stand-still plan, as applied after a step from rest that did not solve, counts as
            none, and so does a plan that waits and puts its motion off: warm starts from it
            put it off again at every step, see candidate.plan_moves).
        obstacles_active: the NLP holds obstacles (Farkas constraints).
        previous_round: the last constraint-generation round's solution is there (a start
            for this round).
        has_fallback: the NLP has an IPOPT fallback (its backend is not IPOPT).
        continuation: the solver of a try the budget cut at the last step that this solve
            may go on with (same NLP, same state), or None.
        failed: tries that failed at earlier steps from the same state, with the same NLP
            (a continuation among them: it was cut in every step it could go on for).

    """

    plan_moves: bool
    obstacles_active: bool
    previous_round: bool = False
    has_fallback: bool = True
    continuation: Solver | None = None
    failed: frozenset[Try] = frozenset()


def solver_tries(situation: Situation) -> tuple[Try, ...]:
    """Return the tries to make in this situation, most promising first.

    Args:
        situation: the plan in force, the NLP and what there is to start from.

    Returns:
        The tries in order. There is always a backend try: the loop makes the first one
        whatever is left of the budget, so that a step always has an answer.

    """
    candidate = Start.CANDIDATE
    if situation.plan_moves:
        tries = [Try(candidate, Solver.BACKEND), Try(candidate, Solver.IPOPT_FALLBACK)]
    elif situation.obstacles_active:
        start = Start.PREVIOUS_ROUND if situation.previous_round else Start.GUIDED
        tries = [Try(start, Solver.IPOPT_COLD), Try(candidate, Solver.IPOPT_COLD),
                 Try(candidate, Solver.BACKEND), Try(candidate, Solver.IPOPT_FALLBACK)]
    else:
        guided = Start.GUIDED
        tries = [Try(candidate, Solver.IPOPT_COLD), Try(candidate, Solver.BACKEND),
                 Try(guided, Solver.IPOPT_FALLBACK), Try(guided, Solver.BACKEND)]
    if situation.continuation is not None:
        solver = situation.continuation
        if solver is Solver.BACKEND and situation.has_fallback:
            solver = Solver.IPOPT_FALLBACK
        tries.insert(0, Try(Start.CONTINUATION, solver))
    if not situation.has_fallback:
        tries = [t for t in tries if t.solver is not Solver.IPOPT_FALLBACK]
    failed = situation.failed
    return tuple([t for t in tries if t not in failed] + [t for t in tries if t in failed])
