# SPDX-License-Identifier: Apache-2.0
"""Tests of the RRT* global planner and its geometric helpers."""

from __future__ import annotations

from pathlib import Path

from conftest import point_in_any
import numpy as np
import pytest

from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.free_space import grid_bounds
from mpc_local_planner.core.obstacles import ConvexPolygon, segment_collides
from mpc_local_planner.core.planner import path_length, RrtStarPlanner
from mpc_local_planner.core.planner_config import PlannerConfig
from mpc_local_planner.perception.grids import PlanningGrid
from mpc_local_planner.sim.laser import SimulatedLaser
from mpc_local_planner.worlds.data_files import BARN_DIR
from mpc_local_planner.worlds.map_files import OccupancyMap
from mpc_local_planner.worlds.world import load_world, paper_world, World

ROOT = Path(__file__).resolve().parents[2]
WORLDS = ROOT / 'config' / 'worlds'
BARN = BARN_DIR


def planner_for(world: World, **options: object) -> RrtStarPlanner:
    config = PlannerConfig(robot_radius=world.robot_radius, **options)  # type: ignore[arg-type]
    return RrtStarPlanner(world.obstacles, world.bounds, config=config)


def assert_valid_path(planner: RrtStarPlanner, world: World, waypoints: np.ndarray) -> None:
    assert waypoints.ndim == 2 and waypoints.shape[1] == 2 and len(waypoints) >= 2
    np.testing.assert_array_equal(waypoints[0], world.start[:2])
    np.testing.assert_array_equal(waypoints[-1], world.goal[:2])
    xmin, xmax, ymin, ymax = world.bounds
    assert np.all((waypoints[:, 0] >= xmin) & (waypoints[:, 0] <= xmax))
    assert np.all((waypoints[:, 1] >= ymin) & (waypoints[:, 1] <= ymax))
    for a, b in zip(waypoints[:-1], waypoints[1:], strict=True):
        assert not segment_collides(planner.inflated_obstacles, a, b)
        # an independent check: dense samples along the segment are outside every obstacle
        samples = np.linspace(a, b, 200)
        assert not point_in_any(planner.inflated_obstacles, samples).any()


@pytest.mark.parametrize(
    'world_file',
    [
        WORLDS / 'paper_obstacle.yaml',
        WORLDS / 'rrt_cluttered.yaml',
        BARN / 'world_000.json',
        BARN / 'world_001.json',
    ],
)
def test_planner_returns_a_collision_free_path_from_start_to_goal(world_file: Path) -> None:
    world = load_world(world_file)
    planner = planner_for(world)

    waypoints = planner.plan(world.start, world.goal)

    assert_valid_path(planner, world, waypoints)
    assert path_length(waypoints) >= np.linalg.norm(world.goal[:2] - world.start[:2])


def test_rrt_cluttered_world_is_solved_within_the_papers_1000_iterations() -> None:
    world = load_world(WORLDS / 'rrt_cluttered.yaml')
    planner = planner_for(world, iterations=1000, time_limit=60.0)

    waypoints = planner.plan(world.start, world.goal)

    assert_valid_path(planner, world, waypoints)
    assert len(waypoints) > 2  # the straight line is blocked


def test_planner_is_deterministic_for_a_seed_and_varies_across_seeds() -> None:
    world = load_world(WORLDS / 'rrt_cluttered.yaml')
    options = {'iterations': 1000, 'time_limit': 60.0}

    first = planner_for(world, seed=7, **options).plan(world.start, world.goal)
    other = planner_for(world, seed=8, **options).plan(world.start, world.goal)
    again = planner_for(world, seed=7, **options).plan(world.start, world.goal)

    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)


def test_default_seed_zero_is_reproducible() -> None:
    world = paper_world()

    first = planner_for(world, iterations=200).plan(world.start, world.goal)
    again = planner_for(world, iterations=200).plan(world.start, world.goal)

    np.testing.assert_array_equal(first, again)


def test_planner_returns_the_straight_segment_when_nothing_is_in_the_way() -> None:
    world = load_world(WORLDS / 'corridor_turn.yaml')

    waypoints = planner_for(world).plan(world.start, world.goal)

    np.testing.assert_array_equal(waypoints, [world.start[:2], world.goal[:2]])


def test_simplified_path_is_still_collision_free_and_no_longer() -> None:
    world = load_world(WORLDS / 'rrt_cluttered.yaml')
    raw = planner_for(world, seed=3).plan(world.start, world.goal)

    planner = planner_for(world, seed=3, simplify=True)
    smooth = planner.plan(world.start, world.goal)

    assert_valid_path(planner, world, smooth)
    assert path_length(smooth) <= path_length(raw) + 1e-9


