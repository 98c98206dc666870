# SPDX-License-Identifier: Apache-2.0
"""Exact checks of a polygon footprint at poses, along straight motions and in turns in place.

The global planner's rule for a polygon robot ("check the poses", see core/planner.py): the
footprint at a pose, driven straight between two poses (the swept polygon, a Minkowski sum
with the segment) and turned in place at a point (sampled headings, each polygon grown by the
most a point moves between samples), against convex polygons (exactly) or the cells of an
occupancy grid (conservatively, by half a cell's diagonal). Touching counts as a collision.
NumPy only: the planner wraps these in OMPL's validity and motion checkers.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import math
from typing import TYPE_CHECKING

import numpy as np

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.obstacles import ConvexPolygon

if TYPE_CHECKING:
    from mpc_local_planner.core.free_space import FreeSpaceGrid

__all__ = ['FootprintChecks', 'FootprintPlan', 'GridObstacles', 'HeldChecks', 'HeldObstacles',
           'NO_TURN', 'PolygonObstacles', 'SAME_POINT', 'TurnRange', 'wrap_heading']

# Consecutive waypoints closer than this are one point, and turns smaller than this (rad) no
# turn: the tolerances WaypointPath (core/paths.py) builds its turn-in-place knots with.
SAME_POINT = 1e-6
NO_TURN = 1e-9
# A turn in place is checked at sampled headings, each polygon grown by r_c * step / 2 (the
# farthest a footprint point moves to the nearest sample): the step is chosen so that this
# over-approximation is at most _TURN_TOLERANCE metres (and the step at most _MAX_TURN_STEP).
_TURN_TOLERANCE = 0.002
_MAX_TURN_STEP = 0.05


def wrap_heading(angle: float) -> float:
    """Wrap an angle to [-pi, pi), exactly as core/paths.py's wrap_angle turns corners."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _place(local: np.ndarray, xy: np.ndarray, headings: np.ndarray) -> np.ndarray:
    """Return (T, K, 2) world vertices of the footprint at xy, one polygon per heading."""
    c = np.cos(headings)[:, None]
    s = np.sin(headings)[:, None]
    x, y = local[None, :, 0], local[None, :, 1]
    return np.stack([xy[0] + c * x - s * y, xy[1] + s * x + c * y], axis=-1)


def _sweep(polygon: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Return the counter-clockwise vertices of what a convex polygon covers translated by d.

    The Minkowski sum of the polygon with the segment [0, d], i.e. the convex hull of the
    polygon and its translate, without a general hull: the edges facing d (outward normal
    . d > 0) come from the translate, the others from the polygon, and each vertex between
    the two groups appears twice (at 0 and at d). Edges parallel to d leave collinear
    vertices, which the checks accept.
    """
    edges = np.concatenate([polygon[1:], polygon[:1]]) - polygon
    front = edges[:, 1] * d[0] - edges[:, 0] * d[1] > 0.0  # normal (e_y, -e_x) faces d
    before = np.concatenate([front[-1:], front[:-1]])  # the edge that ends at each vertex
    first = polygon + np.where(before[:, None], d, 0.0)
    second = polygon + np.where(front[:, None], d, 0.0)
    pairs = np.stack([first, second], axis=1)  # (K, 2, 2)
    keep = np.column_stack([np.ones(len(polygon), dtype=bool), before != front])
    return pairs[keep]


def _edge_distances(points: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Return (..., P, S) distances of points (..., P, 2) to segments (..., S, 2), broadcast."""
    seg = ends - starts
    rel = points[..., :, None, :] - starts[..., None, :, :]
    length2 = np.maximum(np.sum(seg * seg, axis=-1), 1e-300)[..., None, :]
    t = np.clip(np.sum(rel * seg[..., None, :, :], axis=-1) / length2, 0.0, 1.0)
    off = rel - t[..., None] * seg[..., None, :, :]
    return np.hypot(off[..., 0], off[..., 1])


def _outward_normals(polygons: np.ndarray) -> np.ndarray:
    """Return (..., M, 2) unit outward normals of counter-clockwise polygons' edges."""
    edges = np.roll(polygons, -1, axis=-2) - polygons
    normals = np.stack([edges[..., 1], -edges[..., 0]], axis=-1)
    return normals / np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-300)


