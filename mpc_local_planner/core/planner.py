# SPDX-License-Identifier: Apache-2.0
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
backing up from a corner the robot cannot turn at. Where no chain of free circumscribed
discs joins start and goal, RRT* alone cannot succeed and the grid search can
(docs/design/measurements.md, Grid search fallback).

After solving, `RrtStarPlanner.path_problem` checks every pose of the final path again,
turns included, and a path that fails is refused with a PlanningError that says where (with
``simplify``, a simplified path that fails gives way to RRT*'s own first: OMPL's simplifier
can keep an edge the motion validator refused, with only a warning).

Runs are reproducible: OMPL's global seed is set before each plan, and termination is by an
iteration count (the paper's figure uses 1000) with a wall-clock limit only as a safeguard.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import copy
from dataclasses import replace
import math

import numpy as np

from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.footprint_checks import (
    FootprintChecks,
    FootprintPlan,
    GridObstacles,
    HeldChecks,
    PolygonObstacles,
)
from mpc_local_planner.core.footprint_paths import (
    footprint_motion,
    footprint_path_problem,
    xy_text,
)
from mpc_local_planner.core.free_space import (
    EscapeGrid,
    FreeSpaceGrid,
    grid_bounds,
    grid_space,
    polygon_space,
)
from mpc_local_planner.core.grid_search import clearance_field, pull_string, shortest_cells
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet, polygon_separation
from mpc_local_planner.core.paths import remaining_polyline
from mpc_local_planner.core.planner_config import PlannerConfig
from mpc_local_planner.core.rrt_star import MAX_SEED, rrt_star

__all__ = [
    'RrtStarPlanner',
    'path_length',
]


# RrtStarPlanner._drive_on_heading: headings tried per half turn, lengths up to
# drive_on_heading_distance, and the most grid searches from the points reached.
DRIVE_ON_HEADING_SAMPLES = 12
DRIVE_ON_HEADING_STEPS = 5
DRIVE_ON_HEADING_TRIES = 6

# A start standing closer to the held obstacles than start_clearance keeps its clearance less
# this (metres), so that its own pose passes the checks.
_HELD_SLACK = 1e-4


def path_length(waypoints: np.ndarray) -> float:
    """Return the length of the polyline through the waypoints ((M, 2) or (M, 3): x, y used)."""
    pts = np.asarray(waypoints, dtype=float)
    if pts.ndim != 2 or len(pts) < 2:
        return 0.0
    return float(np.sum(np.linalg.norm(np.diff(pts[:, :2], axis=0), axis=1)))



def _check_bounds(bounds: Sequence[float]) -> tuple[float, float, float, float]:
    """Return the bounds as floats, refusing empty or non-finite ones."""
    xmin, xmax, ymin, ymax = (float(v) for v in bounds)
    if not (all(map(math.isfinite, (xmin, xmax, ymin, ymax))) and xmin < xmax and ymin < ymax):
        msg = f'bounds must be finite (xmin, xmax, ymin, ymax) with min < max, got {bounds}'
        raise ValueError(msg)
    return xmin, xmax, ymin, ymax



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
        self._space = polygon_space(self._obstacles, config.inflation)
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
        planner._space = grid_space(grid)
        return planner

    def plan(self, start: np.ndarray, goal: np.ndarray, *,
             local_obstacles: Sequence[ConvexPolygon] = ()) -> np.ndarray:
        """Plan a collision-free polyline from start to goal.

        Args:
            start: Start pose (x, y[, theta]); for a round robot only x, y are used. With a
                footprint, theta is the robot's heading: the path first turns in place
                from it (no turn if theta is not given).
            goal: Goal pose (x, y[, theta]); with a footprint the path ends turning in
                place to theta (if given).
            local_obstacles: The obstacles the local controller holds (as sensed, not
                grown). With a footprint and a start heading, every pose must also keep
                config.start_clearance from them (`held_checks`), and where no plan leaves
                the start, one may first drive on (`_drive_on_heading`).

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
        if checks is not None and len(local_obstacles):
            checks = self.held_checks(checks, start, local_obstacles)
        start_xy, start_heading = self._endpoint(start, 'start', checks)
        goal_xy, goal_heading = self._endpoint(goal, 'goal', checks)
        if checks is None:
            if self._space.segment_free(start_xy, goal_xy):
                # RRT* would converge to this segment anyway; skip the sampling.
                return np.vstack([start_xy, goal_xy])
            try:
                waypoints = self._rrt_star(start_xy, goal_xy, self._space.point_free,
                                        self._space.segment_free, lambda: '')[0]
            except PlanningError as err:
                return self._grid_fallback(str(err), None, (start_xy, None), (goal_xy, None))
            waypoints[0] = start_xy
            waypoints[-1] = goal_xy
            return waypoints
        try:
            return self._footprint_plan(checks, (start_xy, start_heading),
                                        (goal_xy, goal_heading))
        except PlanningError:
            if not len(local_obstacles):
                raise
            waypoints = self._drive_on_heading(checks, (start_xy, start_heading),
                                               (goal_xy, goal_heading))
            if waypoints is None:
                raise
            return waypoints

    def _footprint_plan(self, checks: FootprintChecks, start: tuple[np.ndarray, float | None],
                        goal: tuple[np.ndarray, float | None]) -> np.ndarray:
        """Plan for a footprint: the straight line, RRT*, then the grid search (`plan`)."""
        (start_xy, start_heading), (goal_xy, goal_heading) = start, goal
        direct = np.vstack([start_xy, goal_xy])
        if footprint_path_problem(checks, direct, start_heading, goal_heading) is None:
            return direct
        rules = FootprintPlan(checks, (start_xy, start_heading), (goal_xy, goal_heading))
        try:
            candidates = self._rrt_star(start_xy, goal_xy, rules.state_valid,
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
            problem = footprint_path_problem(checks, waypoints, start_heading, goal_heading)
            if problem is None:
                return waypoints
        msg = f'RRT* found a path that the footprint cannot follow, refused: {problem}'
        return self._grid_fallback(msg, rules, (start_xy, start_heading),
                                   (goal_xy, goal_heading))

    def _drive_on_heading(self, checks: FootprintChecks,
                          start: tuple[np.ndarray, float | None],
                          goal: tuple[np.ndarray, float | None]) -> np.ndarray | None:
        """Return a path that first drives straight on to where the robot can turn, or None.

        For a start whose turns in place do not reach the way out (a tight start: the
        footprint cannot turn there towards it): straight motions on headings the start's
        turns allow, DRIVE_ON_HEADING_STEPS long up to config.drive_on_heading_distance,
        to a point where the robot can turn to any heading, nearest first and, at each
        length, the smallest turn first; from the first such point the grid search finds
        a way on (at most DRIVE_ON_HEADING_TRIES searched), the whole path is checked
        again. Only on a grid, with a start heading.
        """
        (start_xy, start_heading), (goal_xy, goal_heading) = start, goal
        reach = self.config.drive_on_heading_distance
        if self.grid is None or start_heading is None or not reach > 0.0:
            return None
        turns = checks.turn_range(start_xy, start_heading)
        if math.isinf(turns.low) and math.isinf(turns.high):
            return None  # it can turn anywhere: driving on first is no help
        deltas = np.arange(-DRIVE_ON_HEADING_SAMPLES, DRIVE_ON_HEADING_SAMPLES + 1) * (
            math.pi / DRIVE_ON_HEADING_SAMPLES)
        deltas = deltas[np.argsort(np.abs(deltas), kind='stable')]
        deltas = [float(d) for d in deltas if turns.allows(float(d))]
        lengths = np.arange(1, DRIVE_ON_HEADING_STEPS + 1) * (reach / DRIVE_ON_HEADING_STEPS)
        tries = 0
        for length in lengths:
            for delta in deltas:
                heading = start_heading + delta
                point = start_xy + length * np.array([math.cos(heading), math.sin(heading)])
                if not (checks.state_free(point) and checks.sweep_hit(start_xy, point) < 0):
                    continue
                tries += 1
                rules = FootprintPlan(checks, (point, None), (goal_xy, goal_heading))
                rest, _ = self._grid_route(rules, (point, None), (goal_xy, goal_heading))
                if rest is not None:
                    waypoints = np.vstack([start_xy, rest])
                    if footprint_path_problem(checks, waypoints, start_heading,
                                              goal_heading) is None:
                        return waypoints
                if tries >= DRIVE_ON_HEADING_TRIES:
                    return None
        return None

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
                     else footprint_motion(rules, points))
        corners = pull_string(points, motion_ok)
        if corners is None:
            return None, (f'{len(cells)} cells connect the start and the goal, but the robot '
                          'cannot follow them')
        waypoints = points[corners]
        problem = (self.path_problem(waypoints, start_heading=start_heading,
                                     goal_heading=goal_heading) if rules is None
                   else footprint_path_problem(rules.checks, waypoints, start_heading,
                                               goal_heading))
        if problem is not None:  # pull_string asks the same questions: a safeguard
            return None, f'the path through the cells fails the final check: {problem}'
        return waypoints, ''

    def _circle_motion(self, points: np.ndarray) -> Callable[[int, int, int | None], bool]:
        """Return `pull_string`'s motion check for a round robot: the segment's cells."""
        def motion_ok(i: int, j: int, previous: int | None) -> bool:
            return self._space.segment_free(points[i], points[j])
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
                    return (f'segment {i} from {xy_text(a)} to {xy_text(b)} meets the obstacles '
                            f'grown by {self.config.inflation:g} m (robot_radius + clearance)')
            return None
        return footprint_path_problem(checks, points, start_heading, goal_heading)

    def held_checks(self, checks: FootprintChecks, start: np.ndarray,
                    local_obstacles: Sequence[ConvexPolygon]) -> FootprintChecks:
        """Return checks that keep config.start_clearance from the held obstacles too.

        The local controller's convex pieces may reach farther than the planner's obstacles
        (a grid marks the cells the laser hit; a piece is a rectangle along a row of them),
        and a path the controller's own obstacles forbid is one it cannot follow. A start
        already closer to them than config.start_clearance plus the turn checks' sampling
        allowance keeps what it has, less a tenth of a millimetre, so that it may turn
        away from a piece it stands beside; the clearance never goes below touching. A
        start without a heading, or one that already meets a piece (a stale memory), gets
        the planner's checks alone.
        """
        pose = np.asarray(start, dtype=float).reshape(-1)
        if len(pose) < 3 or not np.all(np.isfinite(pose[:3])):
            return checks
        held = ObstacleSet(tuple(local_obstacles))
        standing = float(np.min(polygon_separation(self.footprint.at(pose[:3]), held)[0]))
        if not standing > 0.0:
            return checks
        sampling = checks.turn_grow - checks.clearance  # what a turn's samples are grown by
        clearance = min(self.config.start_clearance, standing - sampling - _HELD_SLACK)
        return HeldChecks(self.footprint, checks.clearance, checks.obstacles,
                          PolygonObstacles(local_obstacles), clearance)

    def replan(self, start: np.ndarray, goal: np.ndarray, *, failures: int = 0,
               grid: EscapeGrid | None = None, escape_distance: float = 1.0,
               local_obstacles: Sequence[ConvexPolygon] = ()) -> np.ndarray:
        """Plan again from where the robot is (global_planner and the navigator both do).

        After failures failed re-plans the seed moves on by their count: the same seed on
        the same grid would fail the same way. The MPC keeps a smaller margin than the
        planner's clearance, so a robot that stopped in front of an obstacle it has just
        seen may stand within the clearance, where no plan can start; with a grid, the plan
        then starts from the nearest clear cell the robot can drive straight to (within
        escape_distance, never closer to an obstacle than inscribed_radius or than the robot
        already is) and begins with that short segment. A robot outside the bounds with no
        such escape is planned for from `way_in` (the nearest pose within them), the plan
        beginning with the segment back.

        With local_obstacles (the local controller's convex pieces), a plan that does not
        keep config.start_clearance from them too (`held_problem`: a turn the grid allows
        but they forbid, by a robot among pieces that reach past the grid) gives way to
        one that does (`plan` with them), where there is one: the robot is sent on by
        motions it can make. A plan that keeps it stays as it is.

        Raises:
            PlanningError: as plan() does, when no escape helps either.

        """
        planner = self
        if failures:
            planner = copy.copy(self)
            planner.config = replace(self.config,
                                     seed=(self.config.seed + failures) % (MAX_SEED + 1))
        try:
            waypoints = planner.plan(start, goal)
        except PlanningError:
            escape = None if grid is None else grid.escape_point(
                start, within=escape_distance, margin=self.config.inscribed_radius)
            if escape is not None:
                return np.vstack([np.asarray(start, dtype=float)[:2],
                                  planner.plan(escape, goal)])
            way_in = self.way_in(start)
            if way_in is None:
                raise
            # off the plane the planner samples, beyond any escape: plan from its edge
            return np.vstack([np.asarray(start, dtype=float)[:2],
                              self.replan(way_in, goal, failures=failures, grid=grid,
                                          escape_distance=escape_distance,
                                          local_obstacles=local_obstacles)])
        if (not len(local_obstacles)
                or planner.held_problem(waypoints, start, goal, local_obstacles) is None):
            return waypoints
        try:  # a plan the controller's obstacles allow, where there is one
            return planner.plan(start, goal, local_obstacles=local_obstacles)
        except PlanningError:
            return waypoints

    def way_in(self, start: np.ndarray) -> np.ndarray | None:
        """Return the pose a re-plan starts from for a robot outside the bounds, else None.

        A robot may leave the plane the planner samples (stepping out of a walker's way,
        pushed, or localized anew), where no plan can start, and would stand there for good.
        Its way back is the straight segment to the nearest point of the bounds that its
        footprint's circumscribed disc (plus the clearance) fits within, heading along that
        segment; the local controller avoids what it sees on the way, as on any plan. None
        for a start within the bounds (or not finite: `plan` says why).
        """
        values = np.asarray(start, dtype=float).reshape(-1)
        xy = values[:2]
        xmin, xmax, ymin, ymax = self.bounds
        if len(xy) != 2 or not np.all(np.isfinite(xy)) or (
                xmin <= xy[0] <= xmax and ymin <= xy[1] <= ymax):
            return None
        inset = min(self.config.inflation, 0.5 * (xmax - xmin), 0.5 * (ymax - ymin))
        inside = np.array([min(max(xy[0], xmin + inset), xmax - inset),
                           min(max(xy[1], ymin + inset), ymax - inset)])
        offset = inside - xy
        return np.array([inside[0], inside[1], math.atan2(offset[1], offset[0])])

    def held_problem(self, waypoints: np.ndarray, start: np.ndarray, goal: np.ndarray,
                     local_obstacles: Sequence[ConvexPolygon]) -> str | None:
        """Say why a path from start fails `held_checks`, or None (None for a circle too)."""
        checks = self._footprint_checks()
        if checks is None:
            return None
        checks = self.held_checks(checks, start, local_obstacles)
        start_pose = np.asarray(start, dtype=float).reshape(-1)
        goal_pose = np.asarray(goal, dtype=float).reshape(-1)
        return footprint_path_problem(
            checks, np.atleast_2d(np.asarray(waypoints, dtype=float))[:, :2],
            float(start_pose[2]) if len(start_pose) > 2 else None,
            float(goal_pose[2]) if len(goal_pose) > 2 else None)

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
        rest = remaining_polyline(plan, position).points
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

    def _rrt_star(self, start_xy: np.ndarray, goal_xy: np.ndarray,
                  state_free: Callable[[np.ndarray], bool],
                  motion_free: Callable[[np.ndarray, np.ndarray], bool],
                  failure_hint: Callable[[], str]) -> list[np.ndarray]:
        """Run RRT* (core/rrt_star.py) with this planner's bounds and settings."""
        config = self.config
        return rrt_star(start_xy, goal_xy, bounds=self.bounds, state_free=state_free,
                        motion_free=motion_free, failure_hint=failure_hint, seed=config.seed,
                        iterations=config.iterations, time_limit=config.time_limit,
                        extension=config.range, simplify=config.simplify)
