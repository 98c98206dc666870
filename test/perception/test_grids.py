# SPDX-License-Identifier: Apache-2.0
"""Tests of grid rectangles and of the planner's grid."""

from __future__ import annotations

import math

from conftest import point_in_any
import numpy as np
import pytest

from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.grids import (
    grid_from_fields,
    grid_rectangles,
    GridError,
    PlanningGrid,
)
from mpc_local_planner.perception.scans import Scan
from mpc_local_planner.sim.laser import SimulatedLaser
from mpc_local_planner.worlds.map_files import OccupancyMap

L_SHAPE = np.array([  # row 0 at the bottom
    [0, 0, 0, 0, 0, 0],
    [0, 100, 100, 100, 0, 0],
    [0, 100, 0, 0, 0, 0],
    [0, 100, 0, 0, 70, -1],
    [0, 0, 0, 0, 10, 0],
], dtype=np.int8)


def cover_mask(rectangles: list[ConvexPolygon], grid: OccupancyMap) -> np.ndarray:
    rows, cols = np.mgrid[0:grid.height, 0:grid.width]
    centres = grid.cell_to_world(rows.ravel(), cols.ravel())
    return point_in_any(rectangles, centres).reshape(grid.height, grid.width)


def test_rectangles_cover_the_occupied_cells_exactly_with_few_disjoint_pieces() -> None:
    grid = OccupancyMap(L_SHAPE, 0.5, (1.0, -2.0, 0.0))

    rectangles = grid_rectangles(grid)

    np.testing.assert_array_equal(cover_mask(rectangles, grid), L_SHAPE >= 65)
    assert len(rectangles) == 3  # the L's foot, its stem, the lone cell
    areas = [np.prod(np.ptp(r.vertices, axis=0)) for r in rectangles]
    assert sum(areas) == pytest.approx(np.count_nonzero(L_SHAPE >= 65) * 0.25)  # disjoint
    lone = [r for r in rectangles if np.allclose(np.ptp(r.vertices, axis=0), 0.5)][0]
    np.testing.assert_allclose(lone.vertices.min(axis=0), [1.0 + 4 * 0.5, -2.0 + 3 * 0.5])


def test_rectangles_follow_a_rotated_origin_and_a_window() -> None:
    grid = OccupancyMap(L_SHAPE, 0.5, (0.0, 0.0, math.pi / 2))
    rectangles = grid_rectangles(grid)
    np.testing.assert_array_equal(cover_mask(rectangles, grid), L_SHAPE >= 65)

    window = grid_rectangles(OccupancyMap(L_SHAPE, 1.0), centre=(4.5, 3.5), radius=0.4)
    assert len(window) == 1  # only the lone cell's neighbourhood
    assert grid_rectangles(OccupancyMap(L_SHAPE, 1.0), threshold=101) == []


def test_grid_from_fields_validates_the_message() -> None:
    grid = grid_from_fields(L_SHAPE.ravel().tolist(), 6, 5, 0.5, (0.0, 0.0, 0.0))
    np.testing.assert_array_equal(grid.data, L_SHAPE)
    for args, match in [
        ((L_SHAPE.ravel(), 5, 5, 0.5, (0, 0, 0)), r'5 x 5 = 25 cells but data has 30'),
        ((L_SHAPE.ravel(), 6, 5, 0.0, (0, 0, 0)), 'resolution must be > 0'),
        ((L_SHAPE.ravel(), 6, 5, math.nan, (0, 0, 0)), 'resolution must be > 0'),
        ((L_SHAPE.ravel(), 6, 5, 0.5, (0, math.inf, 0)), 'origin must be three finite'),
        ((L_SHAPE.ravel(), 0, 0, 0.5, (0, 0, 0)), 'must be > 0'),
        ((np.full(30, 120), 6, 5, 0.5, (0, 0, 0)), r'-1 \(unknown\) or 0..100'),
    ]:
        with pytest.raises(GridError, match=match):
            grid_from_fields(*args)


def empty_map() -> OccupancyMap:
    data = np.zeros((40, 60), dtype=np.int8)  # 6 m x 4 m at 0.1 m, origin (-1, -2)
    data[:, 30] = 100  # a wall at x = 2.0 .. 2.1
    data[18:22, 30] = -1  # with an unknown gap at y = -0.2 .. 0.2
    return OccupancyMap(data, 0.1, (-1.0, -2.0, 0.0))


