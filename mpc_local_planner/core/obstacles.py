# SPDX-License-Identifier: Apache-2.0
"""Convex polygonal obstacles in H-representation {p : A p <= b}.

The MPC needs obstacles as linear inequalities (Farkas' lemma turns "outside" into a
linear condition on a multiplier vector); the planner and the checks need point queries.
Rows of A are kept at unit norm so that A p - b is the signed distance of p to each face's
line: inflation and margins are then in metres.

Polygons against polygons (a robot's footprint at many poses against many obstacles) have one
exact, vectorised signed distance here (`polygon_separation`): what verifies a plan of a
robot with a polygonal footprint, and the direction from which the MPC's warm-start
multipliers are built (`face_weights`).

Segments against polygons have one clipper here (`ObstacleSet.segment_hits`, Cyrus-Beck,
vectorised over segments and obstacles); its `grazing` argument says whether a segment that
only touches a boundary counts. The planner counts it (its tree edges must keep the full
clearance); the controller's plan check does not (a plan at exactly the clearance is valid).

`within_faces` fits sensed polygons to the MPC's face slots (``faces_per_obstacle``) and
replaces needle-sharp ones by their enclosing rectangle before the MPC grows them.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np
from scipy.spatial import ConvexHull, QhullError

__all__ = [
    'ConvexPolygon',
    'ObstacleSet',
    'convex_hull',
    'face_weights',
    'first_blocked_segment',
    'GRAZE_TOLERANCE',
    'min_clearance',
    'nearest_within',
    'polygon_separation',
    'segment_collides',
    'SHARP_CORNER',
    'within_faces',
]

# With grazing=False, obstacles are shrunk by this much (metres) before clipping, so that a
# segment along a face or through a corner does not count as a hit.
GRAZE_TOLERANCE = 1e-9
# |a . d| below this counts as a segment parallel to a face (d is in metres).
_PARALLEL_TOL = 1e-12


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Return the convex hull of 2-D points, counter-clockwise, without repeated points.

    SciPy's Qhull, with the vertices starting at the lexicographically smallest one (so the
    faces of a polygon come in the same order whatever order its vertices were given in).

    Raises:
        ValueError: with fewer than 3 distinct points, or points on one line.

    """
    pts = np.unique(np.asarray(points, dtype=float).reshape(-1, 2), axis=0)
    if len(pts) < 3:
        msg = f'a polygon needs at least 3 distinct vertices, got {len(pts)}'
        raise ValueError(msg)
    if not np.all(np.isfinite(pts)):
        msg = 'polygon vertices must be finite'
        raise ValueError(msg)
    try:
        order = ConvexHull(pts).vertices  # counter-clockwise in 2-D
    except QhullError:
        msg = 'the vertices are collinear: a polygon needs a non-empty interior'
        raise ValueError(msg) from None
    first = int(np.argmin(order))  # pts is sorted: the smallest index is the smallest point
    return pts[np.roll(order, -first)]


