# SPDX-License-Identifier: Apache-2.0
"""Tests of the global planner with a convex polygon footprint (the BARN Jackal).

Every pose of the path the controller follows (core/paths.py's WaypointPath: segments at
their heading, turns in place at the corners, the start and the goal) is checked here by an
independent brute force: the path's poses a few millimetres and milliradians apart, each
polygon's boundary sampled every 2 mm, against the obstacles' exact distance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core import planner as planner_module
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import WaypointPath
from mpc_local_planner.core.planner import RrtStarPlanner
from mpc_local_planner.core.planner_config import PlannerConfig
from mpc_local_planner.perception.grids import PlanningGrid
from mpc_local_planner.worlds.map_files import OccupancyMap

CLEARANCE = 0.05
# The Jackal is 0.430 m wide: 0.53 m with the clearance on both sides fits a 0.60 m gap;
# its circumscribed circle (radius 0.333 m) needs 0.77 m.
JACKAL_CONFIG = PlannerConfig(footprint=JACKAL, clearance=CLEARANCE, iterations=1000,
                              time_limit=60.0)
CIRCLE_CONFIG = PlannerConfig(robot_radius=JACKAL.radius, clearance=CLEARANCE, iterations=1000,
                              time_limit=60.0)
# A wall at x in [2.9, 3.1] across the whole space, with a 0.60 m gap at y in [1.7, 2.3].
GAP_BOUNDS = (0.0, 6.0, 0.0, 4.0)
GAP_WALL = [ConvexPolygon.from_box(2.9, -1.0, 3.1, 1.7),
            ConvexPolygon.from_box(2.9, 2.3, 3.1, 5.0)]
RESOLUTION = 0.05


def gap_map() -> OccupancyMap:
    """The gap world as a 6 m x 4 m grid: its occupied cells are exactly the wall's boxes."""
    data = np.zeros((80, 120), dtype=np.int8)
    data[0:34, 58:62] = 100  # x in [2.9, 3.1], y in [0, 1.7]
    data[46:80, 58:62] = 100  # y in [2.3, 4.0]
    return OccupancyMap(data=data, resolution=RESOLUTION)


def gap_planner(mode: str, config: PlannerConfig) -> RrtStarPlanner:
    if mode == 'polygons':
        return RrtStarPlanner(GAP_WALL, GAP_BOUNDS, config=config)
    grid = PlanningGrid(gap_map(), inflation=config.inflation)
    return RrtStarPlanner.on_grid(grid, config=config)


# ------------------------------------------------------------------ the brute-force check
def path_poses(waypoints: np.ndarray, start_heading: float | None,
               goal_heading: float | None, step: float = 0.002) -> np.ndarray:
    """Return the poses of the path the controller follows, <= step m and step rad apart."""
    knots = WaypointPath(waypoints, start_heading=start_heading, goal_heading=goal_heading,
                         capacity=200).knots
    pieces = [knots[:1]]
    for a, b in zip(knots[:-1], knots[1:], strict=True):
        count = int(max(np.hypot(*(b[:2] - a[:2])) / step, abs(b[2] - a[2]) / step, 1))
        pieces.append(a + np.linspace(0.0, 1.0, count + 1)[1:, None] * (b - a))
    return np.concatenate(pieces)


