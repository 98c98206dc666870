# SPDX-License-Identifier: Apache-2.0
"""A deterministic grid search: the corridor a robot fits through, preferring room.

RRT* samples its states, and a passage barely wider than the robot is one it rarely
samples aligned with (BARN's hardest worlds: gaps a few centimetres wider than the Jackal).
A search over the grid's cells finds such a passage whenever the cells connect, as Nav2's
NavFn and Smac planners do:

- a cell is passable where the robot's inscribed disc, grown by the hard margin, is clear
  of every occupied cell's centre (`clearance_field`: the exact distance from each cell
  centre to the nearest occupied one); near the start and the goal, where a robot may
  already stand tighter than that, cells as clear as the endpoint's own count too;
- Dijkstra (scipy.sparse.csgraph) over the 8-connected passable cells, each step costing
  its length times 1 + ``room_weight`` exp(-(d - d_min) / ``room_decay``): the clearance is
  a cost that prefers room (Nav2's inflation cost), not a margin that closes a gap;
- `pull_string` then turns the cell path into few straight segments, each kept only where
  a caller's motion check accepts it (the planner checks the real footprint there).

NumPy and SciPy only (no OMPL, no rclpy).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import math

import numpy as np
from scipy.ndimage import distance_transform_edt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

__all__ = [
    'GridSearchSettings',
    'clearance_field',
    'pull_string',
    'shortest_cells',
]

# The four half-neighbourhoods of an 8-connected grid (the other four are their reverses).
_STEPS = ((0, 1), (1, 0), (1, 1), (1, -1))


@dataclass(frozen=True)
class GridSearchSettings:
    """How the grid search weighs room against length.

    Attributes:
        room_weight: Extra cost per metre next to the hard margin, relative to the length
            (0: the shortest corridor, however tight).
        room_decay: Distance beyond the hard margin over which that extra cost falls by e,
            metres.
        endpoint_reach: Around the start and the goal, cells at least as clear as the
            endpoint's own cell are passable within this distance, metres (a robot may
            stand tighter than the hard margin asks of the corridor).

    """

    room_weight: float = 4.0
    room_decay: float = 0.15
    endpoint_reach: float = 0.5

    def __post_init__(self) -> None:
        """Refuse settings that make no search."""
        for name in ('room_weight', 'room_decay', 'endpoint_reach'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                msg = f'{name} must be >= 0 and finite, got {value!r}'
                raise ValueError(msg)
        if self.room_decay == 0.0:
            msg = 'room_decay must be > 0'
            raise ValueError(msg)


def clearance_field(occupied: np.ndarray, resolution: float) -> np.ndarray:
    """Return each cell centre's distance to the nearest occupied cell's centre, metres.

    Args:
        occupied: (height, width) booleans.
        resolution: Cell side, metres.

    Returns:
        (height, width) distances (0 on occupied cells, inf without any).

    """
    occupied = np.asarray(occupied, dtype=bool)
    if not occupied.any():
        return np.full(occupied.shape, np.inf)
    return distance_transform_edt(~occupied) * float(resolution)


def _endpoint_floor(clearance: np.ndarray, cell: tuple[int, int], reach: int,
                    threshold: float) -> tuple[slice, slice, float]:
    """Return the window about an endpoint cell and the clearance its cells need there."""
    row, col = cell
    height, width = clearance.shape
    rows = slice(max(row - reach, 0), min(row + reach + 1, height))
    cols = slice(max(col - reach, 0), min(col + reach + 1, width))
    return rows, cols, min(threshold, float(clearance[row, col]))


def shortest_cells(clearance: np.ndarray, threshold: float, start: tuple[int, int],
                   goal: tuple[int, int], *, resolution: float,
                   settings: GridSearchSettings = GridSearchSettings(),
                   blocked: np.ndarray | None = None) -> np.ndarray | None:
    """Return the cheapest 8-connected path of passable cells from start to goal, or None.

    A cell is passable where its clearance exceeds threshold; within
    ``settings.endpoint_reach`` of the start (and of the goal) also where it is at least
    the endpoint cell's own (positive) clearance, and the endpoint cells themselves are.
    A step costs its length times 1 + room_weight exp(-(d - threshold) / room_decay), d the
    mean clearance of its two cells (the room a passage leaves is preferred). Cells marked
    in ``blocked`` are never passable, except the endpoint cells.

    Args:
        clearance: (height, width) cell clearances, metres (`clearance_field`).
        threshold: Clearance a cell of the corridor needs, metres.
        start: (row, column) of the start cell, inside the grid.
        goal: (row, column) of the goal cell, inside the grid.
        resolution: Cell side, metres.
        settings: The cost's weights.
        blocked: (height, width) booleans: cells no path may enter (None: none).

    Returns:
        (K, 2) (row, column) cells from start to goal, or None if they do not connect.

    """
    height, width = clearance.shape
    passable = clearance > threshold
    reach = int(math.ceil(settings.endpoint_reach / resolution))
    for cell in (start, goal):
        rows, cols, floor = _endpoint_floor(clearance, cell, reach, threshold)
        if floor > 0.0:
            passable[rows, cols] |= clearance[rows, cols] >= floor
    if blocked is not None:
        passable &= ~np.asarray(blocked, dtype=bool)
    for cell in (start, goal):
        passable[cell] = True
    finite = np.minimum(clearance, threshold + 50.0 * settings.room_decay)
    room = 1.0 + settings.room_weight * np.exp(
        -np.maximum(finite - threshold, 0.0) / settings.room_decay)
    index = np.arange(height * width).reshape(height, width)
    sources, targets, weights = [], [], []
    for dr, dc in _STEPS:
        r0, r1 = 0, height - dr
        c0, c1 = max(-dc, 0), width - max(dc, 0)
        a = (slice(r0, r1), slice(c0, c1))
        b = (slice(r0 + dr, r1 + dr), slice(c0 + dc, c1 + dc))
        both = passable[a] & passable[b]
        sources.append(index[a][both])
        targets.append(index[b][both])
        weights.append(math.hypot(dr, dc) * resolution * 0.5 * (room[a][both] + room[b][both]))
    graph = coo_matrix((np.concatenate(weights),
                        (np.concatenate(sources), np.concatenate(targets))),
                       shape=(height * width, height * width)).tocsr()
    first, last = int(index[start]), int(index[goal])
    if first == last:
        return np.array([start])
    distances, previous = dijkstra(graph, directed=False, indices=first,
                                   return_predecessors=True)
    if not math.isfinite(distances[last]):
        return None
    chain = [last]
    while chain[-1] != first:
        chain.append(int(previous[chain[-1]]))
    cells = np.array(chain[::-1])
    return np.column_stack([cells // width, cells % width])


def pull_string(points: np.ndarray, motion_ok: Callable[[int, int, int | None], bool], *,
                budget: int | None = None) -> list[int] | None:
    """Return the indices of few points whose segments a motion check accepts, or None.

    From each corner the points a motion reaches are scanned forwards, up to the first
    refusal after an acceptance (before any acceptance every later point is tried); the
    farthest is the next corner. Where no motion leaves a corner (a turn in place that the
    robot cannot make there), the search backs up and tries the previous corner's nearer
    candidates: a depth-first search, farthest first. ``motion_ok(i, j, k)`` says whether
    the straight motion from point i to point j is clear, k being the corner before i (None
    at the first point), so that the turn at i can be checked too.

    Args:
        points: (N, 2) the path's points, N >= 2.
        motion_ok: The motion check.
        budget: Most motion checks before giving up (None: 50 N).

    Returns:
        The corners' indices, from 0 to N - 1, or None where no sequence of motions was found.

    """
    last = len(points) - 1
    budget = 50 * len(points) if budget is None else budget
    checked = 0

    def reachable(i: int, previous: int | None) -> list[int]:
        nonlocal checked
        found: list[int] = []
        for j in range(i + 1, last + 1):
            checked += 1
            if motion_ok(i, j, previous):
                found.append(j)
            elif found:
                break
        return found[::-1]  # farthest first

    corners = [0]
    options = [reachable(0, None)]
    tried: set[tuple[int, int | None]] = set()  # (corner, previous) pairs that led nowhere
    while options:
        if corners[-1] == last:
            return corners
        if not options[-1] or checked > budget:
            if checked > budget:
                return None
            if len(corners) > 1:
                tried.add((corners[-1], corners[-2]))
            corners.pop()
            options.pop()
            continue
        j = options[-1].pop(0)
        if (j, corners[-1]) in tried:
            continue
        previous = corners[-1]
        corners.append(j)
        options.append([] if j == last else reachable(j, previous))
    return None
