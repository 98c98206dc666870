# SPDX-License-Identifier: Apache-2.0
"""The free space a planner searches: what it needs of a grid, and a round robot's queries.

`FreeSpaceGrid` and `EscapeGrid` say what the planner and the re-planning policy need of an
inflated occupancy grid (perception's ``PlanningGrid`` is one); `grid_bounds` is a grid's
extent. `PointSpace` holds the three queries the planner makes for a round robot's
reference point, over inflated polygons (`polygon_space`, exact segment tests) or an
inflated grid (`grid_space`, every cell a segment passes through: `cells_crossed`).
NumPy only: no OMPL here, so core/footprint_checks.py and core/replanning.py can use the
protocols without importing the planner.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from itertools import pairwise
import math
from typing import Any, NamedTuple, Protocol

import numpy as np

from mpc_local_planner.core.obstacles import ObstacleSet

__all__ = [
    'cells_crossed',
    'EscapeGrid',
    'FreeSpaceGrid',
    'grid_bounds',
    'grid_space',
    'PointSpace',
    'polygon_space',
]


def _hits(obstacles: ObstacleSet, a: np.ndarray, b: np.ndarray) -> bool:
    """Say whether segment a-b touches an inflated obstacle (grazing counts: full clearance)."""
    return bool(np.any(obstacles.segment_hits(a, b, grazing=True)))


class FreeSpaceGrid(Protocol):
    """What the planner needs of an inflated occupancy grid (perception's ``PlanningGrid``).

    ``map`` is the grid's geometry (an ``OccupancyMap``: ``origin`` (x, y, yaw) of the
    lower-left corner, ``resolution``, ``width``, ``height``, ``world_to_cell``,
    ``contains_cell``); ``occupied`` the (height, width) cells that are obstacles before
    inflation, ``blocked`` those within ``inflation`` (metres) of one. Points outside the
    grid are free.
    """

    inflation: float

    @property
    def map(self) -> Any:
        """The grid's geometry (origin, resolution, width, height, world_to_cell)."""

    @property
    def occupied(self) -> np.ndarray:
        """(height, width) booleans: the obstacle cells before inflation."""

    @property
    def blocked(self) -> np.ndarray:
        """(height, width) booleans: the cells within the inflation of an obstacle cell."""

    def is_free(self, points: np.ndarray) -> np.ndarray:
        """Say, per (N, 2) point, whether it is free after inflation."""


class EscapeGrid(Protocol):
    """A grid that finds where a robot inside the inflation can start a plan from."""

    def escape_point(self, position: Sequence[float], *, within: float,
                     margin: float) -> np.ndarray | None:
        """Return the nearest clear point the robot can drive straight to, or None."""


def grid_bounds(grid: FreeSpaceGrid) -> tuple[float, float, float, float]:
    """Return (xmin, xmax, ymin, ymax) of the grid's extent (its corners, if rotated)."""
    occupancy = grid.map
    x0, y0, yaw = (float(v) for v in occupancy.origin)
    width = occupancy.width * float(occupancy.resolution)
    height = occupancy.height * float(occupancy.resolution)
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([[0.0, 0.0], [width, 0.0], [width, height], [0.0, height]])
    xs = x0 + c * local[:, 0] - s * local[:, 1]
    ys = y0 + s * local[:, 0] + c * local[:, 1]
    return float(xs.min()), float(xs.max()), float(ys.min()), float(ys.max())


class PointSpace:
    """Where a round robot's reference point may be: the queries the planner makes.

    Two kinds: inflated polygons (exact segment tests) and an inflated grid. Holds only
    NumPy data and plain callables: it must not reference OMPL objects, or the reference
    cycle through C++ would keep them alive past the plan.
    """

    def __init__(self, point_free: Callable[[np.ndarray], bool],
                 segment_free: Callable[[np.ndarray, np.ndarray], bool],
                 collision: Callable[[np.ndarray], str | None]) -> None:
        self.point_free = point_free
        self.segment_free = segment_free
        self.collision = collision


