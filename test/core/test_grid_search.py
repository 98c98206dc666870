# SPDX-License-Identifier: Apache-2.0
"""Tests of the grid search and of the planner's fallback to it where RRT* fails.

Narrow passages: a corridor through a thick wall a centimetre or two wider than the Jackal
(RRT* cannot place a state inside it: its circumscribed circle does not fit), a start
already inside it, and BARN states where RRT* found nothing (worlds 201 and 271 at their
start with every cylinder known, and a state recorded in a laser-only run of world 201).
Every plan is checked by brute force against the occupied cells as exact boxes.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.grid_search import (
    clearance_field,
    GridSearchSettings,
    pull_string,
    shortest_cells,
)
from mpc_local_planner.core.paths import WaypointPath
from mpc_local_planner.core.planner import RrtStarPlanner
from mpc_local_planner.core.planner_config import PlannerConfig
from mpc_local_planner.perception.grids import grid_rectangles, PlanningGrid
from mpc_local_planner.worlds.data_files import BARN_DIR
from mpc_local_planner.worlds.map_files import OccupancyMap, rasterize_world
from mpc_local_planner.worlds.world import load_barn_world

DATA = Path(__file__).parent / 'data'
FINE = 0.01
# The laser-only BARN evaluation's planner (evaluation/sensing_suites.py): the Jackal, a
# 0.05 m clearance, 3000 iterations of range 0.5 m, seed 0, a 0.05 m grid.
BARN_CONFIG = PlannerConfig(iterations=3000, seed=0, range=0.5, footprint=JACKAL,
                            clearance=0.05)
BARN_RESOLUTION = 0.05


# --------------------------------------------------------------------------- the checks
def footprint_distance(waypoints: np.ndarray, start_heading: float, goal_heading: float,
                       occupancy: OccupancyMap) -> float:
    """Return the least distance of the Jackal along a path to the occupied cells (sampled).

    The path's poses as core/paths.py drives it (turns in place included) 5 mm and 5 mrad
    apart, each polygon's boundary every 5 mm, against every occupied cell as an exact box
    (merged into rectangles); a box inside the footprint would need a pose on its boundary
    first, so the boundary suffices.
    """
    knots = WaypointPath(waypoints, start_heading=start_heading, goal_heading=goal_heading,
                         capacity=200).knots
    pieces = [knots[:1]]
    for a, b in zip(knots[:-1], knots[1:], strict=True):
        count = int(max(np.hypot(*(b[:2] - a[:2])) / 0.005, abs(b[2] - a[2]) / 0.005, 1))
        pieces.append(a + np.linspace(0.0, 1.0, count + 1)[1:, None] * (b - a))
    poses = np.concatenate(pieces)
    corners = JACKAL.vertices
    boundary = np.concatenate([
        a + np.linspace(0.0, 1.0, int(np.hypot(*(b - a)) / 0.005), endpoint=False)[:, None]
        * (b - a) for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True)])
    centre = poses[:, :2].mean(axis=0)
    reach = float(np.max(np.hypot(*(poses[:, :2] - centre).T))) + 1.0
    least = math.inf
    for box in grid_rectangles(occupancy, centre=centre, radius=reach):
        # a footprint point is within JACKAL.radius of its pose: farther poses cannot matter
        near = poses[box.distance(poses[:, :2]) <= JACKAL.radius + 0.1]
        if not len(near):
            continue
        c, s = np.cos(near[:, 2])[:, None], np.sin(near[:, 2])[:, None]
        points = np.stack([near[:, None, 0] + c * boundary[:, 0] - s * boundary[:, 1],
                           near[:, None, 1] + s * boundary[:, 0] + c * boundary[:, 1]],
                          axis=-1).reshape(-1, 2)
        least = min(least, float(box.distance(points).min()))
    return least


def assert_clear(planner: RrtStarPlanner, waypoints: np.ndarray, start: np.ndarray,
                 goal: np.ndarray, occupancy: OccupancyMap) -> None:
    np.testing.assert_array_equal(waypoints[[0, -1]], [start[:2], goal[:2]])
    assert planner.path_problem(waypoints, start_heading=start[2], goal_heading=goal[2]) is None
    distance = footprint_distance(waypoints, float(start[2]), float(goal[2]), occupancy)
    assert distance > planner.config.clearance


# ------------------------------------------------------------------------ the search alone
def test_the_clearance_field_is_the_distance_between_cell_centres() -> None:
    occupied = np.zeros((5, 7), dtype=bool)
    occupied[2, 3] = True

    field = clearance_field(occupied, 0.5)

    assert field[2, 3] == 0.0
    assert field[2, 6] == pytest.approx(1.5)
    assert field[0, 1] == pytest.approx(math.hypot(1.0, 1.0))
    assert np.all(np.isinf(clearance_field(np.zeros((3, 3), dtype=bool), 0.5)))


def test_the_search_takes_a_one_cell_passage_and_none_narrower_than_its_threshold() -> None:
    occupied = np.zeros((21, 21), dtype=bool)
    occupied[:, 10] = True
    occupied[10, 10] = False  # one free cell in the wall: its clearance is one cell
    field = clearance_field(occupied, 1.0)

    cells = shortest_cells(field, 0.99, (10, 2), (10, 18), resolution=1.0)

    assert cells is not None
    assert [10, 10] in cells.tolist()
    assert np.all(np.abs(np.diff(cells, axis=0)) <= 1)  # 8-connected steps
    assert shortest_cells(field, 1.0, (10, 2), (10, 18), resolution=1.0) is None


def test_the_search_prefers_room_to_a_slightly_shorter_tight_gap() -> None:
    occupied = np.zeros((41, 41), dtype=bool)
    occupied[:, 20] = True
    occupied[18:21, 20] = False  # a tight gap on the straight line
    occupied[25:34, 20] = False  # a wide one, a short detour away
    field = clearance_field(occupied, 0.1)

    roomy = shortest_cells(field, 0.1, (19, 5), (19, 35), resolution=0.1)
    shortest = shortest_cells(field, 0.1, (19, 5), (19, 35), resolution=0.1,
                              settings=GridSearchSettings(room_weight=0.0))

    assert roomy is not None and shortest is not None
    assert np.all((roomy[roomy[:, 1] == 20, 0] >= 25) & (roomy[roomy[:, 1] == 20, 0] < 34))
    assert np.all(shortest[shortest[:, 1] == 20, 0] < 21)


def test_pull_string_backs_up_to_a_nearer_corner_where_the_farthest_leads_nowhere() -> None:
    points = np.column_stack([np.arange(6.0), np.zeros(6)])

    def motion_ok(i: int, j: int, previous: int | None) -> bool:
        if i == 0:
            return j <= 3  # the farthest, 3, is a dead end: nothing leaves it
        return i == 2 and j == 5

    assert pull_string(points, motion_ok) == [0, 2, 5]
    assert pull_string(points, lambda i, j, k: False) is None


# --------------------------------------------------------------- the planner's fallback
def corridor(cells: int, clearance: float) -> tuple[RrtStarPlanner, OccupancyMap]:
    """A 4 m x 2 m room split by a 1.2 m thick wall with a corridor `cells` cells wide.

    The corridor is centred on y = 1.005 (a cell centre: a corridor an odd number of cells
    wide has a row of cells on its axis), x in [1.6, 2.8]; the planner's grid is 1 cm.
    """
    data = np.zeros((200, 400), dtype=np.int8)
    data[:, 160:280] = 100
    low = 100 - cells // 2
    data[low:low + cells, 160:280] = 0
    occupancy = OccupancyMap(data=data, resolution=FINE)
    config = PlannerConfig(footprint=JACKAL, clearance=clearance, iterations=500)
    grid = PlanningGrid(occupancy, inflation=config.inflation)
    return RrtStarPlanner.on_grid(grid, config=config), occupancy


@pytest.mark.parametrize(('cells', 'clearance'), [(45, 0.0), (55, 0.05)])
def test_the_jackal_plans_through_a_corridor_two_centimetres_wider_than_it_needs(
        cells: int, clearance: float) -> None:
    # 0.45 m for the 0.43 m Jackal; 0.55 m for the Jackal and twice a 0.05 m clearance
    planner, occupancy = corridor(cells, clearance)
    start, goal = np.array([0.6, 1.7, 0.0]), np.array([3.6, 1.6, 0.0])

    waypoints = planner.plan(start, goal)

    assert_clear(planner, waypoints, start, goal, occupancy)
    inside = [a for a, b in zip(waypoints[:-1], waypoints[1:], strict=True)
              if a[0] <= 1.6 and b[0] >= 2.8]
    assert len(inside) == 1  # one straight drive through the whole corridor


@pytest.mark.parametrize('cells', [41, 43])
def test_no_path_through_a_corridor_no_wider_than_the_jackal(cells: int) -> None:
    planner, _ = corridor(cells, 0.0)

    with pytest.raises(PlanningError, match='RRT\\* found no collision-free path.*the grid '
                                            'search found no path either: no cells'):
        planner.plan(np.array([0.6, 1.7, 0.0]), np.array([3.6, 1.6, 0.0]))


def test_a_tight_start_inside_the_corridor_drives_out_along_it() -> None:
    planner, occupancy = corridor(45, 0.0)
    start, goal = np.array([2.0, 1.005, 0.0]), np.array([3.6, 1.6, 0.5])

    waypoints = planner.plan(start, goal)

    assert_clear(planner, waypoints, start, goal, occupancy)
    first = waypoints[1] - waypoints[0]
    assert abs(math.atan2(first[1], first[0])) < 0.02  # along the corridor, no turn inside
    assert waypoints[1][0] >= 2.8


# ---------------------------------------------------------------- recorded BARN failures
def barn_known(world_number: int) -> tuple[RrtStarPlanner, OccupancyMap, np.ndarray,
                                           np.ndarray]:
    """The BARN world's planner with every cylinder known, as the evaluation builds it."""
    world = load_barn_world(BARN_DIR / f'world_{world_number:03d}.json', footprint=JACKAL)
    occupancy = rasterize_world(world, BARN_RESOLUTION)
    grid = PlanningGrid(occupancy, inflation=BARN_CONFIG.inflation)
    planner = RrtStarPlanner.on_grid(grid, config=BARN_CONFIG, bounds=world.bounds)
    return planner, occupancy, world.start, world.goal