class PolygonObstacles:
    """Convex obstacles as padded arrays for the footprint's exact queries (no inflation).

    A footprint pose is in collision when the polygon grown by a distance meets an obstacle,
    i.e. when their distance is at most that distance (touching counts, as grazing does for
    the round robot). Separating axes give a lower bound on the distance that settles most
    pairs; the rest get the exact distance of convex polygons (vertex to edge, both ways).
    """

    def __init__(self, obstacles: Sequence[ConvexPolygon]) -> None:
        count = len(obstacles)
        faces = max((o.num_faces for o in obstacles), default=1)
        self._vertices = np.zeros((count, faces, 2))
        self._A = np.zeros((count, faces, 2))
        self._b = np.zeros((count, faces))
        for i, o in enumerate(obstacles):
            rows = np.minimum(np.arange(faces), o.num_faces - 1)  # pad with the last face
            self._vertices[i] = o.vertices[rows]
            self._A[i], self._b[i] = o.A[rows], o.b[rows]
        self._low = self._vertices.min(axis=1) if count else np.zeros((0, 2))
        self._high = self._vertices.max(axis=1) if count else np.zeros((0, 2))

    def _near(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """Return the indices of obstacles whose bounding box meets [low, high]."""
        return np.flatnonzero(np.all((self._low <= high) & (self._high >= low), axis=1))

    def any_near(self, low: np.ndarray, high: np.ndarray, grow: float) -> bool:
        """Say whether an obstacle may be within grow of the box [low, high] (a quick test)."""
        return bool(np.any((self._low[:, 0] <= high[0] + grow)
                           & (self._high[:, 0] >= low[0] - grow)
                           & (self._low[:, 1] <= high[1] + grow)
                           & (self._high[:, 1] >= low[1] - grow)))

    def polygons_hit(self, polygons: np.ndarray, grow: float) -> np.ndarray:
        """Return, per (T, M, 2) counter-clockwise polygon, the first obstacle within grow (-1).

        Args:
            polygons: Convex polygons in the map frame.
            grow: Distance the polygons are grown by (the clearance), metres.

        """
        hits = np.full(len(polygons), -1, dtype=np.int64)
        near = self._near(polygons.min(axis=(0, 1)) - grow, polygons.max(axis=(0, 1)) + grow)
        if not len(near):
            return hits
        verts, A, b = self._vertices[near], self._A[near], self._b[near]
        # separation along the obstacles' normals: max_f (min_m a_f . r_m - b_f)
        along_theirs = np.max(
            np.einsum('nfk,tmk->tnfm', A, polygons).min(axis=3) - b[None], axis=2)
        # and along the polygons' own normals (their own extent by the max, robustly)
        normals = _outward_normals(polygons)
        own = np.einsum('tmk,tjk->tmj', normals, polygons).max(axis=2)  # (T, M)
        theirs = np.einsum('tmk,nfk->tnmf', normals, verts).min(axis=3)  # (T, N, M)
        separation = np.maximum(along_theirs, np.max(theirs - own[:, None, :], axis=2))
        hit = separation <= 0.0  # overlapping or touching
        close = ~hit & (separation <= grow)
        if np.any(close):
            ends = np.roll(verts, -1, axis=1)
            mine = _edge_distances(polygons[:, None], verts[None], ends[None])  # (T, N, M, F)
            yours = _edge_distances(verts[None], polygons[:, None],
                                    np.roll(polygons, -1, axis=1)[:, None])  # (T, N, F, M)
            distance = np.minimum(mine.min(axis=(2, 3)), yours.min(axis=(2, 3)))
            hit |= close & (distance <= grow)
        found = hit.any(axis=1)
        hits[found] = near[np.argmax(hit[found], axis=1)]
        return hits

    def disc_hit(self, xy: np.ndarray, radius: float) -> int:
        """Return the first obstacle within radius of the point xy (exact distance), or -1."""
        near = self._near(xy - radius, xy + radius)
        if not len(near):
            return -1
        verts = self._vertices[near]
        inside = np.max(np.einsum('nfk,k->nf', self._A[near], xy) - self._b[near], axis=1) <= 0
        distance = _edge_distances(xy[None, None], verts, np.roll(verts, -1, axis=1))
        hit = inside | (distance.min(axis=(1, 2)) <= radius)
        return int(near[np.argmax(hit)]) if hit.any() else -1

    def state_free(self, xy: np.ndarray, radius: float) -> bool:
        """Say whether the disc of radius about xy is free (the turn-anywhere test)."""
        return self.disc_hit(xy, radius) < 0

    def describe(self, index: int) -> str:
        """Name what `polygons_hit` or `disc_hit` found."""
        return f'obstacle {index}'


class GridObstacles:
    """A snapshot of a grid for the footprint's queries: raw occupied cells, and blocked ones.

    A polygon grown by a distance is in collision when the centre of an occupied cell (not
    inflated) is within that distance plus half the cell's diagonal: every point of such a
    cell may be that close, so the check is conservative by at most half a diagonal. The
    turn-anywhere test of an intermediate state is the grid's own inflated layer, by the
    state's cell (``blocked``, inflated by at least the circumscribed radius + clearance).
    Outside the grid is free. A snapshot, so that scans arriving during a plan do not change
    the answers halfway.
    """

    def __init__(self, grid: FreeSpaceGrid) -> None:
        occupancy = grid.map
        self._map = occupancy
        self._occupied = np.array(grid.occupied, dtype=bool)
        self._blocked = np.array(grid.blocked, dtype=bool)
        x0, y0, yaw = (float(v) for v in occupancy.origin)
        self._origin = np.array([x0, y0])
        c, s = math.cos(yaw), math.sin(yaw)
        self._rotation = np.array([[c, -s], [s, c]])  # world offset @ R = grid coordinates
        self._res = float(occupancy.resolution)
        self._half_diagonal = self._res * math.sqrt(0.5)

    def _to_grid(self, points: np.ndarray) -> np.ndarray:
        """Return map-frame points in the grid's frame (metres from its lower-left corner)."""
        return (points - self._origin) @ self._rotation

    def _cells_near(self, low: np.ndarray, high: np.ndarray,
                    margin: float) -> tuple[np.ndarray, np.ndarray]:
        """Return (flat indices, (Q, 2) centres in the grid frame) of occupied cells near a box.

        The box [low, high] (grid frame) grown by margin; only cells inside the grid.
        """
        height, width = self._occupied.shape
        c0 = max(int(math.floor((low[0] - margin) / self._res)), 0)
        c1 = min(int(math.floor((high[0] + margin) / self._res)) + 1, width)
        r0 = max(int(math.floor((low[1] - margin) / self._res)), 0)
        r1 = min(int(math.floor((high[1] + margin) / self._res)) + 1, height)
        if c0 >= c1 or r0 >= r1:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 2))
        rows, cols = np.nonzero(self._occupied[r0:r1, c0:c1])
        rows, cols = rows + r0, cols + c0
        centres = np.column_stack([cols + 0.5, rows + 0.5]) * self._res
        return rows * width + cols, centres

    def any_near(self, low: np.ndarray, high: np.ndarray, grow: float) -> bool:
        """Say whether an occupied cell may be within grow of the box [low, high] (map frame)."""
        corners = self._to_grid(np.array([low, [high[0], low[1]], high, [low[0], high[1]]]))
        cells, _ = self._cells_near(corners.min(axis=0), corners.max(axis=0),
                                    grow + self._half_diagonal)
        return len(cells) > 0

    def polygons_hit(self, polygons: np.ndarray, grow: float) -> np.ndarray:
        """Return, per (T, M, 2) polygon, the first occupied cell (flat index) near it, or -1."""
        hits = np.full(len(polygons), -1, dtype=np.int64)
        local = self._to_grid(polygons)
        margin = grow + self._half_diagonal
        cells, centres = self._cells_near(local.min(axis=(0, 1)), local.max(axis=(0, 1)),
                                          margin)
        if not len(cells):
            return hits
        normals = _outward_normals(local)
        own = np.einsum('tmk,tmk->tm', normals, local)  # each edge's support (convex)
        outside = np.max(np.einsum('tmk,qk->tqm', normals, centres) - own[:, None], axis=2)
        hit = outside <= 0.0  # a centre inside the polygon
        close = ~hit & (outside <= margin)
        if np.any(close):
            distance = _edge_distances(centres[None], local, np.roll(local, -1, axis=1))
            hit |= close & (distance.min(axis=2) <= margin)
        found = hit.any(axis=1)
        hits[found] = cells[np.argmax(hit[found], axis=1)]
        return hits

    def disc_hit(self, xy: np.ndarray, radius: float) -> int:
        """Return the first occupied cell whose centre is within radius + half a diagonal."""
        local = self._to_grid(xy)
        margin = radius + self._half_diagonal
        cells, centres = self._cells_near(local, local, margin)
        hit = np.hypot(*(centres - local).T) <= margin
        return int(cells[np.argmax(hit)]) if hit.any() else -1

    def state_free(self, xy: np.ndarray, radius: float) -> bool:
        """Say whether xy's cell is free in the inflated layer (radius: the grid's own)."""
        rows, cols = self._map.world_to_cell(xy)
        if not self._map.contains_cell(rows, cols):
            return True
        return not bool(self._blocked[rows, cols])

    def describe(self, index: int) -> str:
        """Name the cell `polygons_hit` or `disc_hit` found."""
        row, col = divmod(int(index), self._occupied.shape[1])
        return f'the occupied cell (row {row}, column {col})'


