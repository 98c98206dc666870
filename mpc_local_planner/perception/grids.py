# SPDX-License-Identifier: Apache-2.0
"""Occupancy grids as the controller and the planner need them.

- `grid_rectangles`: the MPC avoids convex polygons, one Farkas multiplier vector each, so a
  map's occupied cells near the robot are merged into few axis-aligned rectangles that cover
  them exactly (runs of occupied cells per row, stacked while the run below is the same).
- `PlanningGrid`: what the RRT* planner checks its motions against: the static map, plus
  cells marked by scan returns and cleared along the beams, unknown cells free (optimistic,
  as the BARN baselines plan), inflated by the robot radius plus a clearance with a
  Euclidean distance transform.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy.ndimage import binary_dilation, distance_transform_edt

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import points_along
from mpc_local_planner.perception.scans import (
    classify_beams,
    compose_pose,
    Scan,
    scan_points,
    validate_scan,
)
from mpc_local_planner.worlds.map_files import OccupancyMap, OCCUPIED

__all__ = [
    'DEFAULT_OCCUPIED_THRESHOLD',
    'GridError',
    'PlanningGrid',
    'grid_from_fields',
    'grid_rectangles',
]

#: Cells with at least this value are obstacles (map_server's occupied_thresh 0.65).
DEFAULT_OCCUPIED_THRESHOLD = 65


class GridError(ValueError):
    """An occupancy grid is malformed (size, resolution or origin)."""


def grid_from_fields(data: Sequence[int] | np.ndarray, width: int, height: int,
                     resolution: float, origin: Sequence[float]) -> OccupancyMap:
    """Check the fields of an OccupancyGrid message and return them as a map.

    Args:
        data: Row-major cell values, row 0 at the bottom (the message's ``data``).
        width: Number of columns.
        height: Number of rows.
        resolution: Cell side, metres.
        origin: (x, y, yaw) of the grid's lower-left corner in the map frame.

    Returns:
        The grid.

    Raises:
        GridError: If width * height != len(data), a size is not positive, the resolution is
            not > 0 or the origin is not finite.

    """
    values = np.asarray(data)
    if isinstance(width, bool) or isinstance(height, bool) or not (
            isinstance(width, (int, np.integer)) and isinstance(height, (int, np.integer))):
        msg = f'grid width and height must be integers, got {width!r}, {height!r}'
        raise GridError(msg)
    if width <= 0 or height <= 0:
        msg = f'grid width and height must be > 0, got {width} x {height}'
        raise GridError(msg)
    if values.ndim != 1 or width * height != len(values):
        msg = f'grid is {width} x {height} = {width * height} cells but data has {values.size}'
        raise GridError(msg)
    if not (isinstance(resolution, (int, float)) and math.isfinite(resolution)
            and resolution > 0.0):
        msg = f'grid resolution must be > 0, got {resolution!r}'
        raise GridError(msg)
    origin = tuple(float(v) for v in origin)
    if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
        msg = f'grid origin must be three finite numbers (x, y, yaw), got {origin!r}'
        raise GridError(msg)
    if values.size and (values.min() < -1 or values.max() > OCCUPIED):
        msg = 'grid values must be -1 (unknown) or 0..100'
        raise GridError(msg)
    return OccupancyMap(data=values.astype(np.int8).reshape(height, width),
                        resolution=float(resolution), origin=origin)  # type: ignore[arg-type]


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (row, first column, end column) of every horizontal run of True cells."""
    padded = np.zeros((mask.shape[0], mask.shape[1] + 2), dtype=np.int8)
    padded[:, 1:-1] = mask
    step = np.diff(padded, axis=1)
    rows_s, starts = np.nonzero(step == 1)
    _, ends = np.nonzero(step == -1)  # same row-major order as the starts
    return rows_s, starts, ends


def grid_rectangles(occupancy: OccupancyMap, *, centre: Sequence[float] | None = None,
                    radius: float = math.inf,
                    threshold: int = DEFAULT_OCCUPIED_THRESHOLD) -> list[ConvexPolygon]:
    """Cover the occupied cells in a window with few axis-aligned rectangles, exactly.

    Each row's occupied cells form runs; a run stacks onto the rectangle below it when that
    rectangle's run has the same columns. The rectangles are disjoint and their union is
    exactly the occupied cells of the window (cell edges, not centres), in the map frame
    (rotated with the grid's origin yaw).

    Args:
        occupancy: The grid.
        centre: (x, y) of the window's centre in the map frame; None: the whole grid.
        radius: Half the side of the square window, metres (cells that overlap it count).
        threshold: Cells with a value >= threshold are occupied (unknown, -1, is not).

    Returns:
        The rectangles as ConvexPolygon boxes.

    """
    r0, c0, r1, c1 = 0, 0, occupancy.height, occupancy.width
    if centre is not None and math.isfinite(radius):
        res = occupancy.resolution
        row, col = occupancy.world_to_cell(np.asarray(centre, dtype=float)[:2])
        cells = int(math.ceil(radius / res))
        r0, r1 = max(int(row) - cells, 0), min(int(row) + cells + 1, occupancy.height)
        c0, c1 = max(int(col) - cells, 0), min(int(col) + cells + 1, occupancy.width)
        if r0 >= r1 or c0 >= c1:
            return []
    mask = occupancy.data[r0:r1, c0:c1] >= threshold
    rows, starts, ends = _runs(mask)
    if not len(rows):
        return []
    order = np.lexsort((rows, ends, starts))
    rows, starts, ends = rows[order], starts[order], ends[order]
    same = np.zeros(len(rows), dtype=bool)
    same[1:] = (starts[1:] == starts[:-1]) & (ends[1:] == ends[:-1]) & (
        rows[1:] == rows[:-1] + 1)
    first = np.flatnonzero(~same)
    last = np.append(first[1:], len(rows)) - 1
    bottom, top = rows[first] + r0, rows[last] + r0 + 1
    left, right = starts[first] + c0, ends[first] + c0
    return _boxes(occupancy, bottom, top, left, right)


def _boxes(occupancy: OccupancyMap, bottom: np.ndarray, top: np.ndarray, left: np.ndarray,
           right: np.ndarray) -> list[ConvexPolygon]:
    """Build polygons for cell-index boxes [left, right) x [bottom, top) in the map frame."""
    x0, y0, yaw = occupancy.origin
    res = occupancy.resolution
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.stack([np.column_stack([left, bottom]), np.column_stack([right, bottom]),
                      np.column_stack([right, top]), np.column_stack([left, top])],
                     axis=1).astype(float) * res  # (K, 4, 2), counter-clockwise
    corners = np.stack([x0 + c * local[..., 0] - s * local[..., 1],
                        y0 + s * local[..., 0] + c * local[..., 1]], axis=-1)
    normals = np.array([[s, -c], [c, s], [-s, c], [-c, -s]])  # -y, +x, +y, -x rotated
    offsets = np.einsum('fj,kfj->kf', normals, corners)
    return [ConvexPolygon(A=normals.copy(), b=offsets[k], vertices=corners[k])
            for k in range(len(corners))]


class PlanningGrid:
    """The planner's grid: static map plus scans, inflated for motion checks.

    Static cells at or above ``threshold`` are permanent. Scans mark the cells of their
    returns and clear, in the scan layer only, the cells their beams pass through (up to the
    cell before the return, or ``clear_range`` for a beam without return). Unknown cells
    and everything outside the grid count as free. A cell is blocked when some point of it
    is within ``inflation`` of some point of an occupied cell, so inflation never shrinks an
    obstacle: the occupied cells are grown by their 8 neighbours (the nearest points of two
    cells are a lattice step apart less than their centres), then by a Euclidean distance
    transform. Queries look up the cell of each point; segments are sampled at most half a
    cell apart.

    Args:
        static_map: The map (its extent is the grid's extent).
        inflation: Robot radius plus clearance, metres (>= 0).
        threshold: Occupied threshold of the static map.
        clear_range: Beams clear at most this far, metres (as nav2's raytrace_max_range).

    Raises:
        ValueError: If inflation or clear_range is negative or not finite.

    """

    def __init__(self, static_map: OccupancyMap, *, inflation: float,
                 threshold: int = DEFAULT_OCCUPIED_THRESHOLD, clear_range: float = 5.0) -> None:
        if not (math.isfinite(inflation) and inflation >= 0.0):
            msg = f'inflation must be >= 0, got {inflation!r}'
            raise ValueError(msg)
        if not (math.isfinite(clear_range) and clear_range >= 0.0):
            msg = f'clear_range must be >= 0, got {clear_range!r}'
            raise ValueError(msg)
        self.map = static_map
        self.inflation = float(inflation)
        self.clear_range = float(clear_range)
        self._static = static_map.data >= threshold
        self._scan = np.zeros_like(self._static)
        self._blocked: np.ndarray | None = None
        self._distance: np.ndarray | None = None

    @property
    def occupied(self) -> np.ndarray:
        """(height, width) booleans: static obstacles or scan marks (row 0 at the bottom)."""
        return self._static | self._scan

    @property
    def blocked(self) -> np.ndarray:
        """(height, width) booleans: cells within the inflation of an occupied cell."""
        if self._blocked is None:
            self._blocked = self.distance <= self.inflation + 1e-9
        return self._blocked

    @property
    def distance(self) -> np.ndarray:
        """(height, width) lower bounds on each cell's distance to an occupied cell, metres.

        A cell's value bounds the distance from any of its points to any point of an occupied
        cell (the occupied cells are grown by their 8 neighbours first); inf without any.
        """
        if self._distance is None:
            occupied = self.occupied
            if not occupied.any():
                self._distance = np.full(occupied.shape, np.inf)
            else:
                grown = binary_dilation(occupied, structure=np.ones((3, 3), dtype=bool))
                self._distance = distance_transform_edt(~grown) * self.map.resolution
        return self._distance

    def clear_scans(self) -> None:
        """Forget every scan mark (the static map stays)."""
        self._scan[:] = False
        self._blocked = self._distance = None

    def add_scan(self, scan: Scan, robot_pose: Sequence[float], *,
                 laser_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 body: Footprint | None = None) -> None:
        """Clear the cells the beams pass through, then mark the cells of the returns.

        The beams are read as `classify_beams` says: a -inf beam marks the cell at range_min
        and clears nothing; NaN and out-of-range readings neither mark nor clear, and nor
        does a return inside the robot's body (the robot itself: marked, it would block
        every plan from where the robot stands).

        Args:
            scan: The scan (validated here).
            robot_pose: (x, y, yaw) of the robot in the map frame at the scan's stamp.
            laser_pose: (x, y, yaw) of the laser in the robot frame.
            body: The robot's footprint; None: every return marks its cell.

        Raises:
            ScanError: If the scan or a pose is malformed.

        """
        validate_scan(scan)
        ox, oy, oyaw = compose_pose(robot_pose, laser_pose)
        readings = classify_beams(scan, body=body, laser_pose=laser_pose)
        free = np.minimum(readings.free, self.clear_range)
        beams = len(free)
        theta = oyaw + scan.angle_min + np.arange(beams) * scan.angle_increment
        res = self.map.resolution
        # Clear up to one cell short of the return, sampled every half cell.
        length = np.maximum(free - res, 0.0)
        counts = np.ceil(length / (0.5 * res)).astype(np.int64) + 1
        counts[length <= 0.0] = 0
        if counts.sum():
            beam = np.repeat(np.arange(beams), counts)
            step = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
            dist = np.minimum(step * 0.5 * res, length[beam])
            xs = ox + dist * np.cos(theta[beam])
            ys = oy + dist * np.sin(theta[beam])
            rows, cols = self.map.world_to_cell(np.column_stack([xs, ys]))
            inside = self.map.contains_cell(rows, cols)
            self._scan[rows[inside], cols[inside]] = False
        hits, _ = scan_points(scan, robot_pose, laser_pose=laser_pose, readings=readings)
        rows, cols = self.map.world_to_cell(hits)
        inside = self.map.contains_cell(rows, cols)
        self._scan[rows[inside], cols[inside]] = True
        self._blocked = self._distance = None

    def is_free(self, points: np.ndarray) -> np.ndarray:
        """Say, per point, whether its cell is free after inflation (outside counts free).

        Args:
            points: (N, 2) or (2,) map-frame points (further columns are ignored).

        Returns:
            (N,) booleans.

        """
        pts = np.atleast_2d(np.asarray(points, dtype=float))[:, :2]
        rows, cols = self.map.world_to_cell(pts)
        inside = self.map.contains_cell(rows, cols)
        free = np.ones(len(pts), dtype=bool)
        blocked = self.blocked
        free[inside] = ~blocked[rows[inside], cols[inside]]
        return free

    def segment_is_free(self, a: Sequence[float], b: Sequence[float]) -> bool:
        """Say whether the segment from a to b stays in free cells (sampled <= half a cell)."""
        return self.path_is_free(np.array([np.asarray(a, dtype=float)[:2],
                                           np.asarray(b, dtype=float)[:2]]))

    def first_within(self, waypoints: np.ndarray, margin: float) -> float | None:
        """Return how far along a polyline it first comes within margin of an occupied cell.

        Samples at most half a cell apart; outside the grid counts as free. This is the
        re-planning test: a plan made clear of the inflation is blocked when a new obstacle
        (a scan's mark) comes within margin of it.

        Args:
            waypoints: (M, 2) vertices (further columns are ignored).
            margin: Distance to the occupied cells that counts as blocked, metres.

        Returns:
            The distance along the polyline (metres) of the first such sample, or None.

        """
        samples, along = self._samples(waypoints)
        rows, cols = self.map.world_to_cell(samples)
        inside = self.map.contains_cell(rows, cols)
        near = np.zeros(len(samples), dtype=bool)
        near[inside] = self.distance[rows[inside], cols[inside]] <= margin
        hits = np.flatnonzero(near)
        return float(along[hits[0]]) if len(hits) else None

    def escape_point(self, position: Sequence[float], *, within: float,
                     margin: float) -> np.ndarray | None:
        """Return the nearest free cell's centre a robot at position can drive straight to.

        A robot may stand inside the inflation (the planner's clearance is wider than the
        controller's margin), where no plan can start; a re-plan starts from here instead.
        Free means not blocked; the straight segment to it must stay farther than margin
        from every occupied cell, or, for a robot already closer than margin, never come
        closer than the robot already is.

        Args:
            position: (x, y) of the robot, map frame.
            within: Largest distance to the point, metres.
            margin: Distance to occupied cells the segment must exceed, metres.

        Returns:
            (2,) the point, or None if there is none within reach.

        """
        origin = np.asarray(position, dtype=float).reshape(-1)[:2]
        row, col = (int(v[0]) for v in self.map.world_to_cell(origin[None, :]))
        reach = int(math.ceil(within / self.map.resolution)) + 1
        r0, c0 = max(row - reach, 0), max(col - reach, 0)
        window = ~self.blocked[r0:row + reach + 1, c0:col + reach + 1]
        rows, cols = np.nonzero(window)
        if not len(rows):
            return None
        centres = self.map.cell_to_world(rows + r0, cols + c0)
        distance = np.hypot(*(centres - origin).T)
        if self.map.contains_cell(np.array([row]), np.array([col]))[0]:
            margin = min(margin, float(self.distance[row, col]) - 1e-9)
        for k in np.argsort(distance, kind='stable'):
            if distance[k] > within:
                break
            if self.first_within(np.vstack([origin, centres[k]]), margin) is None:
                return centres[k]
        return None

    def _samples(self, waypoints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return points along a polyline at most half a cell apart, and their arc length."""
        return points_along(waypoints, 0.5 * self.map.resolution)

    def path_is_free(self, waypoints: np.ndarray) -> bool:
        """Say whether a polyline stays in free cells, every segment sampled <= half a cell.

        Args:
            waypoints: (M, 2) vertices (further columns are ignored); one point is a point test.

        Returns:
            True if every sample is free.

        """
        return bool(np.all(self.is_free(self._samples(waypoints)[0])))
