# SPDX-License-Identifier: Apache-2.0
"""LocalObstacles: the map's rectangles and the scan memory near the robot, fitted for the MPC."""

from __future__ import annotations

from conftest import point_in_any
import numpy as np

from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.local_obstacles import LocalObstacles
from mpc_local_planner.perception.scan_obstacles import ObstacleMemory
from mpc_local_planner.sim.laser import SimulatedLaser
from mpc_local_planner.worlds.map_files import OccupancyMap


def wall_map() -> OccupancyMap:
    data = np.zeros((40, 100), dtype=np.int8)  # 10 m x 4 m at 0.1 m, origin (0, 0)
    data[:, 20] = 100  # a wall at x = 2.0 .. 2.1
    data[:, 80] = 100  # another at x = 8.0 .. 8.1
    return OccupancyMap(data, 0.1, (0.0, 0.0, 0.0))


def test_map_rectangles_near_the_robot_cover_its_cells_and_nothing_far() -> None:
    local = LocalObstacles(8, occupancy=wall_map())
    near = local.near((1.0, 2.0), 1.5)
    assert near and all(o.num_faces <= 8 for o in near)
    wall = np.column_stack([np.full(9, 2.05), np.linspace(1.0, 3.0, 9)])
    assert np.all(point_in_any(near, wall))
    assert not np.any(point_in_any(near, np.array([[8.05, 2.0]])))  # the far wall
    assert local.near((1.0, 2.0), 1.5) is not near  # a new list...
    assert local.near((1.0, 2.0), 1.5) == near  # ...of the same rectangles (same cell)


def test_remembered_obstacles_come_in_after_scan_updated_and_only_near() -> None:
    memory = ObstacleMemory(5.0)
    local = LocalObstacles(8, memory=memory)
    box = ConvexPolygon.from_box(2.0, -0.3, 2.4, 0.3)
    memory.update(SimulatedLaser([box]).scan((0.0, 0.0, 0.0)), (0.0, 0.0, 0.0))
    assert local.near((0.0, 0.0), 5.0) == []  # not taken in yet
    local.scan_updated()
    near = local.near((0.0, 0.0), 5.0)
    assert near and np.all(point_in_any(near, np.array([[2.0, 0.0], [2.0, 0.25]]), margin=1e-6))
    assert local.near((-10.0, 0.0), 5.0) == []