def test_planning_grid_inflates_the_static_map_and_treats_unknown_as_free() -> None:
    grid = PlanningGrid(empty_map(), inflation=0.25)

    assert grid.is_free(np.array([[1.0, 1.0], [2.05, 0.0]])).tolist() == [True, False]
    # Cell 1.7 .. 1.8 comes within 0.2 of the wall's cells: blocked; 1.6 .. 1.7 does not.
    assert not grid.is_free(np.array([1.75, 1.0]))[0]
    assert grid.is_free(np.array([1.65, 1.0]))[0]
    narrow = PlanningGrid(empty_map(), inflation=0.0)
    assert narrow.segment_is_free((0.0, 0.0), (4.0, 0.0))  # through the unknown gap
    assert not narrow.segment_is_free((0.0, 1.0), (4.0, 1.0))
    assert narrow.path_is_free(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 1.5]]))
    assert not narrow.path_is_free(np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 1.5]]))
    assert grid.is_free(np.array([100.0, 100.0]))[0]  # outside the map: unknown, free


def test_planning_grid_marks_scan_returns_and_clears_along_the_beams() -> None:
    grid = PlanningGrid(empty_map(), inflation=0.0)
    box = ConvexPolygon.from_box(1.0, -0.2, 1.3, 0.2)
    laser = SimulatedLaser([box], fov=math.pi, beams=181)
    grid.add_scan(laser.scan((0.0, 0.0, 0.0)), (0.0, 0.0, 0.0))
    assert not grid.segment_is_free((0.0, 0.0), (1.5, 0.0))  # the box blocks the gap now
    assert grid.is_free(np.array([0.5, 0.0]))[0]

    # The box is gone: the next scan's beams pass where it was and clear its cells.
    grid.add_scan(SimulatedLaser([], fov=math.pi, beams=181).scan((0.0, 0.0, 0.0)),
                  (0.0, 0.0, 0.0))
    assert grid.segment_is_free((0.0, 0.0), (1.5, 0.0))
    assert not grid.is_free(np.array([2.05, 1.0]))[0]  # scans never clear the static map

    grid.add_scan(laser.scan((0.0, 0.0, 0.0)), (0.0, 0.0, 0.0))
    grid.clear_scans()
    assert grid.segment_is_free((0.0, 0.0), (1.5, 0.0))


def test_planning_grid_reads_each_beam_as_rep_117_says() -> None:
    box = ConvexPolygon.from_box(1.0, -0.2, 1.3, 0.2)
    laser = SimulatedLaser([box], fov=math.pi, beams=181)
    seen = laser.scan((0.0, 0.0, 0.0))
    # NaN and out-of-range readings where the box was neither clear its cells nor mark any
    for reading in (np.nan, 20.0, 0.01):
        grid = PlanningGrid(empty_map(), inflation=0.0)
        grid.add_scan(seen, (0.0, 0.0, 0.0))
        marked = grid.occupied.copy()
        grid.add_scan(seen._replace(ranges=np.full_like(seen.ranges, reading)), (0.0, 0.0, 0.0))
        np.testing.assert_array_equal(grid.occupied, marked, err_msg=str(reading))
    # one NaN beam among good ones: the others still mark the box
    grid = PlanningGrid(empty_map(), inflation=0.0)
    grid.add_scan(seen._replace(ranges=np.where(np.arange(181) == 90, np.nan, seen.ranges)),
                  (0.0, 0.0, 0.0))
    assert not grid.segment_is_free((0.0, 0.0), (1.5, 0.0))
    # -inf: the cell at range_min along the beam is marked, and nothing is cleared
    grid.add_scan(seen._replace(ranges=np.where(np.arange(181) == 90, -np.inf, np.nan),
                                range_min=0.5), (0.0, 0.0, 0.0))
    assert not grid.is_free(np.array([0.55, 0.05]))[0]  # the cell x 0.5 .. 0.6, y 0 .. 0.1
    assert not grid.segment_is_free((1.0, 0.0), (1.5, 0.0))  # the box stays