def test_planner_raises_when_the_goal_is_inside_an_obstacle() -> None:
    world = paper_world()
    planner = planner_for(world)

    with pytest.raises(PlanningError, match=r'goal \(1.2, 0\) is in collision with obstacle 0'):
        planner.plan(world.start, np.array([1.2, 0.0, 0.0]))


def test_planner_raises_when_the_goal_is_only_inside_the_inflated_obstacle() -> None:
    world = paper_world()
    planner = planner_for(world, clearance=0.1)

    with pytest.raises(PlanningError, match=r'goal .* inflated by 0.1 m'):
        planner.plan(world.start, np.array([0.95, 0.0, 0.0]))


def test_planner_raises_when_the_start_is_in_collision() -> None:
    world = paper_world()
    planner = planner_for(world)

    with pytest.raises(PlanningError, match=r'start \(1.4, 0.5\) is in collision'):
        planner.plan(np.array([1.4, 0.5, 0.0]), world.goal)


@pytest.mark.parametrize(
    ('start', 'goal', 'match'),
    [
        ([0.0, 0.0], [5.0, 0.0], r'goal \(5, 0\) is outside the bounds'),
        ([0.0, -2.0], [2.5, 0.0], r'start \(0, -2\) is outside the bounds'),
        ([float('nan'), 0.0], [2.5, 0.0], 'start must hold finite x and y'),
    ],
)
def test_planner_raises_for_poses_outside_the_bounds_or_not_finite(
    start: list[float], goal: list[float], match: str
) -> None:
    world = paper_world()

    with pytest.raises(PlanningError, match=match):
        planner_for(world).plan(np.array(start), np.array(goal))


def test_a_replan_from_outside_the_bounds_starts_with_the_way_back_in() -> None:
    # a robot that left the plane the planner samples (stepping out of a walker's way) would
    # stand there for good if no plan could start from it
    world = paper_world()
    planner = RrtStarPlanner(world.obstacles, world.bounds,
                             config=PlannerConfig(robot_radius=0.1, iterations=500))
    outside = np.array([0.3, -2.7, -1.0])
    with pytest.raises(PlanningError, match='outside the bounds'):
        planner.plan(outside, world.goal)

    waypoints = planner.replan(outside, world.goal)

    np.testing.assert_array_equal(waypoints[0], outside[:2])
    inset = planner.config.inflation
    np.testing.assert_allclose(waypoints[1], [0.3, world.bounds[2] + inset], atol=1e-12)
    np.testing.assert_array_equal(waypoints[-1], world.goal[:2])
    rest = waypoints[1:]
    xmin, xmax, ymin, ymax = world.bounds
    assert np.all((rest[:, 0] >= xmin) & (rest[:, 0] <= xmax))
    assert np.all((rest[:, 1] >= ymin) & (rest[:, 1] <= ymax))
    for a, b in zip(rest[:-1], rest[1:], strict=True):
        assert not segment_collides(planner.inflated_obstacles, a, b)
    assert planner.way_in(world.start) is None


def test_planner_raises_when_the_goal_is_walled_off() -> None:
    walls = [
        ConvexPolygon.from_box(1.0, -1.0, 1.2, 1.0),  # a wall across the whole space
    ]
    planner = RrtStarPlanner(walls, (0.0, 2.0, -1.0, 1.0), config=PlannerConfig(iterations=200))

    with pytest.raises(PlanningError, match='no collision-free path.*200 iterations'):
        planner.plan(np.array([0.5, 0.0]), np.array([1.5, 0.0]))