def polygon_space(obstacles: ObstacleSet, inflation: float) -> PointSpace:
    """Return the queries over obstacles already inflated by ``inflation`` (exact segments)."""
    def collision(xy: np.ndarray) -> str | None:
        index = obstacles.first_containing(xy)
        if index is None:
            return None
        return (f'in collision with obstacle {index} inflated by {inflation:g} m '
                '(robot_radius + clearance)')

    return PointSpace(point_free=lambda xy: obstacles.first_containing(xy) is None,
                  segment_free=lambda a, b: not _hits(obstacles, a, b),
                  collision=collision)


def cells_crossed(occupancy: Any, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return (rows, cols) of every cell the segment a-b passes through (may be outside).

    Exact: the segment is cut where it crosses a grid line, and the middle of each piece
    names one cell it runs through; so no cell is skipped, however little is clipped of it.
    The cells of the pieces come first, in order from a, then a's and b's own.
    """
    rows, cols = _cells_crossed(_GridFrame.of(occupancy), a, b)
    return np.array(rows, dtype=np.int64), np.array(cols, dtype=np.int64)


class _GridFrame(NamedTuple):
    """A grid's origin, the cosine and sine of its yaw and its resolution, as floats."""

    x0: float
    y0: float
    cos: float
    sin: float
    resolution: float

    @classmethod
    def of(cls, occupancy: Any) -> _GridFrame:
        x0, y0, yaw = (float(v) for v in occupancy.origin)
        return cls(x0, y0, math.cos(yaw), math.sin(yaw), float(occupancy.resolution))


def _cells_crossed(frame: _GridFrame, a: Sequence[float], b: Sequence[float]
                   ) -> tuple[list[int], list[int]]:
    """cells_crossed on plain floats, as lists: the planner asks it of every edge it tries.

    A segment crosses tens of cells, too few for NumPy's per-call cost to pay. The arithmetic
    is cells_crossed's, operation for operation, so the cells are too.
    """
    x0, y0, c, s, res = frame
    ax, ay = float(a[0]) - x0, float(a[1]) - y0
    bx, by = float(b[0]) - x0, float(b[1]) - y0
    u0, u1 = (c * ax + s * ay) / res, (c * bx + s * by) / res  # grid coordinates, in cells
    v0, v1 = (-s * ax + c * ay) / res, (-s * bx + c * by) / res
    cuts = {0.0, 1.0}
    for p0, p1 in ((u0, u1), (v0, v1)):
        if p1 != p0:
            span = p1 - p0
            for line in range(math.ceil(min(p0, p1)), math.floor(max(p0, p1)) + 1):
                cuts.add(min(max((line - p0) / span, 0.0), 1.0))
    mid = [0.5 * (t0 + t1) for t0, t1 in pairwise(sorted(cuts))]
    mid += [0.0, 1.0]  # the end points' own cells
    du, dv = u1 - u0, v1 - v0
    return ([math.floor(v0 + m * dv) for m in mid], [math.floor(u0 + m * du) for m in mid])


def grid_space(grid: FreeSpaceGrid) -> PointSpace:
    """Return the queries over an inflated grid (a segment by every cell it passes through)."""
    occupancy = grid.map

    def point_free(xy: np.ndarray) -> bool:
        return bool(grid.is_free(xy.reshape(1, 2))[0])

    frame = _GridFrame.of(occupancy)
    height, width = int(occupancy.height), int(occupancy.width)

    def segment_free(a: np.ndarray, b: np.ndarray) -> bool:
        blocked = grid.blocked  # a sensing grid renews it as scans come
        rows, cols = _cells_crossed(frame, a, b)
        # outside the grid counts free
        return not any(blocked[row, col] for row, col in zip(rows, cols, strict=True)
                       if 0 <= row < height and 0 <= col < width)

    def collision(xy: np.ndarray) -> str | None:
        if point_free(xy):
            return None
        rows, cols = occupancy.world_to_cell(xy.reshape(1, 2))
        row, col = int(rows[0]), int(cols[0])
        where = 'in an occupied cell' if grid.occupied[row, col] else (
            f'within {grid.inflation:g} m of an occupied cell')
        return (f'{where} (cell row {row}, column {col}) of the grid inflated by '
                f'{grid.inflation:g} m (robot_radius + clearance)')

    return PointSpace(point_free=point_free, segment_free=segment_free, collision=collision)