@pytest.mark.parametrize(('body', 'front'), [(Footprint.circle(0.2), 0.2), (JACKAL, 0.254)])
def test_planning_grid_takes_no_mark_from_the_robots_body(body: Footprint,
                                                          front: float) -> None:
    # 181 beams around the front half-plane of a laser at the robot's origin, all -inf
    # (range_min 5 cm: inside the body), but for an obstacle 1 cm beyond the front face
    ranges = np.full(181, -np.inf)
    ranges[90] = front + 0.01
    scan = Scan(-math.pi / 2, math.pi / 180, 0.05, 10.0, ranges)
    grid = PlanningGrid(empty_map(), inflation=0.0)
    static = grid.occupied.copy()

    grid.add_scan(scan, (0.0, 0.0, 0.0), body=body)

    def marks() -> list[list[int]]:
        return np.argwhere(grid.occupied & ~static).tolist()

    def cell(x: float, y: float) -> list[int]:
        rows, cols = grid.map.world_to_cell(np.array([[x, y]]))
        return [int(rows[0]), int(cols[0])]

    assert marks() == [cell(front + 0.01, 0.0)]  # the obstacle's cell, none of the body's
    # None (the default): the -inf points mark the cells under the robot
    grid.clear_scans()
    grid.add_scan(scan, (0.0, 0.0, 0.0))
    assert cell(0.0, 0.05) in marks() and cell(0.0, -0.05) in marks()
    # -inf ahead and behind a laser on the front face: ahead, range_min reaches out of the
    # body and marks the cell there; behind, it stays inside
    grid.clear_scans()
    both_ways = Scan(0.0, math.pi, 0.05, 10.0, np.array([-np.inf, -np.inf]))
    grid.add_scan(both_ways, (0.0, 0.0, 0.0), laser_pose=(front, 0.0, 0.0), body=body)
    assert marks() == [cell(front + 0.05, 0.0)]


def test_first_within_says_how_far_along_a_path_an_obstacle_comes_within_the_margin() -> None:
    grid = PlanningGrid(empty_map(), inflation=0.25)
    # the wall's cells start at x = 2.0 (grown by a cell: 1.9); the path runs along y = 1
    path = np.array([[0.0, 1.0], [3.0, 1.0]])
    at = grid.first_within(path, 0.2)
    assert at is not None and 1.6 <= at <= 1.75
    assert grid.first_within(np.array([[0.0, 1.0], [1.0, 1.0], [1.0, -1.0]]), 0.2) is None
    # the distances bound the true distance to the occupied cells from below
    assert np.all(grid.distance[:17, 30] == 0.0)  # the wall (the gap at rows 18-21 is unknown)
    assert grid.distance[0, 0] <= 2.9 + 1e-9  # cell x -1.0 .. -0.9, the wall from x = 2.0
    assert PlanningGrid(OccupancyMap(np.zeros((4, 4), dtype=np.int8), 0.1, (0.0, 0.0, 0.0)),
                        inflation=0.1).first_within(path, 10.0) is None


def test_escape_point_is_the_nearest_clear_cell_reachable_straight_from_the_robot() -> None:
    grid = PlanningGrid(empty_map(), inflation=0.25)
    robot = np.array([1.75, 1.0])  # 0.15 m from the wall's grown cells: inside the inflation
    assert not grid.is_free(robot)[0]
    point = grid.escape_point(robot, within=1.0, margin=0.1)
    assert point is not None and grid.is_free(point)[0]
    assert np.hypot(*(point - robot)) <= 0.15 + 1e-9  # the cell just clear of it
    assert grid.first_within(np.vstack([robot, point]), 0.1) is None
    # nothing clear within reach: None
    assert grid.escape_point(robot, within=0.05, margin=0.1) is None


def test_planning_grid_refuses_bad_options_and_scans() -> None:
    with pytest.raises(ValueError, match='inflation'):
        PlanningGrid(empty_map(), inflation=-0.1)
    grid = PlanningGrid(empty_map(), inflation=0.1)
    with pytest.raises(ValueError, match='range_min must be finite'):
        grid.add_scan(Scan(0.0, 0.1, math.nan, 5.0, np.array([1.0, 2.0])), (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match='angle_increment must not be 0'):
        grid.add_scan(Scan(0.0, 0.0, 0.0, 5.0, np.array([1.0, 2.0])), (0.0, 0.0, 0.0))