# HeldObstacles numbers the held pieces from here on, past any grid cell's flat index.
_HELD_BASE = 1 << 48


class HeldObstacles:
    """The planner's obstacles and the pieces a local controller holds, each at its clearance.

    The planner's (a grid's cells or polygons) answer as they are; the held convex pieces
    (the MPC's, as sensed) answer every query with the distance asked for less ``offset``
    (the planner's clearance less theirs; never below touching): so one `FootprintChecks`
    keeps the planner's clearance from its own obstacles and a smaller one from the pieces.
    A hit on a piece is numbered _HELD_BASE + its index.
    """

    def __init__(self, planner: PolygonObstacles | GridObstacles, held: PolygonObstacles,
                 offset: float) -> None:
        self.planner = planner
        self.held = held
        self.offset = float(offset)

    def _grow(self, grow: float) -> float:
        return max(grow - self.offset, 0.0)

    def any_near(self, low: np.ndarray, high: np.ndarray, grow: float) -> bool:
        """Say whether either may be within grow of the box [low, high]."""
        return (self.planner.any_near(low, high, grow)
                or self.held.any_near(low, high, self._grow(grow)))

    def polygons_hit(self, polygons: np.ndarray, grow: float) -> np.ndarray:
        """Return, per polygon, the first obstacle or piece it meets (-1: none)."""
        hits = self.planner.polygons_hit(polygons, grow)
        rest = np.flatnonzero(hits < 0)
        if len(rest):
            held = self.held.polygons_hit(polygons[rest], self._grow(grow))
            hits[rest] = np.where(held >= 0, held + _HELD_BASE, -1)
        return hits

    def disc_hit(self, xy: np.ndarray, radius: float) -> int:
        """Return the first obstacle or piece within radius of xy, or -1."""
        hit = self.planner.disc_hit(xy, radius)
        if hit >= 0:
            return hit
        held = self.held.disc_hit(xy, self._grow(radius))
        return held + _HELD_BASE if held >= 0 else -1

    def state_free(self, xy: np.ndarray, radius: float) -> bool:
        """Say whether the robot can turn at xy among both."""
        return (self.planner.state_free(xy, radius)
                and self.held.state_free(xy, self._grow(radius)))

    def describe(self, index: int) -> str:
        """Name what was hit."""
        if index >= _HELD_BASE:
            return (f"the local controller's obstacle {index - _HELD_BASE} (less "
                    f'{self.offset:.3g} m)')
        return self.planner.describe(index)


