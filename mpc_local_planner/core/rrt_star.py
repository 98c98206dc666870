# SPDX-License-Identifier: Apache-2.0
"""One run of OMPL's RRT* in the plane, with exact validity and motion checks by callables.

The planner (core/planner.py) decides what is free; this module only drives OMPL: a
RealVectorStateSpace(2) over the bounds, a state validity callable, a motion validator that
tests each edge exactly (never by samples along it), RRT* with the path length objective,
and termination by an iteration count (with a wall-clock limit only as a safeguard), so that
with a seed a run is reproducible. OMPL's seed and log level are process-wide: one run at a
time (a lock).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
import contextlib
import threading

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from mpc_local_planner.core.errors import PlanningError

__all__ = ['MAX_SEED', 'rrt_star']

# OMPL ignores seed 0 (it then seeds from the clock), so OMPL gets seed + 1 and every
# PlannerConfig.seed, including the default 0, is reproducible. Its seeds are 32-bit.
MAX_SEED = 2**32 - 2
# OMPL's RNG seed and log level are process-wide: one plan at a time.
_OMPL_LOCK = threading.Lock()


class _ExactMotionValidator(ob.MotionValidator):
    """OMPL motion validator that tests each edge exactly, by a plain callable.

    Round robot: segment against inflated polygon, or every cell the segment passes through;
    polygon footprint: the swept polygon and the turns at the start and goal
    (`FootprintPlan.motion_valid`).
    """

    def __init__(self, si: ob.SpaceInformation,
                 motion_free: Callable[[np.ndarray, np.ndarray], bool]) -> None:
        super().__init__(si)
        self._motion_free = motion_free

    def checkMotion(self, s1: ob.State, s2: ob.State, *args: object) -> bool:
        """Return True if the straight motion from s1 to s2 is collision free (OMPL's name)."""
        a = np.array([s1[0], s1[1]])
        b = np.array([s2[0], s2[1]])
        return self._motion_free(a, b)


class _StateValidity:
    """State validity callable: inside the bounds and free by a plain callable.

    A plain callable holding only NumPy data: it must not reference OMPL objects, or the
    reference cycle through C++ would keep them alive past the plan.
    """

    def __init__(self, state_free: Callable[[np.ndarray], bool],
                 bounds: tuple[float, float, float, float]):
        self._state_free = state_free
        self._bounds = bounds

    def __call__(self, state: ob.State) -> bool:
        x, y = state[0], state[1]
        xmin, xmax, ymin, ymax = self._bounds
        if not (xmin <= x <= xmax and ymin <= y <= ymax):
            return False
        return self._state_free(np.array([x, y]))


@contextlib.contextmanager
def _ompl_log_level(level: ou.LogLevel) -> Iterator[None]:
    """Set OMPL's (process-wide) log level for a block, then restore it."""
    previous = ou.getLogLevel()
    ou.setLogLevel(level)
    try:
        yield
    finally:
        ou.setLogLevel(previous)


def rrt_star(start_xy: np.ndarray, goal_xy: np.ndarray, *,
             bounds: tuple[float, float, float, float],
             state_free: Callable[[np.ndarray], bool],
             motion_free: Callable[[np.ndarray, np.ndarray], bool],
             failure_hint: Callable[[], str], seed: int, iterations: int,
             time_limit: float, extension: float = 0.0,
             simplify: bool = False) -> list[np.ndarray]:
    """Run OMPL's RRT* from start_xy to goal_xy (under the lock, OMPL's warnings only).

    Args:
        start_xy: (2,) start.
        goal_xy: (2,) goal.
        bounds: (xmin, xmax, ymin, ymax) of the plane sampled; a state outside is invalid.
        state_free: Whether a (2,) state is free.
        motion_free: Whether the straight motion between two (2,) states is free.
        failure_hint: Text appended to the failure's message (why it may have failed).
        seed: OMPL's seed is seed + 1, so seed is in [0, MAX_SEED].
        iterations: RRT* iterations.
        time_limit: Upper bound on the run's wall time, seconds.
        extension: RRT*'s range (maximum extension per iteration); 0 lets OMPL choose.
        simplify: Also return the path simplified by OMPL's simplifier.

    Returns:
        The (M, 2) path: with ``simplify``, the simplified one and then RRT*'s own.

    Raises:
        PlanningError: If RRT* finds no exact solution within the iterations and time limit.

    """
    with _OMPL_LOCK, _ompl_log_level(ou.LOG_WARN):
        return _solve(start_xy, goal_xy, bounds, state_free, motion_free, failure_hint,
                      seed, iterations, time_limit, extension, simplify)


def _solve(start_xy: np.ndarray, goal_xy: np.ndarray, bounds: tuple[float, float, float, float],
           state_free: Callable[[np.ndarray], bool],
           motion_free: Callable[[np.ndarray, np.ndarray], bool],
           failure_hint: Callable[[], str], seed: int, iterations: int, time_limit: float,
           extension: float, simplify: bool) -> list[np.ndarray]:
    """Run RRT* as `rrt_star` says; the caller holds the lock (OMPL's seed is process-wide)."""
    with _ompl_log_level(ou.LOG_NONE):
        # OMPL logs an error when reseeding after its first use, yet reseeds all the same
        # (the determinism test checks it): silence the false alarm.
        ou.RNG.setSeed(seed + 1)

    space = ob.RealVectorStateSpace(2)
    box = ob.RealVectorBounds(2)
    xmin, xmax, ymin, ymax = bounds
    box.setLow(0, xmin)
    box.setHigh(0, xmax)
    box.setLow(1, ymin)
    box.setHigh(1, ymax)
    space.setBounds(box)

    setup = og.SimpleSetup(space)
    info = setup.getSpaceInformation()
    setup.setStateValidityChecker(_StateValidity(state_free, bounds))
    info.setMotionValidator(_ExactMotionValidator(info, motion_free))

    start_state = space.allocState()
    goal_state = space.allocState()
    for i in range(2):
        start_state[i] = float(start_xy[i])
        goal_state[i] = float(goal_xy[i])
    setup.setStartAndGoalStates(start_state, goal_state)
    setup.setOptimizationObjective(ob.PathLengthOptimizationObjective(info))

    planner = og.RRTstar(info)
    if extension > 0:
        planner.setRange(extension)
    setup.setPlanner(planner)
    setup.setup()

    # No iteration-count condition in OMPL's bindings: RRT* evaluates the condition once
    # per iteration, so a callable on numIterations() stops after exactly `iterations`.
    count = planner.numIterations
    limit = iterations
    by_iterations = ob.PlannerTerminationCondition(lambda: count() >= limit)
    by_time = ob.timedPlannerTerminationCondition(time_limit)
    status = setup.solve(ob.plannerOrTerminationCondition(by_iterations, by_time))

    if status.getStatus() != ob.PlannerStatus.EXACT_SOLUTION:
        msg = (
            f'RRT* found no collision-free path from ({start_xy[0]:g}, {start_xy[1]:g}) '
            f'to ({goal_xy[0]:g}, {goal_xy[1]:g}) in {count()} iterations '
            f'(limit {limit}, time limit {time_limit:g} s): {status.asString()}'
            f'{failure_hint()}'
        )
        raise PlanningError(msg)
    paths = [_states(setup)]
    if simplify:
        setup.simplifySolution()
        paths.insert(0, _states(setup))
    return paths


def _states(setup: og.SimpleSetup) -> np.ndarray:
    """Return the solution path's states as (M, 2) points."""
    states = setup.getSolutionPath().getStates()
    return np.array([[state[0], state[1]] for state in states], dtype=float)
