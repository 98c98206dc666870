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

"""Global planner: OMPL's RRT* in the plane, over inflated obstacles or an inflated grid.

The paper feeds the MPC an unsmoothed RRT* polyline: the MPC tracks the path's steady states
and copes with the corners itself, so the planner only has to be collision free. It plans for
a point in R^2 among obstacles grown by the robot radius plus a clearance, and checks each
tree edge exactly (segment against convex polygon) rather than by sampling along it, so no
thin obstacle corner slips between two samples.

On a grid (`RrtStarPlanner.on_grid`: an occupancy grid inflated by a distance transform, as
perception's ``PlanningGrid`` keeps it from a map and scans), a state is checked by its
cell, and an edge exactly too: every cell it passes through must be free (not samples along
it, which could clip the corner of a blocked cell); the plane sampled is the grid's extent.

Runs are reproducible: OMPL's global seed is set before each plan, and termination is by an
iteration count (the paper's figure uses 1000) with a wall-clock limit only as a safeguard.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
import contextlib
from dataclasses import dataclass
import math
import threading
from typing import Any, Protocol

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet

__all__ = [
    'FreeSpaceGrid',
    'PlannerConfig',
    'RrtStarPlanner',
    'grid_bounds',
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


class FreeSpaceGrid(Protocol):
    """What the planner needs of an inflated occupancy grid (perception's ``PlanningGrid``).

    ``map`` is the grid's geometry (an ``OccupancyMap``: ``origin`` (x, y, yaw) of the
    lower-left corner, ``resolution``, ``width``, ``height``, ``world_to_cell``,
    ``contains_cell``); ``occupied`` the (height, width) cells that are obstacles before
    inflation, ``blocked`` those within ``inflation`` (metres) of one. Points outside the
    grid are free.
    """

    inflation: float

    @property
    def map(self) -> Any:
        """The grid's geometry (origin, resolution, width, height, world_to_cell)."""

    @property
    def occupied(self) -> np.ndarray:
        """(height, width) booleans: the obstacle cells before inflation."""

    @property
    def blocked(self) -> np.ndarray:
        """(height, width) booleans: the cells within the inflation of an obstacle cell."""

    def is_free(self, points: np.ndarray) -> np.ndarray:
        """Say, per (N, 2) point, whether it is free after inflation."""


def grid_bounds(grid: FreeSpaceGrid) -> tuple[float, float, float, float]:
    """Return (xmin, xmax, ymin, ymax) of the grid's extent (its corners, if rotated)."""
    occupancy = grid.map
    x0, y0, yaw = (float(v) for v in occupancy.origin)
    width = occupancy.width * float(occupancy.resolution)
    height = occupancy.height * float(occupancy.resolution)
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([[0.0, 0.0], [width, 0.0], [width, height], [0.0, height]])
    xs = x0 + c * local[:, 0] - s * local[:, 1]
    ys = y0 + s * local[:, 0] + c * local[:, 1]
    return float(xs.min()), float(xs.max()), float(ys.min()), float(ys.max())


class _Space:
    """Where the robot's reference point may be: the queries the planner makes.

    Two kinds: inflated polygons (exact segment tests) and an inflated grid. Holds only
    NumPy data and plain callables: it must not reference OMPL objects, or the reference
    cycle through C++ would keep them alive past the plan.
    """

    def __init__(self, point_free: Callable[[np.ndarray], bool],
                 segment_free: Callable[[np.ndarray, np.ndarray], bool],
                 collision: Callable[[np.ndarray], str | None]) -> None:
        self.point_free = point_free
        self.segment_free = segment_free
        self.collision = collision


def _polygon_space(obstacles: ObstacleSet, inflation: float) -> _Space:
    def collision(xy: np.ndarray) -> str | None:
        index = obstacles.first_containing(xy)
        if index is None:
            return None
        return (f'in collision with obstacle {index} inflated by {inflation:g} m '
                '(robot_radius + clearance)')

    return _Space(point_free=lambda xy: obstacles.first_containing(xy) is None,
                  segment_free=lambda a, b: not _hits(obstacles, a, b),
                  collision=collision)