@dataclass(frozen=True)
class TurnRange:
    """The turns in place that are clear at a position, from a heading: [low, high] radians.

    low <= 0 <= high (clockwise, counter-clockwise); +-inf where any turn is clear. A turn
    by delta (wrapped, the short way, as a path turns) is clear iff low <= delta <= high.
    """

    low: float
    high: float
    low_hit: str = ''
    high_hit: str = ''

    def allows(self, delta: float) -> bool:
        """Say whether turning by delta radians is clear."""
        return abs(delta) <= NO_TURN or self.low <= delta <= self.high

    def why(self, delta: float) -> str:
        """Say why turning by delta is not clear (call only when `allows` says no)."""
        limit, hit = (self.high, self.high_hit) if delta > 0 else (self.low, self.low_hit)
        side = 'counter-clockwise' if delta > 0 else 'clockwise'
        return (f'the footprint meets {hit} when turned {side} by more than {abs(limit):.3g} '
                f'of the {abs(delta):.3g} rad')

    def within(self, other: TurnRange) -> TurnRange:
        """Return the turns both ranges allow (each limit with what ends it)."""
        low, low_hit = ((self.low, self.low_hit) if self.low >= other.low
                        else (other.low, other.low_hit))
        high, high_hit = ((self.high, self.high_hit) if self.high <= other.high
                          else (other.high, other.high_hit))
        return TurnRange(low=low, high=high, low_hit=low_hit, high_hit=high_hit)


