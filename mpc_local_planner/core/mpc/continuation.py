# SPDX-License-Identifier: Apache-2.0
"""What a solve the step's budget cut carries to the next step, and when it may go on.

A cut solve (Unfinished) goes on at the next step from its last iterate only while the robot
stands where it was (the state within CONTINUE_TOLERANCE: it stood still on the candidate
meanwhile), with the same NLP holding the same obstacles (each vertex within
CONTINUE_TOLERANCE: a laser's pieces are fitted again at every scan, and a standing robot's
odometry and scans jitter in their last digits), until it has made
MAX_CONTINUED_ITERATIONS iterations in all. The next step then also starts its constraint
generation with the round that was cut (resumed_round), not with the rounds before it.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from mpc_local_planner.core.moving_obstacles import motion_of
from mpc_local_planner.core.mpc.backends import Nlp
from mpc_local_planner.core.mpc.tries import Solver, Start, Try
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet

__all__ = ['CONTINUE_TOLERANCE', 'MAX_CONTINUED_ITERATIONS', 'SpotMemory', 'Unfinished',
           'near_polygons', 'resumed_round', 'same_polygons', 'stood_still']

# A solve the budget cut goes on at the next step from where it stopped if the state moved
# less than this (each component): the robot stood still on the candidate meanwhile; and if
# each obstacle its NLP held is still there, each vertex moved less than this (metres). The
# iterate is only where the solver starts: what it returns is verified against the
# obstacles as they are now.
CONTINUE_TOLERANCE = 1e-3
# A cut solve goes on until it has made this many iterations in all (its first step's and each
# continuation's), then counts as failed here: enough for the slowest converging solve seen
# (about 245), few enough that a hopeless try does not hold back the others (see
# docs/design/mpc.md, section MAX_CONTINUED_ITERATIONS). Counted in iterations, not steps, so
# that a try begun with a sliver of a step's budget gets as far as one begun with all of it.
MAX_CONTINUED_ITERATIONS = 300


class Unfinished(NamedTuple):
    """A solve the step's budget cut: where it got to, to go on from at the next step."""

    nlp: Nlp
    x0: np.ndarray
    w: np.ndarray
    solver: Solver  # the solver of the try that was cut
    held: tuple[ConvexPolygon, ...]  # the obstacles its NLP held, in their slots' order
    origin: Try  # the try that began it (a continuation's origin is the first one's)
    spent: int = 0  # the iterations it has made in all (the first step's and each continuation's)