@pytest.mark.parametrize('world_number', [201, 271])
def test_a_barn_world_where_rrt_star_finds_no_way_out_of_the_start_is_planned(
        world_number: int) -> None:
    # 201: RRT*'s states need the Jackal's circumscribed circle free, and no chain of such
    # states joins start and goal (as in all 63 of worlds 200-299 where it failed); 271: also
    # the farthest corner along the cells is one the Jackal cannot turn at (pull_string backs up)
    planner, occupancy, start, goal = barn_known(world_number)

    waypoints = planner.plan(start, goal)

    assert_clear(planner, waypoints, start, goal, occupancy)


def test_a_recorded_laser_only_barn_state_with_no_way_out_is_re_planned() -> None:
    record = json.loads((DATA / 'barn_201_stalled.json').read_text(encoding='utf-8'))
    world = load_barn_world(BARN_DIR / f'world_{record["world"]:03d}.json', footprint=JACKAL)
    xmin, xmax, ymin, ymax = world.bounds
    shape = (math.ceil((ymax - ymin) / BARN_RESOLUTION),
             math.ceil((xmax - xmin) / BARN_RESOLUTION))
    assert list(shape) == record['shape']
    scan = np.zeros(shape, dtype=bool)
    for row, first, end in record['scan_runs']:
        scan[row, first:end] = True
    # no prior map (every cell unknown) but the cells the run's scans had marked
    sensed = OccupancyMap(np.where(scan, 100, -1).astype(np.int8), BARN_RESOLUTION,
                          (xmin, ymin, 0.0))
    grid = PlanningGrid(sensed, inflation=BARN_CONFIG.inflation)
    planner = RrtStarPlanner.on_grid(grid, config=BARN_CONFIG, bounds=world.bounds)
    pose = np.array(record['pose'])

    waypoints = planner.replan(pose, world.goal, grid=grid)

    np.testing.assert_array_equal(waypoints[0], pose[:2])
    np.testing.assert_array_equal(waypoints[-1], world.goal[:2])
    # after the escape segment (PlanningGrid.escape_point), every pose keeps the clearance
    assert planner.path_problem(waypoints[1:], goal_heading=world.goal[2]) is None
    assert footprint_distance(waypoints[1:], math.atan2(*(waypoints[2] - waypoints[1])[::-1]),
                              float(world.goal[2]), sensed) > BARN_CONFIG.clearance