def footprint_distance(poses: np.ndarray, obstacles: list[ConvexPolygon]) -> float:
    """Return the least distance of the footprint at the poses to the obstacles (sampled).

    The polygon's boundary every 2 mm (the sampled distance exceeds the true one by at most
    1 mm), each point's exact distance to each obstacle; an obstacle vertex inside a
    footprint counts as distance 0.
    """
    corners = JACKAL.vertices
    boundary = np.concatenate([
        a + np.linspace(0.0, 1.0, int(np.hypot(*(b - a)) / 0.002), endpoint=False)[:, None]
        * (b - a) for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True)])
    least = math.inf
    # a footprint point is within JACKAL.radius of the pose: farther poses cannot come closer
    centres = np.min([o.distance(poses[:, :2]) for o in obstacles], axis=0)
    poses = poses[centres <= JACKAL.radius + CLEARANCE + 0.01]
    for chunk in np.array_split(poses, max(len(poses) // 200, 1)):
        c, s = np.cos(chunk[:, 2]), np.sin(chunk[:, 2])
        points = np.stack([chunk[:, None, 0] + c[:, None] * boundary[:, 0]
                           - s[:, None] * boundary[:, 1],
                           chunk[:, None, 1] + s[:, None] * boundary[:, 0]
                           + c[:, None] * boundary[:, 1]], axis=-1).reshape(-1, 2)
        for obstacle in obstacles:
            least = min(least, float(obstacle.distance(points).min()))
            if least == 0.0:
                return least
            # an obstacle corner inside the robot (the Jackal is centred): distance 0
            dx = obstacle.vertices[None, :, 0] - chunk[:, None, 0]
            dy = obstacle.vertices[None, :, 1] - chunk[:, None, 1]
            along = c[:, None] * dx + s[:, None] * dy
            across = -s[:, None] * dx + c[:, None] * dy
            if np.any((np.abs(along) <= 0.254) & (np.abs(across) <= 0.215)):
                return 0.0
    return least


def assert_every_pose_clear(waypoints: np.ndarray, start: np.ndarray, goal: np.ndarray,
                            obstacles: list[ConvexPolygon]) -> None:
    poses = path_poses(waypoints, float(start[2]), float(goal[2]))
    np.testing.assert_allclose(poses[0], start)
    assert poses[-1, 2] == pytest.approx(goal[2] + 2 * math.pi * round(
        (poses[-1, 2] - goal[2]) / (2 * math.pi)))
    assert footprint_distance(poses, obstacles) > CLEARANCE


def crosses_the_gap(waypoints: np.ndarray) -> bool:
    for a, b in zip(waypoints[:-1], waypoints[1:], strict=True):
        if (a[0] - 3.0) * (b[0] - 3.0) < 0:
            y = a[1] + (3.0 - a[0]) / (b[0] - a[0]) * (b[1] - a[1])
            return 1.7 < y < 2.3
    return False


# ------------------------------------------------------------------------- the gap world
@pytest.mark.parametrize('mode', ['polygons', 'grid'])
def test_the_jackal_plans_through_a_gap_narrower_than_its_circumscribed_circle(mode: str) -> None:
    planner = gap_planner(mode, JACKAL_CONFIG)
    start, goal = np.array([1.0, 1.2, 0.0]), np.array([5.0, 2.8, math.pi / 2])

    waypoints = planner.plan(start, goal)

    np.testing.assert_array_equal(waypoints[[0, -1]], [start[:2], goal[:2]])
    assert len(waypoints) > 2  # the straight line meets the wall: RRT* found the gap
    assert crosses_the_gap(waypoints)
    assert planner.path_problem(waypoints, start_heading=start[2], goal_heading=goal[2]) is None
    assert_every_pose_clear(waypoints, start, goal, [
        ConvexPolygon.from_box(2.9, 0.0, 3.1, 1.7), ConvexPolygon.from_box(2.9, 2.3, 3.1, 4.0)])


@pytest.mark.parametrize('mode', ['polygons', 'grid'])
def test_the_circumscribed_circle_finds_no_path_through_the_gap_and_says_so(mode: str) -> None:
    planner = gap_planner(mode, CIRCLE_CONFIG)

    with pytest.raises(PlanningError, match=r'no collision-free path from \(1, 1.2\) to '
                                            r'\(5, 2.8\) in 1000 iterations'):
        planner.plan(np.array([1.0, 1.2, 0.0]), np.array([5.0, 2.8, math.pi / 2]))


@pytest.mark.parametrize('mode', ['polygons', 'grid'])
def test_a_straight_drive_through_the_gap_is_planned_as_one_segment(mode: str) -> None:
    start, goal = np.array([1.0, 2.0, 0.0]), np.array([5.0, 2.0, 0.0])

    waypoints = gap_planner(mode, JACKAL_CONFIG).plan(start, goal)

    np.testing.assert_array_equal(waypoints, [start[:2], goal[:2]])
    assert_every_pose_clear(waypoints, start, goal, GAP_WALL)
    with pytest.raises(PlanningError):
        gap_planner(mode, CIRCLE_CONFIG).plan(start, goal)


def test_a_plan_is_reproducible_for_a_seed() -> None:
    start, goal = np.array([1.0, 1.2, 0.0]), np.array([5.0, 2.8, 0.0])

    first = gap_planner('polygons', JACKAL_CONFIG).plan(start, goal)
    again = gap_planner('polygons', JACKAL_CONFIG).plan(start, goal)

    np.testing.assert_array_equal(first, again)


def test_a_segment_through_the_wall_is_refused_with_the_obstacle_it_meets() -> None:
    planner = gap_planner('polygons', JACKAL_CONFIG)

    problem = planner.path_problem(np.array([[1.0, 1.0], [5.0, 1.0]]))

    assert problem is not None
    assert problem.startswith('segment 0 from (1, 1) to (5, 1): the footprint driven along it '
                              'at heading 0 rad meets obstacle 0 grown by the clearance 0.05 m')


def test_a_segment_that_grazes_the_gap_by_its_footprint_only_is_refused() -> None:
    # the reference point runs 0.05 m off the gap's centre line: 0.03 m from the wall, not
    # the clearance, on the upper side; the circle's centre line would pass at 0.25 m
    planner = gap_planner('polygons', JACKAL_CONFIG)
    waypoints = np.array([[1.0, 2.05], [5.0, 2.05]])
    poses = path_poses(waypoints, None, None)
    assert footprint_distance(poses, GAP_WALL) < CLEARANCE  # brute force agrees

    problem = planner.path_problem(waypoints)

    assert problem is not None and 'meets obstacle 1' in problem


# ---------------------------------------------------------------- turns in place are checked
# A small box diagonally ahead of the corner (1, 1): the Jackal clears it at heading 0 and at
# heading pi/2, and along both segments, but its front corner (0.333 m out) sweeps into it
# while turning between them.
CORNER_BOX = ConvexPolygon.from_box(1.23, 1.23, 1.4, 1.4)
CORNER_PATH = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 3.0]])
TIGHT = PlannerConfig(footprint=JACKAL, clearance=0.005, iterations=200)