@dataclass(frozen=True)
class ConvexPolygon:
    """A convex polygon {p : A p <= b} with unit-norm rows of A, and its vertices.

    Attributes:
        A: (m, 2) outward unit normals, one per face.
        b: (m,) offsets, so that A p - b is the signed distance to each face's line.
        vertices: (m, 2) counter-clockwise vertices (for plots and clearance queries).

    """

    A: np.ndarray
    b: np.ndarray
    vertices: np.ndarray

    @classmethod
    def from_vertices(cls, vertices: Sequence[Sequence[float]] | np.ndarray) -> ConvexPolygon:
        """Build the polygon from its vertices (any order; the convex hull is taken)."""
        return cls._from_hull(convex_hull(np.asarray(vertices, dtype=float)))

    @classmethod
    def _from_hull(cls, hull: np.ndarray) -> ConvexPolygon:
        """Build the polygon from hull vertices as convex_hull returns them (CCW, smallest first).

        The shapes whose hull is known (a box, a regular polygon) come here without Qhull,
        which costs far more than the rest (every remembered rectangle and octagon is built
        again at every step of the suites and the node).

        Raises:
            ValueError: if a vertex is not finite.

        """
        if not np.all(np.isfinite(hull)):
            msg = 'polygon vertices must be finite'
            raise ValueError(msg)
        edges = np.roll(hull, -1, axis=0) - hull
        normals = np.column_stack([edges[:, 1], -edges[:, 0]])  # outward for CCW order
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        offsets = np.einsum('ij,ij->i', normals, hull)
        return cls(A=normals, b=offsets, vertices=hull)

    @classmethod
    def from_box(cls, xmin: float, ymin: float, xmax: float, ymax: float) -> ConvexPolygon:
        """Build an axis-aligned box from its lower-left and upper-right corners."""
        if not (xmax > xmin and ymax > ymin):
            msg = f'box needs xmin < xmax and ymin < ymax, got {(xmin, ymin, xmax, ymax)}'
            raise ValueError(msg)
        corners = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]], dtype=float)
        return cls._from_hull(corners)  # counter-clockwise from the smallest corner already

    @classmethod
    def from_circle(
        cls, cx: float, cy: float, radius: float, *, sides: int = 8
    ) -> ConvexPolygon:
        """Build the regular polygon *circumscribed* about a circle.

        Circumscribed, not inscribed: the polygon contains the whole disk, so keeping out of
        the polygon keeps out of the disk (a conservative approximation, worst excess
        radius * (1 / cos(pi / sides) - 1) at the polygon's corners).
        """
        if radius <= 0 or sides < 3:
            msg = f'circle needs radius > 0 and sides >= 3, got radius={radius}, sides={sides}'
            raise ValueError(msg)
        outer = radius / math.cos(math.pi / sides)
        angles = np.arange(sides) * 2.0 * math.pi / sides + math.pi / sides
        pts = np.column_stack([cx + outer * np.cos(angles), cy + outer * np.sin(angles)])
        # counter-clockwise by construction; start at the lexicographically smallest vertex,
        # as convex_hull does
        first = int(np.lexsort((pts[:, 1], pts[:, 0]))[0])
        return cls._from_hull(np.roll(pts, -first, axis=0))

    @property
    def num_faces(self) -> int:
        """Number of half-planes (the size of the Farkas multiplier vector)."""
        return int(self.A.shape[0])

    def inflate(self, distance: float) -> ConvexPolygon:
        """Shift every face outwards by distance (metres).

        The result contains the Minkowski sum of the polygon and a disk of that radius (its
        corners reach further than the rounded sum would): a conservative inflation.
        """
        if distance < 0:
            msg = f'inflation distance must be >= 0, got {distance}'
            raise ValueError(msg)
        if distance == 0:
            return self
        b = self.b + distance
        n = self.num_faces
        vertices = np.empty_like(self.vertices)
        # vertex i lies on faces i-1 and i (face i runs from vertex i to vertex i+1)
        for i in range(n):
            rows = np.vstack([self.A[i - 1], self.A[i]])
            vertices[i] = np.linalg.solve(rows, np.array([b[i - 1], b[i]]))
        return ConvexPolygon(A=self.A, b=b, vertices=vertices)

    def signed_distance_lower_bound(self, points: np.ndarray) -> np.ndarray:
        """Return max_i (a_i p - b_i) per point: > 0 outside, <= 0 inside.

        Outside it is a lower bound on the Euclidean distance (exact near faces); inside it is
        minus the depth. This is the quantity the Farkas constraint bounds from below.
        """
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        return np.max(pts @ self.A.T - self.b, axis=1)

    def contains(self, points: np.ndarray, *, margin: float = 0.0) -> np.ndarray:
        """Say, per point, whether it lies in the polygon grown by margin (boundary included)."""
        return self.signed_distance_lower_bound(points) <= margin

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Return the Euclidean distance of each point to the polygon (0 inside)."""
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        starts = self.vertices
        ends = np.roll(self.vertices, -1, axis=0)
        seg = ends - starts
        rel = pts[:, None, :] - starts[None, :, :]
        t = np.clip(np.einsum('pij,ij->pi', rel, seg) / np.einsum('ij,ij->i', seg, seg), 0, 1)
        nearest = starts[None] + t[..., None] * seg[None]
        dist = np.min(np.linalg.norm(pts[:, None, :] - nearest, axis=2), axis=1)
        return np.where(self.contains(pts), 0.0, dist)


class ObstacleSet:
    """Many polygons as padded arrays, so one NumPy expression queries all of them.

    A BARN world has hundreds of obstacles and the controller asks, every step, which of them
    a prediction can reach; a Python loop over ConvexPolygon methods cost about a millisecond
    per step at 20 obstacles. Faces are padded by repeating a polygon's last face, which
    leaves max_i (a_i p - b_i) unchanged.
    """

    def __init__(self, obstacles: Sequence[ConvexPolygon]) -> None:
        self.obstacles: list[ConvexPolygon] = list(obstacles)
        count = len(self.obstacles)
        if not count:
            self._A, self._b = np.zeros((0, 1, 2)), np.full((0, 1), -np.inf)
            self._V = np.zeros((0, 1, 2))
            self._E = np.zeros((0, 1, 2))
            return
        # one gather for all polygons (a loop of small copies per polygon cost more than the
        # queries: the memory's pieces are set again at every scan)
        counts = np.fromiter((o.A.shape[0] for o in self.obstacles), dtype=np.intp, count=count)
        faces = int(counts.max())
        first = np.cumsum(counts) - counts
        # vertices padded by repeating the last one: the extra edges have zero length and the
        # last padded vertex closes the polygon to vertex 0, so every real edge is kept
        rows = first[:, None] + np.minimum(np.arange(faces)[None, :], counts[:, None] - 1)
        self._A = np.concatenate([o.A for o in self.obstacles]).astype(float, copy=False)[rows]
        self._b = np.concatenate([o.b for o in self.obstacles]).astype(float, copy=False)[rows]
        self._V = np.concatenate([o.vertices for o in self.obstacles]
                                 ).astype(float, copy=False)[rows]
        self._E = self._V[:, (np.arange(faces) + 1) % faces] - self._V  # edge f: f to f + 1

    def __len__(self) -> int:
        return len(self.obstacles)

    def subset(self, indices: np.ndarray) -> ObstacleSet:
        """Return the obstacles at indices, slicing the padded arrays (no per-polygon loop)."""
        chosen = ObstacleSet.__new__(ObstacleSet)
        chosen.obstacles = [self.obstacles[i] for i in indices]
        chosen._A, chosen._b = self._A[indices], self._b[indices]
        chosen._V, chosen._E = self._V[indices], self._E[indices]
        return chosen

    def signed_distance_lower_bound(self, points: np.ndarray) -> np.ndarray:
        """Return max_i (a_i p - b_i) as (points, obstacles): > 0 outside, <= the distance."""
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        if not self.obstacles:
            return np.zeros((len(pts), 0))
        return np.max(np.einsum('mfk,pk->pmf', self._A, pts) - self._b[None], axis=2)

    def near(self, points: np.ndarray, distance: float | np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
        """Return (indices, bounds) of the obstacles some point may be within distance of.

        Conservative: the signed-distance lower bound never exceeds the Euclidean distance,
        so no obstacle within distance is left out (a few beyond it, near corners, may be in).
        Sorted by the bound, nearest first. distance: one for all, or (K,) one per obstacle.
        """
        bound = np.min(self.signed_distance_lower_bound(points), axis=0, initial=np.inf)
        chosen = nearest_within(bound, distance)
        return chosen, bound[chosen]

    def first_containing(self, point: np.ndarray) -> int | None:
        """Return the index of the first obstacle containing point (boundary included)."""
        inside = np.flatnonzero(self.signed_distance_lower_bound(point)[0] <= 0.0)
        return int(inside[0]) if len(inside) else None

    def segment_hits(self, starts: np.ndarray, ends: np.ndarray, *,
                     grazing: bool) -> np.ndarray:
        """Say, per segment and obstacle, whether the closed segment meets the obstacle.

        Cyrus-Beck clipping, exact for convex polygons (no sampling): the point a + t (b - a)
        is in {A p <= b} iff every face i has rate_i t <= slack_i, with
        rate_i = a_i . (b - a) and slack_i = b_i - a_i . a; each face bounds t from one side
        (a face parallel to the segment either excludes it or says nothing), and the segment
        meets the polygon iff the interval left of [0, 1] is not empty.

        Args:
            starts: (S, 2) segment starts (further columns are ignored); (2,) for one.
            ends: (S, 2) segment ends; a zero-length segment is a point test.
            grazing: True: a segment that only touches an obstacle's boundary (along a
                face, or through a corner) hits it, matching `ConvexPolygon.contains`.
                False: it does not (obstacles are shrunk by GRAZE_TOLERANCE first).

        Returns:
            (S, K) booleans, K the number of obstacles.

        """
        a = np.atleast_2d(np.asarray(starts, dtype=float))[:, :2]
        d = np.atleast_2d(np.asarray(ends, dtype=float))[:, :2] - a
        offsets = self._b if grazing else self._b - GRAZE_TOLERANCE
        slack = offsets[None] - np.einsum('kfj,sj->skf', self._A, a)  # (S, K, F)
        rate = np.einsum('kfj,sj->skf', self._A, d)
        parallel = np.abs(rate) < _PARALLEL_TOL
        ratio = slack / np.where(parallel, 1.0, rate)
        enter = np.where(parallel, np.where(slack < 0, np.inf, -np.inf),
                         np.where(rate < 0, ratio, -np.inf))
        leave = np.where(parallel | (rate < 0), np.inf, ratio)
        t_enter = np.maximum(np.max(enter, axis=2, initial=-np.inf), 0.0)
        t_leave = np.minimum(np.min(leave, axis=2, initial=np.inf), 1.0)
        return t_enter <= t_leave


def nearest_within(bound: np.ndarray, distance: float | np.ndarray) -> np.ndarray:
    """Return the indices whose bound is at most distance, smallest bound first (stable)."""
    chosen = np.flatnonzero(bound <= distance)
    return chosen[np.argsort(bound[chosen], kind='stable')]


def segment_collides(obstacles: Sequence[ConvexPolygon] | ObstacleSet, a: Sequence[float],
                     b: Sequence[float], *, grazing: bool = True) -> bool:
    """Say whether the closed segment from a to b meets any of the obstacles.

    Args:
        obstacles: convex polygons, already inflated as the caller needs.
        a: segment start (x, y); further entries are ignored.
        b: segment end (x, y); further entries are ignored.
        grazing: whether touching a boundary counts (see `ObstacleSet.segment_hits`).

    """
    stack = obstacles if isinstance(obstacles, ObstacleSet) else ObstacleSet(obstacles)
    return bool(np.any(stack.segment_hits(np.asarray(a, dtype=float)[:2],
                                          np.asarray(b, dtype=float)[:2], grazing=grazing)))


def first_blocked_segment(obstacles: Sequence[ConvexPolygon], points: np.ndarray, *,
                          grazing: bool = False) -> tuple[int, int] | None:
    """Return (obstacle, segment) of the first polyline segment that meets an obstacle.

    The first obstacle (in the given order) that any segment meets, and the first such
    segment. By default grazing does not count, so that a plan at exactly the clearance
    passes.

    Args:
        obstacles: convex polygons, already grown as the caller needs.
        points: (M, 2) polyline vertices (further columns are ignored).
        grazing: whether touching a boundary counts (see `ObstacleSet.segment_hits`).

    Returns:
        None if every segment is clear (or there are fewer than two points).

    """
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    if len(pts) < 2 or not obstacles:
        return None
    hits = ObstacleSet(obstacles).segment_hits(pts[:-1], pts[1:], grazing=grazing)  # (S, K)
    blocked = np.flatnonzero(np.any(hits, axis=0))
    if not len(blocked):
        return None
    k = int(blocked[0])
    return k, int(np.flatnonzero(hits[:, k])[0])


def min_clearance(obstacles: Sequence[ConvexPolygon], points: np.ndarray) -> float:
    """Return the smallest Euclidean distance from any point to any obstacle (inf if none)."""
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    if not obstacles or len(pts) == 0:
        return math.inf
    return float(min(np.min(obstacle.distance(pts)) for obstacle in obstacles))


# Squared edge length below which an edge counts as a point (padded, repeated vertices).
_POINT_EDGE = 1e-24
# Distance below which two polygons count as touching: the direction is then taken from the
# separating axis, not from the (vanishing) vector between the closest points.
_TOUCH_DISTANCE = 1e-12


def polygon_separation(polygons: np.ndarray, obstacles: ObstacleSet
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Return the exact signed distance of each polygon to each obstacle, and its direction.

    Disjoint convex polygons: the closest pair of points always has a vertex of one of them,
    so the distance is the least vertex-to-edge distance, both ways. Overlapping ones: the
    separating-axis theorem; for polygons the shortest separating translation is along a face
    normal of one of them (the Minkowski difference's faces are theirs), so minus the
    penetration depth is the largest separation along those normals. Both cases are one
    NumPy expression over polygons, obstacles, vertices and faces (no Python loop), because
    the MPC asks this for every predicted pose against every reachable obstacle, several
    times per control step.

    Args:
        polygons: (M, V, 2) counter-clockwise vertices of M convex polygons (a robot's
            footprint at M poses); (V, 2) for one.
        obstacles: K convex obstacles.

    Returns:
        (M, K) signed distances: the Euclidean distance between the sets when disjoint,
        minus the penetration depth when they overlap (0 when touching); and (M, K, 2) unit
        directions w from the obstacle towards the polygon with
        min_{q in polygon} w.q - max_{o in obstacle} w.o equal to that signed distance (the
        closest-point direction when disjoint, the separating axis otherwise).

    """
    P = np.asarray(polygons, dtype=float)
    if P.ndim == 2:
        P = P[None]
    m_count, k_count, v_count = P.shape[0], len(obstacles), P.shape[1]
    if m_count == 0 or k_count == 0:
        return np.zeros((m_count, k_count)), np.zeros((m_count, k_count, 2))
    # x and y as separate (M, K, V, F) arrays (polygons, obstacles, polygon vertices,
    # obstacle faces): einsum on these small shapes cost several times more
    px, py = P[:, None, :, None, 0], P[:, None, :, None, 1]
    Q, E = obstacles._V, obstacles._E
    qx, qy = Q[None, :, None, :, 0], Q[None, :, None, :, 1]
    edges = P[:, (np.arange(v_count) + 1) % v_count] - P  # (M, V, 2): vertex v to v + 1
    ex, ey = edges[:, None, :, None, 0], edges[:, None, :, None, 1]
    length = np.sqrt(ex * ex + ey * ey)
    nx, ny = ey / length, -ex / length  # outward normals (counter-clockwise)

    # separating axes: how far the polygon lies beyond each obstacle face (min over its
    # vertices), and the obstacle beyond each polygon face (the direction from the obstacle
    # to the polygon is then -n)
    ax, ay = obstacles._A[None, :, None, :, 0], obstacles._A[None, :, None, :, 1]
    beyond_obstacle = np.min(ax * px + ay * py, axis=2) - obstacles._b[None]  # (M, K, F)
    beyond_polygon = np.min(nx * (qx - px) + ny * (qy - py), axis=3)  # (M, K, V)
    f_best = np.argmax(beyond_obstacle, axis=2)
    v_best = np.argmax(beyond_polygon, axis=2)
    s_obstacle = np.max(beyond_obstacle, axis=2)
    s_polygon = np.max(beyond_polygon, axis=2)
    from_obstacle = s_obstacle >= s_polygon
    separation = np.where(from_obstacle, s_obstacle, s_polygon)
    m_index, k_index = np.arange(m_count)[:, None], np.arange(k_count)[None, :]
    axis = np.where(from_obstacle[..., None], obstacles._A[k_index, f_best],
                    -np.stack([nx[m_index, 0, v_best, 0], ny[m_index, 0, v_best, 0]], -1))

    # disjoint: polygon vertices to obstacle edges, obstacle vertices to polygon edges; each
    # gap vector points from the obstacle's point to the polygon's
    fx, fy = E[None, :, None, :, 0], E[None, :, None, :, 1]
    rx, ry = px - qx, py - qy  # (M, K, V, F): obstacle vertex f to polygon vertex v
    t = np.clip((rx * fx + ry * fy) / np.maximum(fx * fx + fy * fy, _POINT_EDGE), 0.0, 1.0)
    gx_a, gy_a = rx - t * fx, ry - t * fy
    t = np.clip(-(rx * ex + ry * ey) / np.maximum(length * length, _POINT_EDGE), 0.0, 1.0)
    gx_b, gy_b = rx + t * ex, ry + t * ey  # polygon edge v's nearest point minus vertex f
    gx = np.concatenate([gx_a, gx_b], axis=2).reshape(m_count * k_count, -1)
    gy = np.concatenate([gy_a, gy_b], axis=2).reshape(m_count * k_count, -1)
    squared = gx * gx + gy * gy
    nearest = np.argmin(squared, axis=1)
    rows = np.arange(m_count * k_count)
    gap = np.stack([gx[rows, nearest], gy[rows, nearest]], axis=-1).reshape(m_count, k_count, 2)
    distance = np.sqrt(squared[rows, nearest]).reshape(m_count, k_count)

    disjoint = separation > 0.0
    signed = np.where(disjoint, distance, separation)
    use_gap = disjoint & (distance > _TOUCH_DISTANCE)
    direction = np.where(use_gap[..., None],
                         gap / np.where(use_gap, distance, 1.0)[..., None], axis)
    return signed, direction


