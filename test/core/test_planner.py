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

"""Tests of the RRT* global planner and its geometric helpers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.obstacles import ConvexPolygon, point_in_any, segment_collides
from mpc_local_planner.core.planner import path_length, PlannerConfig, RrtStarPlanner
from mpc_local_planner.worlds.data_files import BARN_DIR
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


def test_path_length_sums_segment_lengths() -> None:
    assert path_length(np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 5.0]])) == pytest.approx(6.0)
    assert path_length(np.array([[0.0, 0.0, 1.0], [0.0, 2.0, 2.0]])) == pytest.approx(2.0)
    assert path_length(np.array([[1.0, 1.0]])) == 0.0