def test_a_path_whose_corner_turn_sweeps_into_an_obstacle_is_refused() -> None:
    planner = RrtStarPlanner([CORNER_BOX], (-1.0, 3.0, -1.0, 4.0), config=TIGHT)
    segments_only = np.concatenate([path_poses(CORNER_PATH[:2], 0.0, 0.0),
                                    path_poses(CORNER_PATH[1:], math.pi / 2, math.pi / 2)])
    assert footprint_distance(segments_only, [CORNER_BOX]) > 0.005  # every straight pose
    assert footprint_distance(path_poses(CORNER_PATH, 0.0, None), [CORNER_BOX]) == 0.0

    problem = planner.path_problem(CORNER_PATH, start_heading=0.0)

    assert problem is not None
    assert problem.startswith('turning in place at waypoint 1 (1, 1) from heading 0 to 1.57 '
                              'rad: the footprint meets obstacle 0 grown by the clearance')
    # without the box, the same path is clear: the refusal is the turn's
    clear = RrtStarPlanner([], (-1.0, 3.0, -1.0, 4.0), config=TIGHT)
    assert clear.path_problem(CORNER_PATH, start_heading=0.0) is None


def test_plan_refuses_a_path_from_rrt_star_that_fails_the_final_check(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # RRT*'s own motions keep corners where the robot can turn; this (the OMPL run replaced)
    # stands in for a path that escaped them (e.g. from a future simplifier): the final
    # check must refuse it
    planner = RrtStarPlanner([CORNER_BOX, ConvexPolygon.from_box(0.5, 1.5, 0.7, 2.5)],
                             (-1.0, 3.0, -1.0, 4.0), config=TIGHT)
    monkeypatch.setattr(planner_module, 'rrt_star', lambda *args, **kwargs: [CORNER_PATH.copy()])

    with pytest.raises(PlanningError, match=r'cannot follow, refused: turning in place at '
                                            r'waypoint 1 \(1, 1\)'):
        planner.plan(np.array([0.0, 1.0, 0.0]), np.array([1.0, 3.0, math.pi / 2]))


def test_a_simplified_path_that_fails_the_final_check_falls_back_to_rrt_stars_own(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # OMPL's simplifier can keep an edge the motion validator refused (it only warns): the
    # plan then falls back to RRT*'s path, whose every motion was validated
    planner = RrtStarPlanner([CORNER_BOX, ConvexPolygon.from_box(0.5, 1.5, 0.7, 2.5)],
                             (-1.0, 3.0, -1.0, 4.0), config=TIGHT)
    detour = np.array([[0.0, 1.0], [0.0, 3.0], [1.0, 3.0]])
    monkeypatch.setattr(planner_module, 'rrt_star',
                        lambda *args, **kwargs: [CORNER_PATH.copy(), detour.copy()])

    waypoints = planner.plan(np.array([0.0, 1.0, 0.0]), np.array([1.0, 3.0, math.pi / 2]))

    np.testing.assert_array_equal(waypoints, detour)


def test_a_simplified_plan_on_the_grid_keeps_every_pose_clear() -> None:
    config = PlannerConfig(footprint=JACKAL, clearance=CLEARANCE, simplify=True)
    start, goal = np.array([1.0, 1.2, 0.0]), np.array([5.0, 2.8, math.pi / 2])

    waypoints = gap_planner('grid', config).plan(start, goal)

    assert crosses_the_gap(waypoints)
    assert_every_pose_clear(waypoints, start, goal, GAP_WALL)


# A slot 0.60 m wide, open towards -x, closed at x = 1.5 (the robot at (1, 1) fits facing
# either way along it, 0.03 m to spare on each side, but cannot turn round in it).
SLOT = [ConvexPolygon.from_box(0.5, 1.3, 1.6, 1.5), ConvexPolygon.from_box(0.5, 0.5, 1.6, 0.7),
        ConvexPolygon.from_box(1.35, 0.7, 1.6, 1.3)]
SLOT_BOUNDS = (-2.0, 2.0, -1.0, 3.0)
IN_SLOT = (1.0, 1.0)
OUTSIDE = (-1.0, 1.0)
SLOT_CONFIG = PlannerConfig(footprint=JACKAL, clearance=0.02, iterations=300)


def test_the_turn_at_the_start_is_checked() -> None:
    planner = RrtStarPlanner(SLOT, SLOT_BOUNDS, config=SLOT_CONFIG)
    facing_out = np.array([*IN_SLOT, math.pi])
    facing_in = np.array([*IN_SLOT, 0.0])
    goal = np.array([*OUTSIDE, math.pi])

    np.testing.assert_array_equal(planner.plan(facing_out, goal), [IN_SLOT, OUTSIDE])
    # facing the closed end, the robot would have to turn round inside the slot
    problem = planner.path_problem(np.array([IN_SLOT, OUTSIDE]), start_heading=0.0)
    assert problem is not None and problem.startswith(
        'turning in place at the start (1, 1) from heading 0 to 3.14 rad: the footprint meets')
    assert footprint_distance(path_poses(np.array([IN_SLOT, OUTSIDE]), 0.0, None), SLOT) == 0.0
    with pytest.raises(PlanningError, match=r'no collision-free path.* motions out of the '
                                            r'start were refused because the footprint cannot '
                                            r'turn in place there'):
        planner.plan(facing_in, goal)


def test_the_turn_at_the_goal_is_checked() -> None:
    planner = RrtStarPlanner(SLOT, SLOT_BOUNDS, config=SLOT_CONFIG)
    start = np.array([*OUTSIDE, 0.0])

    np.testing.assert_array_equal(planner.plan(start, np.array([*IN_SLOT, 0.0])),
                                  [OUTSIDE, IN_SLOT])
    # arriving at heading 0, the robot cannot turn round to face out of the slot
    with pytest.raises(PlanningError, match=r'motions into the goal were refused because the '
                                            r'footprint cannot turn in place there'):
        planner.plan(start, np.array([*IN_SLOT, math.pi]))


# ------------------------------------------------------------------------- start and goal
@pytest.mark.parametrize('mode', ['polygons', 'grid'])
def test_a_start_whose_footprint_overlaps_an_obstacle_is_refused(mode: str) -> None:
    planner = gap_planner(mode, JACKAL_CONFIG)
    # 0.28 m below the upper box: across the gap the Jackal fits (0.215 + 0.05), along not
    np.testing.assert_array_equal(planner.check_endpoint(np.array([3.0, 2.02, 0.0]), 'start'),
                                  [3.0, 2.02])
    what = 'obstacle 1' if mode == 'polygons' else r'the occupied cell \(row 46, column 5[89]\)'

    with pytest.raises(PlanningError, match=r'start \(3, 2.02\) is in collision: the footprint '
                                            rf'at heading 1.57 rad meets {what} grown by the '
                                            r'clearance 0.05 m'):
        planner.plan(np.array([3.0, 2.02, math.pi / 2]), np.array([5.0, 2.0, 0.0]))


def test_a_pose_without_heading_is_refused_only_where_no_heading_fits() -> None:
    planner = gap_planner('polygons', JACKAL_CONFIG)
    planner.check_endpoint(np.array([3.0, 2.0]), 'goal')  # some heading fits there

    with pytest.raises(PlanningError, match=r'goal \(3, 1.9\) is in collision: the disc of '
                                            r'0.215 m the footprint covers at any heading'):
        planner.check_endpoint(np.array([3.0, 1.9]), 'goal')


# ------------------------------------------------------------------------------ settings
def test_footprint_settings_are_validated_and_hashable() -> None:
    nav2 = PlannerConfig(footprint='[[0.254, 0.215], [-0.254, 0.215], [-0.254, -0.215], '
                                   '[0.254, -0.215]]', clearance=0.1)
    listed = PlannerConfig(footprint=[[0.254, 0.215], [-0.254, 0.215], [-0.254, -0.215],
                                      [0.254, -0.215]], clearance=0.1)

    assert nav2 == listed and hash(nav2) == hash(listed)
    assert nav2.footprint == ((0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215),
                              (0.254, -0.215))
    assert nav2.inflation == pytest.approx(JACKAL.radius + 0.1)
    assert PlannerConfig(footprint='[]', robot_radius=0.2).robot_footprint.is_circle
    with pytest.raises(ValueError, match='footprint must be a convex polygon.*not convex'):
        PlannerConfig(footprint=[[0, 0], [2, 0], [1, 0.2], [2, 1], [0, 1]])


def test_a_grid_inflated_less_than_the_circumscribed_radius_plus_clearance_is_refused() -> None:
    grid = PlanningGrid(gap_map(), inflation=0.3)

    with pytest.raises(ValueError, match=r"less than the footprint's circumscribed radius \+ "
                                         r'clearance = 0.382778 m'):
        RrtStarPlanner.on_grid(grid, config=JACKAL_CONFIG)
