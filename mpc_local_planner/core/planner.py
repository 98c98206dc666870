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

"""Global planner: OMPL's RRT* in the plane, over obstacles or a grid, for a circle or a polygon.

The paper feeds the MPC an unsmoothed RRT* polyline: the MPC tracks the path's steady states
and copes with the corners itself, so the planner only has to be collision free. For a round
robot (``robot_radius``, the fast special case) it plans for a point in R^2 among obstacles
grown by the robot radius plus a clearance, and checks each tree edge exactly (segment
against convex polygon) rather than by sampling along it, so no thin obstacle corner slips
between two samples.

On a grid (`RrtStarPlanner.on_grid`: an occupancy grid inflated by a distance transform, as
perception's ``PlanningGrid`` keeps it from a map and scans), a state is checked by its
cell, and an edge exactly too: every cell it passes through must be free (not samples along
it, which could clip the corner of a blocked cell); the plane sampled is the grid's extent.

A convex polygon footprint (``PlannerConfig.footprint``, e.g. the BARN Jackal, 0.508 m x
0.430 m) turns the paper's Assumption 1 into a statement about poses: every pose g_p(s) of the
path the controller follows must keep the polygon ``clearance`` away from the obstacles. A
waypoint path's poses (core/paths.py) are straight segments driven at the segment's heading
and turns in place: at each corner, at the start (from the robot's heading to the first
segment) and at the goal (to the goal's heading). Of the two options, planning in SE(2) and
checking these poses, this module checks the poses (core/footprint_checks.py), and still
plans in the plane:

- an intermediate RRT* state is valid where the circumscribed disc (``Footprint.radius``)
  grown by the clearance is free: the robot can turn there to any heading, so the corner's
  turn is clear whatever the next segment;
- a motion a -> b is valid where the polygon driven straight at heading atan2(b - a) is:
  that swept region is the convex hull of the polygon at a and at b (a Minkowski sum with
  the segment), checked exactly against polygons (convex-convex separation, then the exact
  distance) and, on a grid, against the raw occupied cells (each by its centre, with half the
  cell's diagonal added, so the check is conservative);
- the start and the goal are valid where the polygon at their actual heading is, and the
  turns in place there are part of the motions out of the start and into the goal: each
  endpoint's reachable headings are found once per plan by rotating the polygon in fine
  steps (grown by r_c dtheta / 2, the most a point moves between two samples).

Why not SE(2): the path the controller follows (WaypointPath) derives every heading from the
positions (each segment at its direction, turns in place between them), so headings sampled
by an SE(2) planner would be discarded, or would need another path model and a 3-D search;
the checks above are exact for the path actually followed, keep RRT* 2-D with the same
sampling as the paper's planner, and leave the circle case untouched. The price: no corner
is placed where the robot could not turn fully, so a passage narrower than the circumscribed
circle (a 0.60 m gap for the Jackal, whose circle needs 0.67 m) is crossed by one straight
motion between states outside it, which RRT* has to sample aligned with the gap (a narrow
passage, as for any sampling planner: more iterations, or another seed, where it misses).

On a grid, where RRT* finds nothing (or only a path the final check refuses), a deterministic
grid search takes over (core/grid_search.py, as Nav2's NavFn and Smac search their costmaps):
Dijkstra over the cells where the inscribed disc grown by the clearance clears the occupied
cells, preferring room by a cost rather than a wider margin, then straight segments along
those cells kept only where the footprint's sweep and turns are clear (the checks below),
backing up from a corner the robot cannot turn at. On BARN's hardest worlds (200-299) no
chain of circumscribed discs joins start and goal in most worlds, so RRT* alone cannot
succeed there; the grid search finds them all at the start with the cylinders known.

After solving, `RrtStarPlanner.path_problem` checks every pose of the final path again,
turns included, and a path that fails is refused with a PlanningError that says where (with
``simplify``, a simplified path that fails gives way to RRT*'s own first: OMPL's simplifier
can keep an edge the motion validator refused, with only a warning).

Runs are reproducible: OMPL's global seed is set before each plan, and termination is by an
iteration count (the paper's figure uses 1000) with a wall-clock limit only as a safeguard.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
import contextlib
import copy
from dataclasses import dataclass, replace
import math
import threading
from typing import Any, Protocol

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.footprint import Footprint, parse_footprint
from mpc_local_planner.core.footprint_checks import (
    FootprintChecks,
    FootprintPlan,
    GridObstacles,
    NO_TURN,
    PolygonObstacles,
    SAME_POINT,
    wrap_heading,
)
from mpc_local_planner.core.grid_search import clearance_field, pull_string, shortest_cells
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet
from mpc_local_planner.core.paths import remaining_polyline

__all__ = [
    'EscapeGrid',
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



def _footprint_vertices(value: object) -> tuple[tuple[float, float], ...]:
    """Return a footprint setting as hashable vertices (() for a round robot).

    Accepts vertices [[x, y], ...], Nav2's string form, or a polygon `Footprint`; a polygon
    is validated (convex, with an interior) by `Footprint.polygon`.

    Raises:
        ValueError: If it is not a convex polygon, or a round `Footprint` (whose radius is
            ``robot_radius``'s job).

    """
    if value is None:
        return ()
    if isinstance(value, Footprint):
        if value.vertices is None:
            msg = 'a round robot is given by robot_radius, not a circle Footprint'
            raise ValueError(msg)
        vertices = value.vertices
    elif isinstance(value, str):
        parsed = parse_footprint(value)
        if parsed.vertices is None:
            return ()
        vertices = parsed.vertices
    else:
        if len(value) == 0:  # type: ignore[arg-type]
            return ()
        Footprint.polygon(value)  # type: ignore[arg-type]  # refuses what is not convex
        vertices = np.asarray(value, dtype=float)  # kept as given
    return tuple((float(x), float(y)) for x, y in np.asarray(vertices, dtype=float))


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
        robot_radius: Radius of the disk covering the robot, metres (without a footprint).
        clearance: Extra room beyond the robot, metres: room for the MPC to cut the
            polyline's corners and for its own collision margin. With a footprint, the
            distance every pose of the path keeps from the obstacles.
        simplify: Shortcut and smooth the path with OMPL's simplifier. Off by default: the
            paper's point is that the MPC does not need a smoothed path.
        footprint: The robot's convex polygon in its own frame, ((x, y), ...), x forward
            (Nav2's ``footprint``; its string form, a list of pairs or a polygon `Footprint`
            are accepted and stored as a tuple, so the config stays hashable). Empty: a
            circle of robot_radius. A polygon takes precedence over robot_radius, as in Nav2.

    """

    iterations: int = 1000
    time_limit: float = 5.0
    seed: int = 0
    range: float = 0.0
    robot_radius: float = 0.0
    clearance: float = 0.1
    simplify: bool = False
    footprint: tuple[tuple[float, float], ...] = ()

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
        try:
            object.__setattr__(self, 'footprint', _footprint_vertices(self.footprint))
        except (TypeError, ValueError) as err:
            problems.append(f'footprint must be a convex polygon [[x, y], ...] or empty: {err}')
        if problems:
            msg = 'invalid PlannerConfig: ' + '; '.join(problems)
            raise ValueError(msg)

    @property
    def robot_footprint(self) -> Footprint:
        """The robot the planner plans for: the polygon, or a circle of robot_radius."""
        if self.footprint:
            return Footprint.polygon(self.footprint)
        return Footprint.circle(self.robot_radius)

    @property
    def inflation(self) -> float:
        """Distance by which the planner grows the obstacles where the robot may turn, metres.

        robot_radius + clearance for a circle; for a polygon its circumscribed radius +
        clearance (the disc an intermediate waypoint needs free, and the least inflation of
        the grid `RrtStarPlanner.on_grid` accepts).
        """
        if self.footprint:
            return self.robot_footprint.radius + self.clearance
        return self.robot_radius + self.clearance

    @property
    def inscribed_radius(self) -> float:
        """The largest disc about the robot's origin inside its footprint, metres.

        What a re-plan that starts from a robot inside the inflation keeps from the
        obstacles on its first, short segment (PlanningGrid.escape_point). For a polygon,
        its faces' distances from the origin (Footprint.body, unit rows).
        """
        footprint = self.robot_footprint
        if footprint.is_circle:
            return footprint.radius
        return float(np.min(footprint.body.b))


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


class EscapeGrid(Protocol):
    """A grid that finds where a robot inside the inflation can start a plan from."""

    def escape_point(self, position: Sequence[float], *, within: float,
                     margin: float) -> np.ndarray | None:
        """Return the nearest clear point the robot can drive straight to, or None."""


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
    """Where a round robot's reference point may be: the queries the planner makes.

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


# ----------------------------------------------------------------------- footprint geometry
# Private helpers for the polygon footprint; they could move to core/footprint.py.

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


def _check_bounds(bounds: Sequence[float]) -> tuple[float, float, float, float]:
    """Return the bounds as floats, refusing empty or non-finite ones."""
    xmin, xmax, ymin, ymax = (float(v) for v in bounds)
    if not (all(map(math.isfinite, (xmin, xmax, ymin, ymax))) and xmin < xmax and ymin < ymax):
        msg = f'bounds must be finite (xmin, xmax, ymin, ymax) with min < max, got {bounds}'
        raise ValueError(msg)
    return xmin, xmax, ymin, ymax


class _TurnCheck:
    """The turns in place at one corner from one heading, found lazily, as `TurnRange` does.

    `FootprintChecks.turn_range` allows delta iff no sampled heading k turn_step away on
    delta's side, with (k - 1/2) turn_step < |delta|, is in collision: only those samples are
    checked, and each side's samples once (a small turn at a tight corner costs a few
    polygons, not a full circle).
    """

    def __init__(self, checks: FootprintChecks, xy: np.ndarray, heading: float) -> None:
        self._checks = checks
        self._xy = xy
        self._heading = heading
        self._free = checks.state_free(xy)
        self._clear = [0, 0]  # samples known clear per side (counter-clockwise, clockwise)
        self._blocked = [math.inf, math.inf]  # the first sample in collision per side

    def allows(self, delta: float) -> bool:
        """Say whether turning by delta radians (wrapped) is clear."""
        if self._free or abs(delta) <= NO_TURN:
            return True
        checks, side = self._checks, 0 if delta > 0 else 1
        count = min(math.ceil(abs(delta) / checks.turn_step + 0.5), checks.turn_samples + 1)
        if count <= self._clear[side]:
            return True
        if self._blocked[side] < count:
            return False
        steps = np.arange(self._clear[side], max(count, 2 * self._clear[side]))
        steps = steps[steps <= checks.turn_samples]
        headings = self._heading + math.copysign(checks.turn_step, delta) * steps
        c, s = np.cos(headings)[:, None], np.sin(headings)[:, None]
        x, y = checks.local[None, :, 0], checks.local[None, :, 1]
        polygons = np.stack([self._xy[0] + c * x - s * y, self._xy[1] + s * x + c * y],
                            axis=-1)
        hits = np.flatnonzero(checks.obstacles.polygons_hit(polygons, checks.turn_grow) >= 0)
        if len(hits):
            self._blocked[side] = int(steps[hits[0]])
            self._clear[side] = int(steps[hits[0]])
        else:
            self._clear[side] = int(steps[-1]) + 1
        return count <= self._clear[side]


def _distinct(points: np.ndarray) -> np.ndarray:
    """Drop consecutive points within SAME_POINT of the previous one (as WaypointPath)."""
    keep = np.concatenate([[True], np.linalg.norm(np.diff(points, axis=0), axis=1)
                           > SAME_POINT])
    return points[keep]


def _xy(point: np.ndarray) -> str:
    return f'({point[0]:g}, {point[1]:g})'


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
    With ``config.footprint`` the robot is that convex polygon and every pose of the path
    (segments and turns in place) is checked; otherwise it is a circle of robot_radius.

    Args:
        obstacles: The obstacles as described (not inflated); for a round robot the planner
            inflates them by ``config.robot_radius + config.clearance``.
        bounds: (xmin, xmax, ymin, ymax) of the plane the planner samples (where the robot's
            reference point may be).
        config: Planner settings.

    Attributes:
        obstacles: The obstacles as given.
        inflated_obstacles: The obstacles grown by ``config.inflation``: what a round
            robot's reference point avoids. With a polygon footprint the planner checks the
            polygon exactly against ``obstacles`` instead.

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
        self.footprint = config.robot_footprint
        self.obstacles = tuple(obstacles)
        self.inflated_obstacles = tuple(
            obstacle.inflate(config.inflation) for obstacle in obstacles
        )
        self._obstacles = ObstacleSet(self.inflated_obstacles)
        self._space = _polygon_space(self._obstacles, config.inflation)
        self._polygon_checks = None if self.footprint.is_circle else FootprintChecks(
            self.footprint, config.clearance, PolygonObstacles(self.obstacles))

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
        a grid inflated by less than ``config.inflation``. With a polygon footprint the
        inflated layer serves the states (where the robot turns), and the motions and the
        endpoints' poses are checked against the raw occupied cells.

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
            what = ('robot_radius + clearance' if not config.footprint
                    else "the footprint's circumscribed radius + clearance")
            msg = (f'the grid is inflated by {inflation:g} m, less than {what} = '
                   f'{config.inflation:g} m')
            raise ValueError(msg)
        planner = cls([], grid_bounds(grid) if bounds is None else bounds, config=config)
        planner.grid = grid
        planner._space = _grid_space(grid)
        return planner

    def plan(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Plan a collision-free polyline from start to goal.

        Args:
            start: Start pose (x, y[, theta]); for a round robot only x, y are used. With a
                footprint, theta is the robot's heading: the path first turns in place
                from it (no turn if theta is not given).
            goal: Goal pose (x, y[, theta]); with a footprint the path ends turning in
                place to theta (if given).

        Returns:
            (M, 2) waypoints, M >= 2, with the first equal to start[:2] and the last equal to
            goal[:2]; every segment clears the inflated obstacles (or the inflated grid); with
            a footprint, every pose of the path, turns in place included, keeps the
            clearance (`path_problem` finds nothing).

        Raises:
            PlanningError: If start or goal is out of bounds or in collision, if RRT* finds
                no exact solution within the iterations and the time limit, or (footprint)
                if the path it finds fails `path_problem`.

        """
        checks = self._footprint_checks()  # on a grid: one snapshot for the whole plan
        start_xy, start_heading = self._endpoint(start, 'start', checks)
        goal_xy, goal_heading = self._endpoint(goal, 'goal', checks)
        if checks is None:
            if self._space.segment_free(start_xy, goal_xy):
                # RRT* would converge to this segment anyway; skip the sampling.
                return np.vstack([start_xy, goal_xy])
            try:
                with _OMPL_LOCK, _ompl_log_level(ou.LOG_WARN):
                    waypoints = self._solve(start_xy, goal_xy, self._space.point_free,
                                            self._space.segment_free, lambda: '')[0]
            except PlanningError as err:
                return self._grid_fallback(str(err), None, (start_xy, None), (goal_xy, None))
            waypoints[0] = start_xy
            waypoints[-1] = goal_xy
            return waypoints
        direct = np.vstack([start_xy, goal_xy])
        if self._footprint_problem(checks, direct, start_heading, goal_heading) is None:
            return direct
        rules = FootprintPlan(checks, (start_xy, start_heading), (goal_xy, goal_heading))
        try:
            with _OMPL_LOCK, _ompl_log_level(ou.LOG_WARN):
                candidates = self._solve(start_xy, goal_xy, rules.state_valid,
                                         rules.motion_valid, rules.failure_hint)
        except PlanningError as err:
            return self._grid_fallback(str(err), rules, (start_xy, start_heading),
                                       (goal_xy, goal_heading))
        # The simplified path first, then RRT*'s own: OMPL's simplifier may keep an edge
        # the validator refused (it warns "may slightly touch on an invalid region").
        problem = None
        for waypoints in candidates:
            waypoints[0] = start_xy
            waypoints[-1] = goal_xy
            problem = self._footprint_problem(checks, waypoints, start_heading, goal_heading)
            if problem is None:
                return waypoints
        msg = f'RRT* found a path that the footprint cannot follow, refused: {problem}'
        return self._grid_fallback(msg, rules, (start_xy, start_heading),
                                   (goal_xy, goal_heading))

    def _grid_fallback(self, failure: str, rules: FootprintPlan | None,
                       start: tuple[np.ndarray, float | None],
                       goal: tuple[np.ndarray, float | None]) -> np.ndarray:
        """Return the grid search's path where RRT* failed; raise if there is none either.

        Only on a grid (`on_grid`): over polygons the failure stands.

        Raises:
            PlanningError: RRT*'s failure, with why the grid search found nothing either.

        """
        if self.grid is None:
            raise PlanningError(failure) from None
        waypoints, why = self._grid_route(rules, start, goal)
        if waypoints is None:
            msg = f'{failure}; the grid search found no path either: {why}'
            raise PlanningError(msg) from None
        return waypoints

    def _grid_route(self, rules: FootprintPlan | None, start: tuple[np.ndarray, float | None],
                    goal: tuple[np.ndarray, float | None]) -> tuple[np.ndarray | None, str]:
        """Search the grid's cells for a corridor, then keep the segments the robot can follow.

        Round robot: the cells the grid does not block, each segment free of blocked cells
        (as RRT*'s edges). Footprint: the cells where the inscribed disc grown by the
        clearance clears every occupied cell's centre by half a cell's diagonal (necessary
        for any heading), preferring room (core/grid_search.py); then `pull_string` keeps
        straight segments the footprint sweeps clear with clear turns at their corners, the
        start's and the goal's included (`path_problem`'s rules).

        Returns:
            (waypoints, '') or (None, why there is no path).

        """
        assert self.grid is not None
        occupancy = self.grid.map
        (start_xy, start_heading), (goal_xy, goal_heading) = start, goal
        rows, cols = occupancy.world_to_cell(np.array([start_xy, goal_xy]))
        if not np.all(occupancy.contains_cell(rows, cols)):
            return None, 'the start or the goal is off the grid'
        resolution = float(occupancy.resolution)
        clearance = clearance_field(self.grid.occupied, resolution)
        if rules is None:
            threshold, blocked = self.config.inflation, np.array(self.grid.blocked, dtype=bool)
            needs = f'cells clear of the inflation ({self.config.inflation:g} m)'
        else:
            threshold = (self.config.inscribed_radius + self.config.clearance
                         + resolution * math.sqrt(0.5))
            blocked = None
            needs = (f'cells {threshold:.3g} m from the occupied ones (the inscribed radius, '
                     f'the clearance and half a cell diagonal)')
        cells = shortest_cells(clearance, threshold, (int(rows[0]), int(cols[0])),
                               (int(rows[1]), int(cols[1])), resolution=resolution,
                               blocked=blocked)
        if cells is None:
            return None, f'no {needs} connect the start and the goal'
        points = occupancy.cell_to_world(cells[:, 0], cells[:, 1])
        if len(points) < 2:
            points = np.vstack([start_xy, goal_xy])
        points[0], points[-1] = start_xy, goal_xy
        motion_ok = (self._circle_motion(points) if rules is None
                     else self._footprint_motion(rules, points))
        corners = pull_string(points, motion_ok)
        if corners is None:
            return None, (f'{len(cells)} cells connect the start and the goal, but the robot '
                          'cannot follow them')
        waypoints = points[corners]
        problem = self.path_problem(waypoints, start_heading=start_heading,
                                    goal_heading=goal_heading)
        if problem is not None:  # pull_string asks the same questions: a safeguard
            return None, f'the path through the cells fails the final check: {problem}'
        return waypoints, ''

    def _circle_motion(self, points: np.ndarray) -> Callable[[int, int, int | None], bool]:
        """Return `pull_string`'s motion check for a round robot: the segment's cells."""
        def motion_ok(i: int, j: int, previous: int | None) -> bool:
            return self._space.segment_free(points[i], points[j])
        return motion_ok

    @staticmethod
    def _footprint_motion(rules: FootprintPlan,
                          points: np.ndarray) -> Callable[[int, int, int | None], bool]:
        """Return `pull_string`'s motion check for a footprint (`path_problem`'s rules).

        The motion i -> j: the turn in place at i (from the start heading at the start, else
        from the segment into i), the swept footprint, and the turn to the goal heading
        where j is the goal.
        """
        checks, last = rules.checks, len(points) - 1
        turns: dict[tuple[int, int], _TurnCheck] = {}

        def motion_ok(i: int, j: int, previous: int | None) -> bool:
            a, b = points[i], points[j]
            if math.hypot(b[0] - a[0], b[1] - a[1]) <= SAME_POINT:
                return False
            heading = math.atan2(b[1] - a[1], b[0] - a[0])
            if previous is None:
                if (rules.start_turns is not None and rules.start_heading is not None
                        and not rules.start_turns.allows(
                            wrap_heading(heading - rules.start_heading))):
                    return False
            else:
                p = points[previous]
                incoming = math.atan2(a[1] - p[1], a[0] - p[0])
                delta = wrap_heading(heading - incoming)
                if abs(delta) > NO_TURN:
                    if (previous, i) not in turns:
                        turns[previous, i] = _TurnCheck(checks, a, incoming)
                    if not turns[previous, i].allows(delta):
                        return False
            if (j == last and rules.goal_turns is not None and rules.goal_heading is not None
                    and not rules.goal_turns.allows(
                        -wrap_heading(rules.goal_heading - heading))):
                return False
            return checks.sweep_hit(a, b) < 0
        return motion_ok

    def path_problem(self, waypoints: np.ndarray, *, start_heading: float | None = None,
                     goal_heading: float | None = None) -> str | None:
        """Say why the robot cannot follow a waypoint path, or None if every pose is clear.

        The path as core/paths.py's WaypointPath makes it: turn in place from start_heading
        to the first segment (if given), drive each segment at its heading, turn in place
        at each corner the short way, turn to goal_heading at the end (if given). Round
        robot: every segment against the inflated obstacles (or grid), as the planner checks
        its edges. Footprint: every straight segment exactly (the swept polygon), every
        turn at headings a fine step apart grown to cover the headings between them (a
        turn where the circumscribed disc is free is clear at once), each grown by the
        clearance; consecutive waypoints within 1e-6 m count as one.

        Args:
            waypoints: (M, 2) positions (further columns are ignored).
            start_heading: The robot's heading at the first waypoint, radians.
            goal_heading: The heading to end with, radians.

        Returns:
            None if the path is clear, else what is in collision, and where.

        """
        points = np.atleast_2d(np.asarray(waypoints, dtype=float))[:, :2]
        checks = self._footprint_checks()
        if checks is None:
            for i, (a, b) in enumerate(zip(points[:-1], points[1:], strict=True)):
                if not self._space.segment_free(a, b):
                    return (f'segment {i} from {_xy(a)} to {_xy(b)} meets the obstacles grown '
                            f'by {self.config.inflation:g} m (robot_radius + clearance)')
            return None
        return self._footprint_problem(checks, points, start_heading, goal_heading)

    def replan(self, start: np.ndarray, goal: np.ndarray, *, failures: int = 0,
               grid: EscapeGrid | None = None, escape_distance: float = 1.0) -> np.ndarray:
        """Plan again from where the robot is (global_planner and the navigator both do).

        After failures failed re-plans the seed moves on by their count: the same seed on
        the same grid would fail the same way. The MPC keeps a smaller margin than the
        planner's clearance, so a robot that stopped in front of an obstacle it has just
        seen may stand within the clearance, where no plan can start; with a grid, the plan
        then starts from the nearest clear cell the robot can drive straight to (within
        escape_distance, never closer to an obstacle than inscribed_radius or than the robot
        already is) and begins with that short segment.

        Raises:
            PlanningError: as plan() does, when no escape helps either.

        """
        planner = self
        if failures:
            planner = copy.copy(self)
            planner.config = replace(self.config,
                                     seed=(self.config.seed + failures) % (_MAX_SEED + 1))
        try:
            return planner.plan(start, goal)
        except PlanningError:
            if grid is None:
                raise
            escape = grid.escape_point(start, within=escape_distance,
                                       margin=self.config.inscribed_radius)
            if escape is None:
                raise
            return np.vstack([np.asarray(start, dtype=float)[:2], planner.plan(escape, goal)])

    def rest_problem(self, plan: np.ndarray, position: Sequence[float]) -> str | None:
        """Say why the rest of a plan no longer passes this planner's check, or None.

        The re-planning test, the same rule plans are made with (path_problem): the rest of
        the plan from the robot's projection onto it, where obstacles marked since (the
        laser's) may now violate the clearance. Its first config.inflation metres are left
        out: a robot passing an obstacle may stand within the planner's clearance of it
        (the MPC keeps a smaller margin), and a plan made from there starts there; judging
        that stretch would re-plan at every check while the robot passes.

        Args:
            plan: (M, 2+) waypoints of the plan in force.
            position: (x, y) of the robot.

        Returns:
            None if the rest is clear, else what is in collision, and where.

        """
        rest = remaining_polyline(plan, position)
        if len(rest) < 2:
            return None
        lengths = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(rest, axis=0).T))])
        skip = self.config.inflation
        if lengths[-1] <= skip:
            return None
        k = int(np.searchsorted(lengths, skip, side='right')) - 1
        t = (skip - lengths[k]) / max(lengths[k + 1] - lengths[k], 1e-12)
        start = rest[k] + t * (rest[k + 1] - rest[k])
        return self.path_problem(np.vstack([start, rest[k + 1:]]))

    def check_endpoint(self, pose: np.ndarray, label: str) -> np.ndarray:
        """Return pose[:2] after checking it is finite, in bounds and clear of the obstacles.

        Round robot: clear of the obstacles as the planner grows them (robot_radius +
        clearance). Footprint: the polygon at the pose's heading, grown by the clearance,
        is clear (without a heading, the disc it covers at every heading). A start or goal
        that passes this may still be walled off, but one that fails it can never be
        planned to.

        Args:
            pose: (x, y[, theta]).
            label: what the pose is ('start', 'goal'), for the message.

        Raises:
            PlanningError: saying why the pose cannot be planned from or to.

        """
        return self._endpoint(pose, label, self._footprint_checks())[0]

    def _endpoint(self, pose: np.ndarray, label: str,
                  checks: FootprintChecks | None) -> tuple[np.ndarray, float | None]:
        """Check a start or goal (see `check_endpoint`); return its x, y and heading."""
        values = np.asarray(pose, dtype=float).reshape(-1)
        xy = values[:2]
        if len(xy) != 2 or not np.all(np.isfinite(xy)):
            msg = f'{label} must hold finite x and y, got {pose!r}'
            raise PlanningError(msg)
        xmin, xmax, ymin, ymax = self.bounds
        if not (xmin <= xy[0] <= xmax and ymin <= xy[1] <= ymax):
            msg = f'{label} ({xy[0]:g}, {xy[1]:g}) is outside the bounds {self.bounds}'
            raise PlanningError(msg)
        if checks is None:
            collision = self._space.collision(xy)
            if collision is not None:
                msg = f'{label} ({xy[0]:g}, {xy[1]:g}) is {collision}'
                raise PlanningError(msg)
            return xy, None
        heading = float(values[2]) if len(values) > 2 else None
        if heading is not None and not math.isfinite(heading):
            msg = f'{label} heading must be finite, got {pose!r}'
            raise PlanningError(msg)
        problem = checks.pose_problem(xy, heading)
        if problem is not None:
            msg = f'{label} ({xy[0]:g}, {xy[1]:g}) is {problem}'
            raise PlanningError(msg)
        return xy, heading

    def _footprint_checks(self) -> FootprintChecks | None:
        """Return the footprint's checks (on a grid: of the grid now), None for a circle."""
        if self.footprint.is_circle:
            return None
        if self.grid is None:
            return self._polygon_checks
        return FootprintChecks(self.footprint, self.config.clearance,
                                GridObstacles(self.grid))

    @staticmethod
    def _footprint_problem(checks: FootprintChecks, waypoints: np.ndarray,
                           start_heading: float | None, goal_heading: float | None) -> str | None:
        """Check every pose of a waypoint path for a polygon footprint (see `path_problem`).

        The same queries as the planner's motions (`FootprintPlan`), so a path RRT* built
        passes: segments by the swept polygon, turns by `FootprintChecks.turn_range` (from
        the start heading, from the incoming heading at a corner, and from the goal heading
        backwards at the goal).
        """
        points = _distinct(np.atleast_2d(np.asarray(waypoints, dtype=float))[:, :2])
        if len(points) == 1:  # a turn in place only
            if start_heading is None or goal_heading is None:
                return None
            delta = wrap_heading(goal_heading - start_heading)
            turns = checks.turn_range(points[0], start_heading)
            if turns.allows(delta):
                return None
            return (f'turning in place at {_xy(points[0])} from heading {start_heading:.3g} to '
                    f'{goal_heading:.3g} rad: {turns.why(delta)}')
        # math.atan2, as the planner's motions compute it (bit for bit the same headings)
        headings = [math.atan2(b[1] - a[1], b[0] - a[0])
                    for a, b in zip(points[:-1], points[1:], strict=True)]
        if start_heading is not None:
            delta = wrap_heading(headings[0] - start_heading)
            turns = checks.turn_range(points[0], start_heading)
            if not turns.allows(delta):
                return (f'turning in place at the start {_xy(points[0])} from heading '
                        f'{start_heading:.3g} to {headings[0]:.3g} rad: {turns.why(delta)}')
        for i, (a, b) in enumerate(zip(points[:-1], points[1:], strict=True)):
            hit = checks.sweep_hit(a, b)
            if hit >= 0:
                return (f'segment {i} from {_xy(a)} to {_xy(b)}: the footprint driven along it '
                        f'at heading {headings[i]:.3g} rad meets '
                        f'{checks.obstacles.describe(hit)} grown by the clearance '
                        f'{checks.clearance:g} m')
            if i == 0:
                continue
            delta = wrap_heading(headings[i] - headings[i - 1])
            if abs(delta) <= NO_TURN:
                continue
            turns = checks.turn_range(a, headings[i - 1])
            if not turns.allows(delta):
                return (f'turning in place at waypoint {i} {_xy(a)} from heading '
                        f'{headings[i - 1]:.3g} to {headings[i]:.3g} rad: {turns.why(delta)}')
        if goal_heading is not None:
            delta = wrap_heading(goal_heading - headings[-1])
            turns = checks.turn_range(points[-1], goal_heading)
            if not turns.allows(-delta):
                return (f'turning in place at the goal {_xy(points[-1])} from heading '
                        f'{headings[-1]:.3g} to the goal heading {goal_heading:.3g} rad: '
                        f'{turns.why(-delta)}')
        return None

    def _solve(self, start_xy: np.ndarray, goal_xy: np.ndarray,
               state_free: Callable[[np.ndarray], bool],
               motion_free: Callable[[np.ndarray, np.ndarray], bool],
               failure_hint: Callable[[], str]) -> list[np.ndarray]:
        """Run OMPL's RRT*; the caller holds the lock (OMPL's seed is process-wide).

        Returns:
            The (M, 2) path: with ``simplify``, the simplified one and then RRT*'s own.

        """
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
        setup.setStateValidityChecker(_StateValidity(state_free, self.bounds))
        info.setMotionValidator(_ExactMotionValidator(info, motion_free))

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
                f'{failure_hint()}'
            )
            raise PlanningError(msg)
        paths = [self._states(setup)]
        if config.simplify:
            setup.simplifySolution()
            paths.insert(0, self._states(setup))
        return paths

    @staticmethod
    def _states(setup: og.SimpleSetup) -> np.ndarray:
        """Return the solution path's states as (M, 2) points."""
        states = setup.getSolutionPath().getStates()
        return np.array([[state[0], state[1]] for state in states], dtype=float)