@pytest.mark.parametrize(
    ('options', 'match'),
    [
        ({'iterations': 0}, 'iterations must be >= 1'),
        ({'iterations': 1.5}, 'iterations must be an integer'),
        ({'time_limit': 0.0}, 'time_limit must be > 0'),
        ({'seed': -1}, 'seed must be an integer'),
        ({'seed': 2**32}, 'seed must be an integer'),
        ({'range': -1.0}, 'range must be >= 0'),
        ({'robot_radius': float('nan')}, 'robot_radius must be >= 0'),
        ({'clearance': -0.1}, 'clearance must be >= 0'),
    ],
)
def test_planner_config_rejects_invalid_settings(options: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        PlannerConfig(**options)  # type: ignore[arg-type]


def test_planner_rejects_empty_bounds() -> None:
    with pytest.raises(ValueError, match='bounds must be finite'):
        RrtStarPlanner([], (1.0, 0.0, 0.0, 1.0))


def test_check_endpoint_refuses_a_goal_inside_an_obstacle_as_the_planner_inflates_it() -> None:
    box = ConvexPolygon.from_box(0.0, 0.0, 1.0, 1.0)
    planner = RrtStarPlanner([box], (-2.0, 3.0, -2.0, 3.0),
                             config=PlannerConfig(robot_radius=0.1, clearance=0.1))
    np.testing.assert_allclose(planner.check_endpoint(np.array([1.25, 0.5, 0.0]), 'goal'),
                               [1.25, 0.5])
    with pytest.raises(PlanningError, match=r'goal \(1.15, 0.5\) is in collision with obstacle 0'):
        planner.check_endpoint(np.array([1.15, 0.5, 0.0]), 'goal')  # outside the raw box


def test_path_problem_of_a_round_robot_names_the_segment_that_meets_an_obstacle() -> None:
    box = ConvexPolygon.from_box(0.0, 0.0, 1.0, 1.0)
    planner = RrtStarPlanner([box], (-2.0, 3.0, -2.0, 3.0),
                             config=PlannerConfig(robot_radius=0.1, clearance=0.1))
    around = np.array([[-0.5, -0.5], [1.5, -0.5], [1.5, 1.5]])

    assert planner.path_problem(around, start_heading=2.0, goal_heading=-1.0) is None
    assert planner.path_problem(around + [0.0, 0.35]) == (
        'segment 0 from (-0.5, -0.15) to (1.5, -0.15) meets the obstacles grown by 0.2 m '
        '(robot_radius + clearance)')


def test_path_length_sums_segment_lengths() -> None:
    assert path_length(np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 5.0]])) == pytest.approx(6.0)
    assert path_length(np.array([[0.0, 0.0, 1.0], [0.0, 2.0, 2.0]])) == pytest.approx(2.0)
    assert path_length(np.array([[1.0, 1.0]])) == 0.0


# ----------------------------------------------------------------------------- on a grid
RESOLUTION = 0.05
GRID_CONFIG = PlannerConfig(robot_radius=0.2, clearance=0.1, iterations=1000, time_limit=60.0)


def wall_map() -> OccupancyMap:
    """A 10 m x 6 m map, free, with a wall x in [4.5, 5], y in [0, 4] (a gap above it)."""
    data = np.zeros((120, 200), dtype=np.int8)
    data[0:80, 90:100] = 100
    data[110:, 0:20] = -1  # unknown cells count as free
    return OccupancyMap(data=data, resolution=RESOLUTION, origin=(0.0, 0.0, 0.0))


def grid_planner(occupancy: OccupancyMap, **options: object) -> RrtStarPlanner:
    config = PlannerConfig(**{**GRID_CONFIG.__dict__, **options})  # type: ignore[arg-type]
    grid = PlanningGrid(occupancy, inflation=config.inflation)
    return RrtStarPlanner.on_grid(grid, config=config)


def assert_free_on_grid(grid: PlanningGrid, waypoints: np.ndarray) -> None:
    for a, b in zip(waypoints[:-1], waypoints[1:], strict=True):
        assert grid.segment_is_free(a, b)
        # an independent check: samples a millimetre apart, against the blocked cells
        samples = np.linspace(a, b, max(int(np.linalg.norm(b - a) / 1e-3), 2))
        assert grid.is_free(samples).all()


def test_grid_planner_goes_around_a_wall_and_every_segment_is_free() -> None:
    planner = grid_planner(wall_map())
    assert planner.bounds == (0.0, 10.0, 0.0, 6.0)  # the grid's extent
    start, goal = np.array([1.0, 1.0, 0.0]), np.array([9.0, 1.0, 0.0])

    waypoints = planner.plan(start, goal)

    assert planner.grid is not None
    np.testing.assert_array_equal(waypoints[[0, -1]], [start[:2], goal[:2]])
    assert len(waypoints) > 2
    assert_free_on_grid(planner.grid, waypoints)  # type: ignore[arg-type]
    # over the wall's top (y = 4) with the clearance: robot_radius + clearance above it
    crossing = waypoints[np.argmin(np.abs(waypoints[:, 0] - 4.75))]
    assert waypoints[:, 1].max() >= 4.0 + GRID_CONFIG.inflation
    assert crossing[1] > 4.0


def test_grid_planner_is_deterministic_for_a_seed() -> None:
    first = grid_planner(wall_map(), seed=5).plan(np.array([1.0, 1.0]), np.array([9.0, 1.0]))
    again = grid_planner(wall_map(), seed=5).plan(np.array([1.0, 1.0]), np.array([9.0, 1.0]))

    np.testing.assert_array_equal(first, again)