class SpotMemory:
    """What the solver tried where the robot stands: a cut solve to go on with, and failures.

    A control step asks it for the continuation its NLP may go on with (`continuation`), and
    which tries already failed here (`failed`, for tries.solver_tries to put last), then
    records each try it made (`record`). Moving on forgets both. A stop keeps it (the robot
    stands still, and the next step is here again); a reset of the MPC starts a new one.
    """

    def __init__(self) -> None:
        self.unfinished: Unfinished | None = None
        # tries that failed from the state _x0, with their NLP's id (the NLPs live as long as
        # the controller's settings)
        self._failed: set[tuple[int, Try]] = set()
        self._x0: np.ndarray | None = None

    def continuation(self, nlp: Nlp, x0: np.ndarray, held: Sequence[ConvexPolygon]
                     ) -> Unfinished | None:
        """Return the cut solve nlp goes on with from x0 holding held (None: none).

        A cut solve is offered once: to the step after it, in its own NLP, if the robot has
        not moved and the NLP holds the same obstacles. A robot that moved makes every try
        worth making again.
        """
        unfinished, continuation = self.unfinished, None
        if unfinished is not None and unfinished.nlp is nlp:
            self.unfinished = None  # continued once, or moved away from
            if stood_still(unfinished.x0, x0) and near_polygons(unfinished.held, held):
                continuation = unfinished
        if not stood_still(self._x0, x0):
            self._failed = set()
            self._x0 = x0.copy()
        return continuation

    def failed(self, nlp: Nlp) -> frozenset[Try]:
        """Return the tries that failed here in nlp."""
        return frozenset(t for n, t in self._failed if n == id(nlp))

    def reject(self, nlp: Nlp, origin: Try) -> None:
        """Record that the try begun by origin solved here, but its solution is not applied.

        It lost to the candidate, or it hits an obstacle its NLP had no room for. The robot
        stands, so the same try from the same state would give the same solution again and
        hold the robot at every step: it goes last instead.
        """
        self._failed.add((id(nlp), origin))

    def record(self, nlp: Nlp, x0: np.ndarray, made: Try, origin: Try, spent: int, *,
               verified: bool, cut: bool, iterations: int, w: np.ndarray,
               held: Sequence[ConvexPolygon]) -> None:
        """Record a try: a failure here, or a cut solve to go on with at the next step.

        Args:
            nlp: the NLP it ran in.
            x0: the state it ran from.
            made: the try.
            origin: the try that began it (made, or a continuation's first).
            spent: the iterations it has made in all, this step's included.
            verified: it gave a verified solution.
            cut: the budget cut it.
            iterations: the iterations it made.
            w: its last iterate.
            held: the obstacles its NLP held, in their slots' order.

        """
        if not verified and (not cut or spent >= MAX_CONTINUED_ITERATIONS):
            # failed outright, or cut before it converged in all it may make: not first again
            # while the robot stands here. A continuation is its origin's: one that failed
            # says nothing of the next cut solve's continuation
            self._failed.add((id(nlp), origin))
            if made.start is not Start.CONTINUATION:
                self._failed.add((id(nlp), made))
        if (cut and not verified and iterations > 0 and spent < MAX_CONTINUED_ITERATIONS
                and np.all(np.isfinite(w))):
            self.unfinished = Unfinished(nlp, x0.copy(), w, made.solver, tuple(held), origin,
                                         spent)


def stood_still(before: np.ndarray | None, x0: np.ndarray) -> bool:
    """Say whether the state is where it was (within CONTINUE_TOLERANCE); None: unknown."""
    return before is not None and float(np.max(np.abs(before - x0))) <= CONTINUE_TOLERANCE


def same_polygons(a: Sequence[ConvexPolygon], b: Sequence[ConvexPolygon]) -> bool:
    """Say whether two obstacle lists are the same polygons in the same order."""
    return len(a) == len(b) and all(
        p.vertices.shape == q.vertices.shape and np.array_equal(p.vertices, q.vertices)
        and np.array_equal(motion_of(p), motion_of(q))
        for p, q in zip(a, b, strict=True))


def near_polygons(a: Sequence[ConvexPolygon], b: Sequence[ConvexPolygon],
                  tolerance: float = CONTINUE_TOLERANCE) -> bool:
    """Say whether two obstacle lists are the same obstacles, seen again.

    The same polygons in the same order, each vertex within tolerance (metres) of its twin.
    """
    return len(a) == len(b) and all(
        p.vertices.shape == q.vertices.shape
        and float(np.max(np.abs(p.vertices - q.vertices), initial=0.0)) <= tolerance
        for p, q in zip(a, b, strict=True))


def resumed_round(unfinished: Unfinished | None, x0: np.ndarray, reachable: ObstacleSet
                  ) -> list[ConvexPolygon] | None:
    """Return the obstacles of the round the budget cut last step, to take it up again.

    Only when the robot has not moved since (the state within CONTINUE_TOLERANCE) and
    every obstacle that round held is still there (near_polygons): then this step starts with
    that round, and its cut try goes on first, rather than solving the rounds before it
    again. Without this a step whose rounds need more iterations together than one step has
    would spend its budget on the same first round at every step, and the cut round would
    never get further (see docs/design/mpc.md, section "Resuming a cut round
    (_resumed_round)").

    Returns:
        The reachable obstacles that round held, in its order, or None.

    """
    if unfinished is None or not stood_still(unfinished.x0, x0):
        return None
    resumed = []
    for old in unfinished.held:
        match = next((o for o in reachable.obstacles if near_polygons((o,), (old,))), None)
        if match is None:
            return None
        resumed.append(match)
    return resumed