class FootprintChecks:
    """The pose checks of a convex polygon footprint against one set of obstacles.

    Three queries make the planner's rules (see the module docstring): a state where the
    robot can turn to any heading (its circumscribed disc grown by the clearance is free),
    a straight motion (the swept polygon grown by the clearance), the clear turns at a
    position (sampled headings). Holds only NumPy data (no OMPL objects).
    """

    def __init__(self, footprint: Footprint, clearance: float,
                 obstacles: PolygonObstacles | GridObstacles | HeldObstacles) -> None:
        assert footprint.vertices is not None
        self.local = footprint.vertices
        self.radius = footprint.radius
        self.clearance = clearance
        self.obstacles = obstacles
        # the largest disc about the reference point inside the polygon at every heading
        offsets = np.einsum('ij,ij->i', _outward_normals(self.local), self.local)
        self.inner = float(offsets.min()) if offsets.min() > 0.0 else None
        step = min(_MAX_TURN_STEP, 2.0 * _TURN_TOLERANCE / max(self.radius, 1e-12))
        self.turn_samples = math.ceil(math.pi / step)
        self.turn_step = math.pi / self.turn_samples
        self.turn_grow = clearance + self.radius * self.turn_step / 2.0

    def state_free(self, xy: np.ndarray) -> bool:
        """Say whether the robot can turn in place at xy to any heading."""
        return self.obstacles.state_free(xy, self.radius + self.clearance)

    def pose_problem(self, xy: np.ndarray, heading: float | None) -> str | None:
        """Say why the footprint at (xy, heading) is in collision, or None if it is clear.

        Without a heading: the disc the polygon covers at every heading (necessary only).
        """
        if heading is None:
            if self.inner is None:
                return None
            hit = self.obstacles.disc_hit(xy, self.inner + self.clearance)
            if hit < 0:
                return None
            return (f'in collision: the disc of {self.inner:.3g} m the footprint covers at any '
                    f'heading meets {self.obstacles.describe(hit)} grown by the clearance '
                    f'{self.clearance:g} m')
        hit = int(self.obstacles.polygons_hit(_place(self.local, xy, np.array([heading])),
                                              self.clearance)[0])
        if hit < 0:
            return None
        return (f'in collision: the footprint at heading {heading:.3g} rad meets '
                f'{self.obstacles.describe(hit)} grown by the clearance {self.clearance:g} m')

    def sweep_hit(self, a: np.ndarray, b: np.ndarray) -> int:
        """Return what the footprint driven straight from a to b meets (-1: nothing)."""
        d = b - a
        c, s = d / math.hypot(d[0], d[1])  # the heading's cosine and sine
        polygon = self.local @ np.array([[c, s], [-s, c]]) + a
        low, high = polygon.min(axis=0), polygon.max(axis=0)
        if not self.obstacles.any_near(np.minimum(low, low + d), np.maximum(high, high + d),
                                       self.clearance):
            return -1  # most motions: nothing near the swept box
        return int(self.obstacles.polygons_hit(_sweep(polygon, d)[None], self.clearance)[0])

    def turn_range(self, xy: np.ndarray, heading: float) -> TurnRange:
        """Return the turns in place that are clear at xy from heading.

        Any turn where the circumscribed disc is free; otherwise the polygon at headings
        turn_step apart on both sides, each grown by turn_grow (covering the headings half a
        step either side), up to the first sample in collision.
        """
        if self.state_free(xy):
            return TurnRange(-math.inf, math.inf)
        steps = np.arange(self.turn_samples + 1) * self.turn_step
        headings = heading + np.concatenate([steps, -steps[1:]])
        hits = self.obstacles.polygons_hit(_place(self.local, xy, headings), self.turn_grow)
        sides = (hits[:self.turn_samples + 1], np.concatenate([hits[:1],
                                                               hits[self.turn_samples + 1:]]))
        limits: list[float] = []
        names: list[str] = []
        for side in sides:
            blocked = np.flatnonzero(side >= 0)
            if not len(blocked):
                limits.append(math.inf)
                names.append('')
                continue
            k = int(blocked[0])
            limits.append(max(k - 0.5, 0.0) * self.turn_step)
            names.append(self.obstacles.describe(int(side[k])) +
                         f' grown by the clearance {self.clearance:g} m')
        return TurnRange(low=-limits[1], high=limits[0], low_hit=names[1], high_hit=names[0])


