# SPDX-License-Identifier: Apache-2.0
"""The planner's grid queries (free_space.py) against brute force.

A segment is free on the grid when no cell it passes through is blocked: cells_crossed must
name every cell whose inside the segment enters (else the planner could cut a corner of an
obstacle) and no cell the segment does not touch (else it would refuse a free edge).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core.free_space import cells_crossed, grid_space
from mpc_local_planner.worlds.map_files import OccupancyMap

# cells checked beyond the segment's bounding box, either side (none of them is touched)
MARGIN = 2


def to_cells(grid: OccupancyMap, xy: np.ndarray) -> np.ndarray:
    """Return xy (metres, map frame) in the grid's own coordinates, in cells."""
    x0, y0, yaw = grid.origin
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = xy[0] - x0, xy[1] - y0
    return np.array([c * dx + s * dy, -s * dx + c * dy]) / grid.resolution


def clipped_length(a: np.ndarray, b: np.ndarray, col: int, row: int,
                   shrink: float = 0.0) -> float | None:
    """Return the length of a-b inside the closed cell square (None: it misses the square).

    The square shrunk by shrink on every side, when given.
    """
    t0, t1 = 0.0, 1.0
    d = b - a
    for axis, low in ((0, col), (1, row)):
        for bound, sign in ((low + shrink, -1.0), (low + 1 - shrink, 1.0)):
            p, q = sign * d[axis], sign * (bound - a[axis])
            if p == 0.0:
                if q < 0.0:
                    return None
                continue
            t = q / p
            if p < 0.0:
                t0 = max(t0, t)
            else:
                t1 = min(t1, t)
    return None if t0 > t1 else (t1 - t0) * float(np.hypot(*d))


def strictly_inside(point: np.ndarray, col: int, row: int) -> bool:
    return col < point[0] < col + 1 and row < point[1] < row + 1


@pytest.mark.parametrize('yaw', [0.0, 0.4, -2.5])
def test_cells_crossed_are_the_cells_the_segment_enters_and_only_cells_it_touches(
        yaw: float) -> None:
    grid = OccupancyMap(np.zeros((60, 50)), 0.05, (-0.7, 0.3, yaw))
    rng = np.random.default_rng(7)
    for trial in range(250):
        a = rng.uniform(-1.0, 2.0, 2)
        b = a + rng.normal(0.0, 0.2, 2)
        if trial % 4 == 0:  # along a grid line, through corners: the hard cases
            a_cells = np.round(to_cells(grid, a))
            b_cells = a_cells + rng.integers(-5, 6, 2) * np.array([1, trial % 8 == 0])
            a, b = (grid_point(grid, p) for p in (a_cells, b_cells))
        rows, cols = cells_crossed(grid, a, b)
        named = set(zip(rows.tolist(), cols.tolist(), strict=True))
        ua, ub = to_cells(grid, a), to_cells(grid, b)
        low = np.floor(np.minimum(ua, ub)).astype(int) - MARGIN
        high = np.floor(np.maximum(ua, ub)).astype(int) + MARGIN
        for row in range(low[1], high[1] + 1):
            for col in range(low[0], high[0] + 1):
                # into the open square, not along its edge
                inside = clipped_length(ua, ub, col, row, shrink=1e-9)
                enters = ((inside is not None and inside > 0.0)
                          or strictly_inside(ua, col, row) or strictly_inside(ub, col, row))
                if enters:
                    assert (row, col) in named, (trial, a, b, row, col)
                if (row, col) in named:
                    # touched: reached within rounding (the cut points are computed)
                    assert clipped_length(ua, ub, col, row) is not None or near(
                        ua, ub, col, row), (trial, a, b, row, col)


def grid_point(grid: OccupancyMap, cells: np.ndarray) -> np.ndarray:
    """Return the map-frame point at these grid coordinates (cells)."""
    x0, y0, yaw = grid.origin
    c, s = math.cos(yaw), math.sin(yaw)
    u, v = cells * grid.resolution
    return np.array([x0 + c * u - s * v, y0 + s * u + c * v])


def near(a: np.ndarray, b: np.ndarray, col: int, row: int) -> bool:
    """The segment passes within 1e-9 cells of the cell square."""
    grown = [(a + offset, b + offset) for offset in
             (np.array([dx, dy]) for dx in (-1e-9, 0, 1e-9) for dy in (-1e-9, 0, 1e-9))]
    return any(clipped_length(p, q, col, row) is not None for p, q in grown)


class FakeGrid:
    """A FreeSpaceGrid with one blocked cell."""

    inflation = 0.0

    def __init__(self, blocked_cell: tuple[int, int]) -> None:
        self.map = OccupancyMap(np.zeros((20, 30)), 0.1, (0.0, 0.0, 0.0))
        self.blocked = np.zeros((20, 30), dtype=bool)
        self.blocked[blocked_cell] = True
        self.occupied = self.blocked

    def is_free(self, points: np.ndarray) -> np.ndarray:
        rows, cols = self.map.world_to_cell(points)
        inside = self.map.contains_cell(rows, cols)
        free = np.ones(len(points), dtype=bool)
        free[inside] = ~self.blocked[rows[inside], cols[inside]]
        return free


def test_a_segment_is_refused_for_the_corner_of_a_blocked_cell_and_free_outside_the_grid(
        ) -> None:
    space = grid_space(FakeGrid((5, 5)))  # the cell [0.5, 0.6] x [0.5, 0.6]
    # clips the blocked cell's lower-right corner, between two free cells
    assert not space.segment_free(np.array([0.45, 0.45]), np.array([0.65, 0.56]))
    assert space.segment_free(np.array([0.45, 0.45]), np.array([0.65, 0.48]))
    # beyond the grid's edges everything is free
    assert space.segment_free(np.array([-1.0, -1.0]), np.array([-0.5, 5.0]))
    assert space.segment_free(np.array([2.5, 1.5]), np.array([10.0, 1.5]))