@pytest.mark.parametrize(
    ('start', 'goal', 'match'),
    [
        ([1.0, 1.0], [4.7, 1.0], r'goal \(4.7, 1\) is in an occupied cell \(cell row 20, '
         r'column 94\) of the grid inflated by 0.3 m \(robot_radius \+ clearance\)'),
        ([4.3, 2.0], [9.0, 1.0], r'start \(4.3, 2\) is within 0.3 m of an occupied cell'),
        ([1.0, 1.0], [11.0, 1.0], r'goal \(11, 1\) is outside the bounds \(0.0, 10.0'),
    ],
)
def test_grid_planner_refuses_a_start_or_goal_in_an_inflated_cell_or_off_the_grid(
    start: list[float], goal: list[float], match: str
) -> None:
    planner = grid_planner(wall_map())

    with pytest.raises(PlanningError, match=match):
        planner.plan(np.array(start), np.array(goal))


def test_grid_planner_raises_when_the_goal_is_walled_off() -> None:
    occupancy = wall_map()
    occupancy.data[:, 90:100] = 100  # the wall now spans the whole height
    planner = grid_planner(occupancy, iterations=200)

    with pytest.raises(PlanningError, match='no collision-free path.*200 iterations'):
        planner.plan(np.array([1.0, 1.0]), np.array([9.0, 1.0]))


def test_grid_planner_avoids_cells_a_scan_marks_and_not_the_ones_a_later_scan_clears() -> None:
    occupancy = OccupancyMap(data=np.zeros((120, 200), dtype=np.int8), resolution=RESOLUTION)
    planner = grid_planner(occupancy)
    grid = planner.grid
    assert isinstance(grid, PlanningGrid)
    start, goal = np.array([1.0, 3.0, 0.0]), np.array([9.0, 3.0, 0.0])
    box = ConvexPolygon.from_box(5.0, 1.5, 5.3, 4.5)  # not in the map

    np.testing.assert_array_equal(planner.plan(start, goal), [start[:2], goal[:2]])

    grid.add_scan(SimulatedLaser([box], beams=720).scan(start), start)
    around = planner.plan(start, goal)

    assert len(around) > 2
    assert_free_on_grid(grid, around)
    # the scan saw the box's face x = 5, y in [1.5, 4.5]: the plan keeps the clearance to it
    face = ConvexPolygon.from_box(5.0, 1.5, 5.0 + RESOLUTION, 4.5)
    samples = np.concatenate([np.linspace(a, b, 500) for a, b in zip(around[:-1], around[1:],
                                                                      strict=True)])
    assert face.distance(samples).min() > GRID_CONFIG.inflation

    grid.add_scan(SimulatedLaser([], beams=720).scan(start, stamp=1.0), start)  # box gone
    np.testing.assert_array_equal(planner.plan(start, goal), [start[:2], goal[:2]])


def test_grid_planner_refuses_an_edge_that_clips_only_the_corner_of_a_blocked_cell() -> None:
    data = np.zeros((20, 20), dtype=np.int8)
    data[10, 10] = 100  # blocked with its 8 neighbours: the square [9, 12] x [9, 12]
    grid = PlanningGrid(OccupancyMap(data=data, resolution=1.0), inflation=0.0)
    planner = RrtStarPlanner.on_grid(grid, config=PlannerConfig(clearance=0.0))
    # the straight line cuts 0.02 m off the corner (9, 12), between two half-cell samples
    start, goal = np.array([7.1, 10.08]), np.array([11.1, 14.08])

    waypoints = planner.plan(start, goal)

    assert len(waypoints) > 2
    assert_free_on_grid(grid, waypoints)


def test_grid_planner_refuses_a_grid_inflated_less_than_radius_plus_clearance() -> None:
    grid = PlanningGrid(wall_map(), inflation=0.1)

    with pytest.raises(ValueError, match=r'inflated by 0.1 m, less than .* = 0.3 m'):
        RrtStarPlanner.on_grid(grid, config=GRID_CONFIG)


def test_grid_bounds_cover_a_rotated_grid() -> None:
    occupancy = OccupancyMap(data=np.zeros((10, 20), dtype=np.int8), resolution=0.1,
                             origin=(1.0, 2.0, np.pi / 2))
    grid = PlanningGrid(occupancy, inflation=0.0)

    np.testing.assert_allclose(grid_bounds(grid), (0.0, 1.0, 2.0, 4.0), atol=1e-12)


def test_replan_after_failures_plans_with_the_seed_moved_on_and_keeps_its_own() -> None:
    world = load_world(WORLDS / 'rrt_cluttered.yaml')
    options = {'iterations': 1000, 'time_limit': 60.0}
    planner = planner_for(world, seed=7, **options)
    moved = planner.replan(world.start, world.goal, failures=1)
    np.testing.assert_array_equal(
        moved, planner_for(world, seed=8, **options).plan(world.start, world.goal))
    assert planner.config.seed == 7
    np.testing.assert_array_equal(planner.replan(world.start, world.goal),
                                  planner.plan(world.start, world.goal))