class HeldChecks(FootprintChecks):
    """`FootprintChecks` against the planner's obstacles and the pieces a controller holds.

    Poses and straight motions meet either (`HeldObstacles`); the turns in place clear at
    a position are those clear of both, each found as its own checks find them (the
    planner's: anywhere where its grid's inflated layer is free; the pieces': anywhere
    where the circumscribed disc keeps their clearance from them), so that the pieces never
    make the planner's own answer stricter.

    Args:
        footprint: The robot's polygon.
        clearance: The planner's clearance.
        planner: The planner's obstacles.
        held: The pieces.
        held_clearance: The clearance kept from the pieces (may be below 0 for a start
            already that close: then its turns keep what the start has, and motions keep
            them from touching).

    """

    def __init__(self, footprint: Footprint, clearance: float,
                 planner: PolygonObstacles | GridObstacles, held: PolygonObstacles,
                 held_clearance: float) -> None:
        super().__init__(footprint, clearance,
                         HeldObstacles(planner, held, offset=clearance - held_clearance))
        self.planner_checks = FootprintChecks(footprint, clearance, planner)
        self.held_checks = FootprintChecks(footprint, held_clearance, held)

    def turn_range(self, xy: np.ndarray, heading: float) -> TurnRange:
        """Return the turns clear of the planner's obstacles and of the pieces."""
        return self.planner_checks.turn_range(xy, heading).within(
            self.held_checks.turn_range(xy, heading))