def face_weights(normals: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Write each direction as a nonnegative combination of at most two adjacent face normals.

    The outward normals of a convex polygon's two faces at a vertex span that vertex's normal
    cone, and the cones of all vertices cover the plane; so any direction w is
    alpha a_i + beta a_{i+1} with alpha, beta >= 0 for the vertex where the polygon's support
    point in direction w is. Those are the multipliers that make the duality bound of two
    polygons exact (see nlp_values.dual_multipliers).

    Args:
        normals: (n, 2) unit outward normals of a convex polygon, counter-clockwise (face i
            and face i + 1 meet at a vertex; face n - 1 and face 0 too).
        directions: (M, 2) directions.

    Returns:
        (M, n) nonnegative weights, at most two nonzero per row (adjacent faces), with
        weights @ normals equal to directions (up to rounding).

    """
    a = np.asarray(normals, dtype=float)
    w = np.atleast_2d(np.asarray(directions, dtype=float))
    nxt = np.roll(a, -1, axis=0)
    turn = a[:, 0] * nxt[:, 1] - a[:, 1] * nxt[:, 0]  # > 0: consecutive normals turn left
    # w = alpha a_i + beta a_{i+1}: cross(a_i, w) = beta turn_i, cross(w, a_{i+1}) = alpha turn_i
    beta = (a[None, :, 0] * w[:, None, 1] - a[None, :, 1] * w[:, None, 0]) / turn
    alpha = (w[:, None, 0] * nxt[None, :, 1] - w[:, None, 1] * nxt[None, :, 0]) / turn
    best = np.argmax(np.minimum(alpha, beta), axis=1)  # the cone w is most inside of
    rows = np.arange(len(w))
    weights = np.zeros((len(w), len(a)))
    weights[rows, best] = np.maximum(alpha[rows, best], 0.0)
    weights[rows, (best + 1) % len(a)] += np.maximum(beta[rows, best], 0.0)
    return weights


# Sensed polygons with an interior angle below this (radians) are replaced by their enclosing
# rectangle before the MPC grows them (see within_faces): growing by r moves a corner of angle
# alpha by r / sin(alpha / 2), which is 2 r at 60 degrees.
SHARP_CORNER = math.radians(60.0)


def within_faces(obstacles: Sequence[ConvexPolygon], max_faces: int) -> list[ConvexPolygon]:
    """Return the obstacles, each with at most max_faces faces and no needle-sharp corner.

    A polygon with more faces than the NLP's slots hold (a scan cluster's hull) or with a
    corner sharper than SHARP_CORNER is replaced by the smallest-area rectangle around it
    with a side along one of its edges (it contains the polygon: avoiding it avoids the
    polygon). Sharp corners matter because the MPC grows obstacles by shifting their faces:
    a corner of angle alpha moves out by r / sin(alpha / 2), so the sliver a laser makes of
    a face seen at a grazing angle (a parallelogram with 5 degree corners) grows metres long
    spikes that block a free path (docs/design/measurements.md, within_faces). The world's
    obstacles with too many faces are refused instead, with a reason, where the parameters
    are checked.
    """
    fitted = []
    for obstacle in obstacles:
        if obstacle.num_faces <= max_faces and _sharpest_corner(obstacle) >= SHARP_CORNER:
            fitted.append(obstacle)
            continue
        fitted.append(_enclosing_rectangle(obstacle))
    return fitted


def _sharpest_corner(obstacle: ConvexPolygon) -> float:
    """Return the smallest interior angle of a convex polygon, radians."""
    normals = obstacle.A
    # interior angle at the vertex between faces i-1 and i: pi minus the turn of the normal
    cosines = np.einsum('ij,ij->i', normals, np.roll(normals, 1, axis=0))
    return float(np.min(np.pi - np.arccos(np.clip(cosines, -1.0, 1.0))))


def _enclosing_rectangle(obstacle: ConvexPolygon) -> ConvexPolygon:
    """Return the smallest-area rectangle around the polygon with a side along an edge."""
    vertices = np.asarray(obstacle.vertices, dtype=float)
    edges = np.roll(vertices, -1, axis=0) - vertices
    angles = np.arctan2(edges[:, 1], edges[:, 0])
    best = None
    for angle in angles:
        c, s = math.cos(angle), math.sin(angle)
        along = vertices @ np.array([c, s])
        across = vertices @ np.array([-s, c])
        area = np.ptp(along) * np.ptp(across)
        if best is None or area < best[0]:
            best = (area, c, s, along.min(), along.max(), across.min(), across.max())
    _, c, s, a0, a1, b0, b1 = best
    u, n = np.array([c, s]), np.array([-s, c])
    corners = [a0 * u + b0 * n, a1 * u + b0 * n, a1 * u + b1 * n, a0 * u + b1 * n]
    return ConvexPolygon.from_vertices(corners)
