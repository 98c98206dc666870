# SPDX-License-Identifier: Apache-2.0
"""LocalObstacles: the map's rectangles and the scan memory near the robot, fitted for the MPC."""

from __future__ import annotations

from conftest import point_in_any
import numpy as np

from mpc_local_planner.core.moving_obstacles import MovingPolygon
from mpc_local_planner.core.obstacles import ConvexPolygon, within_faces
from mpc_local_planner.perception.local_obstacles import LocalObstacles
from mpc_local_planner.perception.scan_obstacles import ObstacleMemory
from mpc_local_planner.perception.tracking import ScanTracker
from mpc_local_planner.sim.laser import SimulatedLaser
from mpc_local_planner.sim.moving import WorldClock
from mpc_local_planner.worlds.map_files import OccupancyMap
from mpc_local_planner.worlds.world import world_from_dict


def wall_map() -> OccupancyMap:
    data = np.zeros((40, 100), dtype=np.int8)  # 10 m x 4 m at 0.1 m, origin (0, 0)
    data[:, 20] = 100  # a wall at x = 2.0 .. 2.1
    data[:, 80] = 100  # another at x = 8.0 .. 8.1
    return OccupancyMap(data, 0.1, (0.0, 0.0, 0.0))


def box_and_walker(box: ConvexPolygon, way: list[list[float]], name: str) -> WorldClock:
    """A static box, and a walker (0.25 m) at 1 m/s back and forth along way."""
    return WorldClock.from_world(world_from_dict({
        'bounds': [-6.0, 6.0, -4.0, 4.0], 'obstacles': [{'polygon': box.vertices.tolist()}],
        'start': [0.0, 0.0, 0.0], 'goal': [5.0, 0.0, 0.0],
        'moving_obstacles': [
            {'circle': [0.0, 0.0, 0.25],
             'waypoints': {'points': way, 'speed': 1.0, 'mode': 'back_and_forth'}}]},
        name=name))


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


def test_a_remembered_piece_is_fitted_once_when_it_enters_not_at_every_scan(monkeypatch) -> None:
    import mpc_local_planner.perception.local_obstacles as local_obstacles
    fitted: list[ConvexPolygon] = []

    def counting(polygons, faces):
        fitted.extend(polygons)
        return within_faces(polygons, faces)

    monkeypatch.setattr(local_obstacles, 'within_faces', counting)
    memory = ObstacleMemory(5.0)
    local = LocalObstacles(4, memory=memory)
    ahead, behind = ConvexPolygon.from_box(2.0, -0.3, 2.4, 0.3), ConvexPolygon.from_box(
        -2.4, -0.3, -2.0, 0.3)
    laser = SimulatedLaser([ahead, behind])  # 270 degrees: one box in view at a time
    memory.update(laser.scan((0.0, 0.0, 0.0), stamp=0.0), (0.0, 0.0, 0.0))
    local.scan_updated()
    first = memory.obstacles()
    assert fitted and len(fitted) == len(first)
    # turned round: the box ahead is out of view and kept; only the new pieces are fitted
    memory.update(laser.scan((0.0, 0.0, np.pi), stamp=0.1), (0.0, 0.0, np.pi))
    local.scan_updated()
    now = memory.obstacles()
    assert all(any(p is q for q in now) for p in first)  # the first pieces are remembered
    assert [id(p) for p in fitted[len(first):]] == [id(p) for p in now if
                                                    not any(p is q for q in first)]
    near = local.near((0.0, 0.0), 10.0)
    assert np.all(point_in_any(near, np.array([[2.0, 0.0], [-2.0, 0.0]]), margin=1e-6))
    # another face count: every piece is fitted again, to it
    local.faces = 8
    count = len(fitted)
    local.scan_updated()
    assert len(fitted) - count == len(now)


def test_a_tracked_walker_is_handed_over_moving_and_its_pieces_are_not() -> None:
    """A walker (0.25 m, 1 m/s along y = -1.5) told moving reaches the MPC as one polygon.

    That polygon holds the walker's disc where the walker is at the time asked for (now, or
    0.5 s later: it moves with the track's velocity); the scan's pieces of the walker are left
    out, and a static box is handed over as before.
    """
    box = ConvexPolygon.from_box(2.0, 0.5, 2.4, 1.1)
    clock = box_and_walker(box, [[3.0, -1.5], [-5.0, -1.5]], 'passing')
    walker = clock.moving[0]
    laser = SimulatedLaser(clock)
    memory = ObstacleMemory(5.0, tracker=ScanTracker())
    local = LocalObstacles(8, memory=memory)
    pose = (0.0, 0.0, -0.5)  # facing the walker's way in
    for k in range(16):
        t = round(k * 0.1, 9)
        memory.update(laser.scan(pose, stamp=t), pose)
        local.scan_updated()
    for ahead in (0.0, 0.5):
        now = t + ahead
        handed = local.near((0.0, 0.0), 10.0, now=now)
        movers = [o for o in handed if isinstance(o, MovingPolygon)]
        assert len(movers) == 1
        np.testing.assert_allclose(movers[0].velocity, [-1.0, 0.0], atol=0.2)
        angles = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
        rim = walker.position(now) + 0.25 * np.column_stack([np.cos(angles), np.sin(angles)])
        assert np.all(movers[0].contains(rim))
        static = [o for o in handed if not isinstance(o, MovingPolygon)]
        assert static and not any(o.contains(walker.position(now), margin=0.3)[0]
                                  for o in static)
        assert any(float(np.min(box.distance(o.vertices))) < 0.05 for o in static)  # the box


def test_a_walker_seen_in_free_space_is_predicted_before_it_is_told_moving() -> None:
    """A walker (0.25 m, 1 m/s) stepping out from behind a box is predicted at once.

    Its track has stood in free space once and has a velocity, but not yet the sightings
    that tell it moving: the MPC gets it as a mover already (where it will be, not where
    it stood), and its pieces stay among the static obstacles until the tracker knows.
    """
    box = ConvexPolygon.from_box(2.0, -1.0, 2.4, -0.2)
    clock = box_and_walker(box, [[3.0, -0.6], [3.0, 3.0]], 'stepping out')
    walker = clock.moving[0]
    laser = SimulatedLaser(clock)
    memory = ObstacleMemory(5.0, tracker=ScanTracker())
    local = LocalObstacles(8, memory=memory)
    pose = (0.0, 0.0, 0.0)
    early = []
    for k in range(16):
        t = round(k * 0.1, 9)
        memory.update(laser.scan(pose, stamp=t), pose)
        local.scan_updated()
        if memory.moving_tracks:
            break
        handed = local.near((0.0, 0.0), 10.0, now=t + 0.5)
        movers = [o for o in handed if isinstance(o, MovingPolygon)]
        if movers:
            static = [o for o in handed if not isinstance(o, MovingPolygon)]
            early.append((t, movers, static))
    assert memory.moving_tracks and early  # predicted at a scan before it was told moving
    for t, movers, static in early:
        assert len(movers) == 1
        assert movers[0].contains(walker.position(t + 0.5))[0]  # where it will be
        # its pieces on the near side, 0.25 m from its centre, stay
        assert any(float(o.distance(walker.position(t))[0]) < 0.3 for o in static)