class FootprintPlan:
    """One plan's state and motion rules for a polygon footprint (OMPL's callbacks use it).

    The start and the goal were checked before (`RrtStarPlanner.check_endpoint`); the turns
    in place there are part of the motions out of the start and into the goal. Counts the
    motions refused for those turns alone, so that a failed plan can say so.
    """

    def __init__(self, checks: FootprintChecks, start: tuple[np.ndarray, float | None],
                 goal: tuple[np.ndarray, float | None]) -> None:
        self.checks = checks
        (self.start_xy, self.start_heading), (self.goal_xy, self.goal_heading) = start, goal
        self.start_turns = (None if self.start_heading is None
                            else checks.turn_range(self.start_xy, self.start_heading))
        self.goal_turns = (None if self.goal_heading is None
                           else checks.turn_range(self.goal_xy, self.goal_heading))
        self.start_turn_refusals = 0
        self.goal_turn_refusals = 0
        # RRT* asks about the same states again and again (rewiring): remember the answers
        self._turnable: dict[tuple[float, float], bool] = {}

    def _is(self, xy: np.ndarray, endpoint: np.ndarray) -> bool:
        return bool(xy[0] == endpoint[0] and xy[1] == endpoint[1])

    def _can_turn(self, xy: np.ndarray) -> bool:
        key = (float(xy[0]), float(xy[1]))
        free = self._turnable.get(key)
        if free is None:
            free = self._turnable[key] = self.checks.state_free(xy)
        return free

    def state_valid(self, xy: np.ndarray) -> bool:
        """A state: the start or goal as checked, elsewhere where the robot can turn."""
        if self._is(xy, self.start_xy) or self._is(xy, self.goal_xy):
            return True
        return self._can_turn(xy)

    def motion_valid(self, a: np.ndarray, b: np.ndarray) -> bool:
        """A straight motion a -> b, with the turns at the start and the goal it implies."""
        d = b - a
        if math.hypot(d[0], d[1]) <= SAME_POINT:
            return self.state_valid(a) and self.state_valid(b)
        heading = math.atan2(d[1], d[0])
        if self._is(a, self.start_xy):
            if (self.start_turns is not None and self.start_heading is not None
                    and not self.start_turns.allows(wrap_heading(heading - self.start_heading))):
                self.start_turn_refusals += 1
                return False
        elif not self._can_turn(a):  # a corner (OMPL's simplifier makes new ones too)
            return False
        if self._is(b, self.goal_xy):
            if (self.goal_turns is not None and self.goal_heading is not None
                    and not self.goal_turns.allows(-wrap_heading(self.goal_heading - heading))):
                self.goal_turn_refusals += 1
                return False
        elif not self._can_turn(b):
            return False
        return self.checks.sweep_hit(a, b) < 0

    def failure_hint(self) -> str:
        """Say which endpoint turns refused motions, for the message of a failed plan."""
        hints = []
        for label, turns, count in (('start', self.start_turns, self.start_turn_refusals),
                                    ('goal', self.goal_turns, self.goal_turn_refusals)):
            if turns is not None and count:
                hints.append(f'{count} motions {"out of" if label == "start" else "into"} the '
                             f'{label} were refused because the footprint cannot turn in place '
                             f'there by more than {turns.high:.3g} rad counter-clockwise or '
                             f'{-turns.low:.3g} rad clockwise of the {label} heading')
        return ('; ' + '; '.join(hints)) if hints else ''
