# SPDX-License-Identifier: Apache-2.0
"""A recorded BARN state where the planner and the MPC disagreed about a turn at the start.

Laser-only BARN world 265 at 2 m/s (test/core/data/barn_265_wedged.json): a blocked re-plan
began with a turn in place that the planner's grid allowed (the true cylinders are 6.6 cm
away) but the MPC's convex pieces did not (a rectangle along a diagonal row of cylinders
covers the hollows between them, 7 cm past their surface). The MPC turned until its
footprint met that rectangle and stood there, 1.4 mm from it; every no-progress re-plan
gave the same path, and the run stalled. A re-plan now takes the obstacles the local
controller holds (``local_obstacles``): a plan they refuse is made again with every pose
``start_clearance`` from them (a start already closer keeps what it has), and a start whose
turns do not reach the way out first drives on to where it can turn
(``drive_on_heading_distance``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet, polygon_separation
from mpc_local_planner.core.paths import WaypointPath
from mpc_local_planner.core.planner import RrtStarPlanner
from mpc_local_planner.core.planner_config import PlannerConfig
from mpc_local_planner.perception.grids import PlanningGrid
from mpc_local_planner.worlds.data_files import BARN_DIR
from mpc_local_planner.worlds.map_files import OccupancyMap
from mpc_local_planner.worlds.world import load_barn_world

RECORD = json.loads((Path(__file__).parent / 'data' / 'barn_265_wedged.json')
                    .read_text(encoding='utf-8'))
# The laser-only BARN evaluation's planner (evaluation/sensing_suites.py).
BARN_CONFIG = PlannerConfig(iterations=3000, seed=0, range=0.5, footprint=JACKAL,
                            clearance=0.05)


def recorded(case: str) -> tuple[RrtStarPlanner, PlanningGrid, dict, list[ConvexPolygon]]:
    """Return the planner on the recorded grid, the case, and the MPC's pieces then."""
    world = load_barn_world(BARN_DIR / f'world_{RECORD["world"]:03d}.json', footprint=JACKAL)
    xmin, xmax, ymin, ymax = world.bounds
    shape = (math.ceil((ymax - ymin) / RECORD['resolution']),
             math.ceil((xmax - xmin) / RECORD['resolution']))
    assert list(shape) == RECORD['shape']
    record = RECORD['cases'][case]
    scan = np.zeros(shape, dtype=bool)
    for row, first, end in record['scan_runs']:
        scan[row, first:end] = True
    # no prior map (every cell unknown) but the cells the run's scans had marked
    sensed = OccupancyMap(np.where(scan, 100, -1).astype(np.int8), RECORD['resolution'],
                          (xmin, ymin, 0.0))
    grid = PlanningGrid(sensed, inflation=BARN_CONFIG.inflation)
    planner = RrtStarPlanner.on_grid(grid, config=BARN_CONFIG, bounds=world.bounds)
    pieces = [ConvexPolygon(A=np.array(p['A']), b=np.array(p['b']),
                            vertices=np.array(p['vertices'])) for p in record['pieces']]
    return planner, grid, record, pieces


def least_separation(waypoints: np.ndarray, start_heading: float, goal_heading: float,
                     pieces: list[ConvexPolygon]) -> float:
    """Return the least exact distance of the Jackal from the pieces along a path (sampled).

    The poses as core/paths.py drives them (turns in place included) 5 mm and 5 mrad apart.
    """
    knots = WaypointPath(waypoints, start_heading=start_heading, goal_heading=goal_heading,
                         capacity=200).knots
    poses = [knots[:1]]
    for a, b in zip(knots[:-1], knots[1:], strict=True):
        steps = max(int(math.ceil(max(np.hypot(*(b[:2] - a[:2])) / 0.005,
                                      abs(b[2] - a[2]) / 0.005))), 1)
        poses.append(a + np.linspace(0.0, 1.0, steps + 1)[1:, None] * (b - a))
    poses = np.vstack(poses)
    distances, _ = polygon_separation(JACKAL.at_poses(poses), ObstacleSet(pieces))
    return float(distances.min())


@pytest.mark.parametrize(('case', 'kept'), [
    # 10.8 s: the old plan's start turn came 6 mm from the pieces then (and into them as
    # later scans reshaped them); a new one keeps start_clearance
    ('turn_refused', BARN_CONFIG.start_clearance),
    # 44.4 s: 1.4 mm from a piece already; the old plan's turn went into it
    ('wedged', 0.0),
])
def test_a_re_plan_starts_with_motions_the_controllers_obstacles_allow(case: str,
                                                                       kept: float) -> None:
    planner, grid, record, pieces = recorded(case)
    pose, goal = np.array(record['pose']), np.array(record['goal'])
    old = least_separation(np.array(record['old_plan']), float(pose[2]), float(goal[2]), pieces)
    assert old < kept

    waypoints = planner.replan(pose, goal, grid=grid, local_obstacles=pieces)

    np.testing.assert_array_equal(waypoints[[0, -1]], [pose[:2], goal[:2]])
    # the grid's clearance, as every plan keeps it, and the MPC's pieces kept clear too
    assert planner.path_problem(waypoints, start_heading=pose[2], goal_heading=goal[2]) is None
    assert least_separation(waypoints, float(pose[2]), float(goal[2]), pieces) > kept


def test_without_the_controllers_obstacles_the_plan_is_as_before() -> None:
    planner, grid, record, _ = recorded('wedged')
    pose, goal = np.array(record['pose']), np.array(record['goal'])

    waypoints = planner.replan(pose, goal, grid=grid)

    np.testing.assert_allclose(waypoints, record['old_plan'], atol=1e-6)