def _cells_crossed(occupancy: Any, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return (rows, cols) of every cell the segment a-b passes through (may be outside).

    Exact: the segment is cut where it crosses a grid line, and the middle of each piece
    names one cell it runs through; so no cell is skipped, however little is clipped of it.
    """
    x0, y0, yaw = (float(v) for v in occupancy.origin)
    res = float(occupancy.resolution)
    c, s = math.cos(yaw), math.sin(yaw)
    ends = np.array([a, b], dtype=float) - (x0, y0)
    u = (c * ends[:, 0] + s * ends[:, 1]) / res  # grid coordinates, in cells
    v = (-s * ends[:, 0] + c * ends[:, 1]) / res
    cuts = [np.array([0.0, 1.0])]
    for p0, p1 in ((u[0], u[1]), (v[0], v[1])):
        if p1 != p0:
            lines = np.arange(math.ceil(min(p0, p1)), math.floor(max(p0, p1)) + 1)
            cuts.append((lines - p0) / (p1 - p0))
    t = np.unique(np.clip(np.concatenate(cuts), 0.0, 1.0))
    mid = 0.5 * (t[:-1] + t[1:]) if len(t) > 1 else t
    mid = np.concatenate([mid, [0.0, 1.0]])  # the end points' own cells
    cols = np.floor(u[0] + mid * (u[1] - u[0])).astype(np.int64)
    rows = np.floor(v[0] + mid * (v[1] - v[0])).astype(np.int64)
    return rows, cols


def _grid_space(grid: FreeSpaceGrid) -> _Space:
    occupancy = grid.map

    def point_free(xy: np.ndarray) -> bool:
        return bool(grid.is_free(xy.reshape(1, 2))[0])

    def segment_free(a: np.ndarray, b: np.ndarray) -> bool:
        rows, cols = _cells_crossed(occupancy, a, b)
        inside = occupancy.contains_cell(rows, cols)  # outside the grid counts free
        return not bool(np.any(grid.blocked[rows[inside], cols[inside]]))

    def collision(xy: np.ndarray) -> str | None:
        if point_free(xy):
            return None
        rows, cols = occupancy.world_to_cell(xy.reshape(1, 2))
        row, col = int(rows[0]), int(cols[0])
        where = 'in an occupied cell' if grid.occupied[row, col] else (
            f'within {grid.inflation:g} m of an occupied cell')
        return (f'{where} (cell row {row}, column {col}) of the grid inflated by '
                f'{grid.inflation:g} m (robot_radius + clearance)')

    return _Space(point_free=point_free, segment_free=segment_free, collision=collision)


class _ExactMotionValidator(ob.MotionValidator):
    """OMPL motion validator that tests each edge exactly against the inflated obstacles.

    Polygons: segment against polygon; a grid: every cell the segment passes through.
    """

    def __init__(self, si: ob.SpaceInformation, space: _Space) -> None:
        super().__init__(si)
        self._segment_free = space.segment_free

    def checkMotion(self, s1: ob.State, s2: ob.State, *args: object) -> bool:
        """Return True if the straight motion from s1 to s2 is collision free (OMPL's name)."""
        a = np.array([s1[0], s1[1]])
        b = np.array([s2[0], s2[1]])
        return self._segment_free(a, b)


class _StateValidity:
    """State validity callable: inside the bounds and free (outside the inflated obstacles).

    A plain callable holding only NumPy data: it must not reference OMPL objects, or the
    reference cycle through C++ would keep them alive past the plan.
    """

    def __init__(self, space: _Space, bounds: tuple[float, float, float, float]):
        self._point_free = space.point_free
        self._bounds = bounds

    def __call__(self, state: ob.State) -> bool:
        x, y = state[0], state[1]
        xmin, xmax, ymin, ymax = self._bounds
        if not (xmin <= x <= xmax and ymin <= y <= ymax):
            return False
        return self._point_free(np.array([x, y]))


def _check_bounds(bounds: Sequence[float]) -> tuple[float, float, float, float]:
    """Return the bounds as floats, refusing empty or non-finite ones."""
    xmin, xmax, ymin, ymax = (float(v) for v in bounds)
    if not (all(map(math.isfinite, (xmin, xmax, ymin, ymax))) and xmin < xmax and ymin < ymax):
        msg = f'bounds must be finite (xmin, xmax, ymin, ymax) with min < max, got {bounds}'
        raise ValueError(msg)
    return xmin, xmax, ymin, ymax


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

    `on_grid` builds one over an inflated occupancy grid instead; it reads the grid at
    each plan, so cells that scans mark or clear between two plans count at the next one.

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
        self.config = config
        self.bounds = _check_bounds(bounds)
        self.grid: FreeSpaceGrid | None = None
        self.inflated_obstacles = tuple(
            obstacle.inflate(config.inflation) for obstacle in obstacles
        )
        self._obstacles = ObstacleSet(self.inflated_obstacles)
        self._space = _polygon_space(self._obstacles, config.inflation)

    @classmethod
    def on_grid(
        cls,
        grid: FreeSpaceGrid,
        *,
        config: PlannerConfig = PlannerConfig(),
        bounds: tuple[float, float, float, float] | None = None,
    ) -> RrtStarPlanner:
        """Return a planner whose states and edges are checked on an inflated grid.

        The grid carries its own inflation (perception's ``PlanningGrid(map,
        inflation=config.inflation)``); the planner does not inflate it again, and refuses
        a grid inflated by less than robot_radius + clearance.

        Args:
            grid: The inflated grid (kept by reference: later scans count at the next plan).
            config: Planner settings.
            bounds: (xmin, xmax, ymin, ymax) to sample; None: the grid's extent.

        Raises:
            ValueError: If the grid is inflated by less than ``config.inflation`` or the
                bounds are empty or not finite.

        """
        inflation = float(grid.inflation)
        if not inflation >= config.inflation - 1e-9:
            msg = (f'the grid is inflated by {inflation:g} m, less than robot_radius + '
                   f'clearance = {config.inflation:g} m')
            raise ValueError(msg)
        planner = cls([], grid_bounds(grid) if bounds is None else bounds, config=config)
        planner.grid = grid
        planner._space = _grid_space(grid)
        return planner

    def plan(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Plan a collision-free polyline from start to goal.

        Args:
            start: Start pose (x, y[, theta]); only x, y are used.
            goal: Goal pose (x, y[, theta]); only x, y are used.

        Returns:
            (M, 2) waypoints, M >= 2, with the first equal to start[:2] and the last equal to
            goal[:2]; every segment clears the inflated obstacles (or the inflated grid).

        Raises:
            PlanningError: If start or goal is out of bounds or in collision, or if RRT* finds
                no exact solution within the iterations and the time limit.

        """
        start_xy = self.check_endpoint(start, 'start')
        goal_xy = self.check_endpoint(goal, 'goal')
        if self._space.segment_free(start_xy, goal_xy):
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
        collision = self._space.collision(xy)
        if collision is not None:
            msg = f'{label} ({xy[0]:g}, {xy[1]:g}) is {collision}'
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
        setup.setStateValidityChecker(_StateValidity(self._space, self.bounds))
        info.setMotionValidator(_ExactMotionValidator(info, self._space))

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
