# Copyright 2026 mpc_local_planner developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Global planner: OMPL's RRT* in the plane, over the world's inflated obstacles.

The paper feeds the MPC an unsmoothed RRT* polyline: the MPC tracks the path's steady states
and copes with the corners itself, so the planner only has to be collision free. It plans for
a point in R^2 among obstacles grown by the robot radius plus a clearance, and checks each
tree edge exactly (segment against convex polygon) rather than by sampling along it, so no
thin obstacle corner slips between two samples.

Runs are reproducible: OMPL's global seed is set before each plan, and termination is by an
iteration count (the paper's figure uses 1000) with a wall-clock limit only as a safeguard.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
import contextlib
from dataclasses import dataclass
import math
import threading

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet

__all__ = [
    'PlannerConfig',
    'RrtStarPlanner',
    'path_length',
]

# OMPL ignores seed 0 (it then seeds from the clock), so OMPL gets seed + 1 and every
# PlannerConfig.seed, including the default 0, is reproducible. Its seeds are 32-bit.
_MAX_SEED = 2**32 - 2
# OMPL's RNG seed and log level are process-wide: one plan at a time.
_OMPL_LOCK = threading.Lock()


@dataclass(frozen=True)
class PlannerConfig:
    """Settings of `RrtStarPlanner` (the global planner node's parameters mirror them).

    Attributes:
        iterations: RRT* iterations per plan (the paper's figure: 1000). With the seed, this
            makes plans reproducible; a time limit alone would not.
        time_limit: Upper bound on planning time in seconds, besides the iterations. A plan cut
            short by it is not reproducible.
        seed: Seed of OMPL's random number generator (any value in [0, 2**32 - 2]).
        range: RRT*'s maximum extension per iteration in metres; 0 lets OMPL choose (a fifth
            of the space's extent).
        robot_radius: Radius of the disk covering the robot, metres.
        clearance: Extra inflation beyond robot_radius, metres: room for the MPC to cut the
            polyline's corners and for its own collision margin.
        simplify: Shortcut and smooth the path with OMPL's simplifier. Off by default: the
            paper's point is that the MPC does not need a smoothed path.

    """

    iterations: int = 1000
    time_limit: float = 5.0
    seed: int = 0
    range: float = 0.0
    robot_radius: float = 0.0
    clearance: float = 0.1
    simplify: bool = False

    def __post_init__(self) -> None:
        """Refuse settings that OMPL would misread or silently ignore."""
        problems = []
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int):
            problems.append(f'iterations must be an integer, got {self.iterations!r}')
        elif self.iterations < 1:
            problems.append(f'iterations must be >= 1, got {self.iterations}')
        if not (math.isfinite(self.time_limit) and self.time_limit > 0):
            problems.append(f'time_limit must be > 0 and finite, got {self.time_limit}')
        if not (isinstance(self.seed, int) and 0 <= self.seed <= _MAX_SEED):
            problems.append(f'seed must be an integer in [0, {_MAX_SEED}], got {self.seed!r}')
        for name in ('range', 'robot_radius', 'clearance'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                problems.append(f'{name} must be >= 0 and finite, got {value}')
        if problems:
            msg = 'invalid PlannerConfig: ' + '; '.join(problems)
            raise ValueError(msg)

    @property
    def inflation(self) -> float:
        """Distance by which the planner grows every obstacle, metres."""
        return self.robot_radius + self.clearance


def path_length(waypoints: np.ndarray) -> float:
    """Return the length of the polyline through the waypoints ((M, 2) or (M, 3): x, y used)."""
    pts = np.asarray(waypoints, dtype=float)
    if pts.ndim != 2 or len(pts) < 2:
        return 0.0
    return float(np.sum(np.linalg.norm(np.diff(pts[:, :2], axis=0), axis=1)))


def _hits(obstacles: ObstacleSet, a: np.ndarray, b: np.ndarray) -> bool:
    """Say whether segment a-b touches an inflated obstacle (grazing counts: full clearance)."""
    return bool(np.any(obstacles.segment_hits(a, b, grazing=True)))


class _ExactMotionValidator(ob.MotionValidator):
    """OMPL motion validator that tests each edge exactly against the inflated obstacles."""

    def __init__(self, si: ob.SpaceInformation, obstacles: ObstacleSet) -> None:
        super().__init__(si)
        self._obstacles = obstacles

    def checkMotion(self, s1: ob.State, s2: ob.State, *args: object) -> bool:
        """Return True if the straight motion from s1 to s2 is collision free (OMPL's name)."""
        a = np.array([s1[0], s1[1]])
        b = np.array([s2[0], s2[1]])
        return not _hits(self._obstacles, a, b)


class _StateValidity:
    """State validity callable: inside the bounds and outside every inflated obstacle.

    A plain callable holding only NumPy data: it must not reference OMPL objects, or the
    reference cycle through C++ would keep them alive past the plan.
    """

    def __init__(self, obstacles: ObstacleSet, bounds: tuple[float, float, float, float]):
        self._obstacles = obstacles
        self._bounds = bounds

    def __call__(self, state: ob.State) -> bool:
        x, y = state[0], state[1]
        xmin, xmax, ymin, ymax = self._bounds
        if not (xmin <= x <= xmax and ymin <= y <= ymax):
            return False
        return self._obstacles.first_containing(np.array([x, y])) is None


@contextlib.contextmanager
def _ompl_log_level(level: ou.LogLevel) -> Iterator[None]:
    """Set OMPL's (process-wide) log level for a block, then restore it."""
    previous = ou.getLogLevel()
    ou.setLogLevel(level)
    try:
        yield
    finally:
        ou.setLogLevel(previous)


class RrtStarPlanner:
    """RRT* from OMPL over fixed obstacles and bounds; one instance serves many queries.

    Args:
        obstacles: The obstacles as described (not inflated); the planner inflates them by
            ``config.robot_radius + config.clearance``.
        bounds: (xmin, xmax, ymin, ymax) of the plane the planner samples.
        config: Planner settings.

    Raises:
        ValueError: If the bounds are empty or not finite.

    """

    def __init__(
        self,
        obstacles: Sequence[ConvexPolygon],
        bounds: tuple[float, float, float, float],
        *,
        config: PlannerConfig = PlannerConfig(),
    ) -> None:
        xmin, xmax, ymin, ymax = (float(v) for v in bounds)
        if not (all(map(math.isfinite, (xmin, xmax, ymin, ymax))) and xmin < xmax and ymin < ymax):
            msg = f'bounds must be finite (xmin, xmax, ymin, ymax) with min < max, got {bounds}'
            raise ValueError(msg)
        self.config = config
        self.bounds = (xmin, xmax, ymin, ymax)
        self.inflated_obstacles = tuple(
            obstacle.inflate(config.inflation) for obstacle in obstacles
        )
        self._obstacles = ObstacleSet(self.inflated_obstacles)

    def plan(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Plan a collision-free polyline from start to goal.

        Args:
            start: Start pose (x, y[, theta]); only x, y are used.
            goal: Goal pose (x, y[, theta]); only x, y are used.

        Returns:
            (M, 2) waypoints, M >= 2, with the first equal to start[:2] and the last equal to
            goal[:2]; every segment clears the inflated obstacles.

        Raises:
            PlanningError: If start or goal is out of bounds or in collision, or if RRT* finds
                no exact solution within the iterations and the time limit.

        """
        start_xy = self.check_endpoint(start, 'start')
        goal_xy = self.check_endpoint(goal, 'goal')
        if not _hits(self._obstacles, start_xy, goal_xy):
            # RRT* would converge to this segment anyway; skip the sampling.
            return np.vstack([start_xy, goal_xy])
        with _OMPL_LOCK, _ompl_log_level(ou.LOG_WARN):
            waypoints = self._solve(start_xy, goal_xy)
        waypoints[0] = start_xy
        waypoints[-1] = goal_xy
        return waypoints

    def check_endpoint(self, pose: np.ndarray, label: str) -> np.ndarray:
        """Return pose[:2] after checking it is finite, in bounds and clear of the obstacles.

        Clear of the obstacles as the planner grows them (robot_radius + clearance): a start
        or goal that passes this may still be walled off, but one that fails it can never
        be planned to.

        Args:
            pose: (x, y[, theta]).
            label: what the pose is ('start', 'goal'), for the message.

        Raises:
            PlanningError: saying why the pose cannot be planned from or to.

        """
        xy = np.asarray(pose, dtype=float).reshape(-1)[:2]
        if len(xy) != 2 or not np.all(np.isfinite(xy)):
            msg = f'{label} must hold finite x and y, got {pose!r}'
            raise PlanningError(msg)
        xmin, xmax, ymin, ymax = self.bounds
        if not (xmin <= xy[0] <= xmax and ymin <= xy[1] <= ymax):
            msg = f'{label} ({xy[0]:g}, {xy[1]:g}) is outside the bounds {self.bounds}'
            raise PlanningError(msg)
        index = self._obstacles.first_containing(xy)
        if index is not None:
            msg = (
                f'{label} ({xy[0]:g}, {xy[1]:g}) is in collision with obstacle {index} '
                f'inflated by {self.config.inflation:g} m (robot_radius + clearance)'
            )
            raise PlanningError(msg)
        return xy

    def _solve(self, start_xy: np.ndarray, goal_xy: np.ndarray) -> np.ndarray:
        """Run OMPL's RRT*; the caller holds the lock (OMPL's seed is process-wide)."""
        config = self.config
        with _ompl_log_level(ou.LOG_NONE):
            # OMPL logs an error when reseeding after its first use, yet reseeds all the same
            # (the determinism test checks it): silence the false alarm.
            ou.RNG.setSeed(config.seed + 1)

        space = ob.RealVectorStateSpace(2)
        bounds = ob.RealVectorBounds(2)
        xmin, xmax, ymin, ymax = self.bounds
        bounds.setLow(0, xmin)
        bounds.setHigh(0, xmax)
        bounds.setLow(1, ymin)
        bounds.setHigh(1, ymax)
        space.setBounds(bounds)

        setup = og.SimpleSetup(space)
        info = setup.getSpaceInformation()
        setup.setStateValidityChecker(_StateValidity(self._obstacles, self.bounds))
        info.setMotionValidator(_ExactMotionValidator(info, self._obstacles))

        start_state = space.allocState()
        goal_state = space.allocState()
        for i in range(2):
            start_state[i] = float(start_xy[i])
            goal_state[i] = float(goal_xy[i])
        setup.setStartAndGoalStates(start_state, goal_state)
        setup.setOptimizationObjective(ob.PathLengthOptimizationObjective(info))

        planner = og.RRTstar(info)
        if config.range > 0:
            planner.setRange(config.range)
        setup.setPlanner(planner)
        setup.setup()

        # No iteration-count condition in OMPL's bindings: RRT* evaluates the condition once
        # per iteration, so a callable on numIterations() stops after exactly `iterations`.
        count = planner.numIterations
        limit = config.iterations
        by_iterations = ob.PlannerTerminationCondition(lambda: count() >= limit)
        by_time = ob.timedPlannerTerminationCondition(config.time_limit)
        status = setup.solve(ob.plannerOrTerminationCondition(by_iterations, by_time))

        if status.getStatus() != ob.PlannerStatus.EXACT_SOLUTION:
            msg = (
                f'RRT* found no collision-free path from ({start_xy[0]:g}, {start_xy[1]:g}) '
                f'to ({goal_xy[0]:g}, {goal_xy[1]:g}) in {count()} iterations '
                f'(limit {limit}, time limit {config.time_limit:g} s): {status.asString()}'
            )
            raise PlanningError(msg)
        if config.simplify:
            setup.simplifySolution()
        states = setup.getSolutionPath().getStates()
        return np.array([[state[0], state[1]] for state in states], dtype=float)
