# SPDX-License-Identifier: Apache-2.0
"""The world's exact obstacles in arrays: ray casting and distances, vectorised.

Shared by the simulated laser (which casts against the true world) and the obstacle memory
(which casts the current beams against what it remembers, to clear what they pass through).

Every obstacle is bounded by a disk; a disk beyond the range of interest is dropped, and each
remaining disk is paired only with the beams whose angles fall inside the cone it subtends
from the origin. The exact intersection (analytic for disks, per edge for polygons) is then
one NumPy expression over those (beam, obstacle) pairs.
"""

from __future__ import annotations

import math
from typing import Sequence, TYPE_CHECKING

import numpy as np

from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.worlds.world import Circle

if TYPE_CHECKING:
    from mpc_local_planner.worlds.world import Shape, World

__all__ = ['TrueGeometry']

# A denominator below this counts as a beam parallel to a polygon edge (beams are unit vectors,
# edges are in metres).
_PARALLEL_TOL = 1e-12


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Wrap angles to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class TrueGeometry:
    """The exact obstacles of a world, packed in arrays for ray casting and contact checks.

    Disks are kept as centre and radius; polygons as padded edge arrays (a polygon with fewer
    faces repeats its last edge, which changes no minimum). Every obstacle also gets a bounding
    disk, so that far obstacles are dropped with one comparison.

    Args:
        shapes: Convex polygons and `Circle`s, e.g. ``world.physical_shapes()``.

    """

    def __init__(self, shapes: Sequence[Shape]) -> None:
        circles = [s for s in shapes if isinstance(s, Circle)]
        polygons = [s for s in shapes if isinstance(s, ConvexPolygon)]
        if len(circles) + len(polygons) != len(shapes):
            kinds = sorted({type(s).__name__ for s in shapes} - {'Circle', 'ConvexPolygon'})
            msg = f'shapes must be ConvexPolygon or Circle, got {kinds}'
            raise TypeError(msg)
        self.circles = np.array([tuple(c) for c in circles], dtype=float).reshape(-1, 3)
        self.polygons: list[ConvexPolygon] = polygons
        self._pack_polygons(polygons)
        self._num_circles = len(self.circles)

    def _pack_polygons(self, polygons: list[ConvexPolygon]) -> None:
        """Pack the polygons' edges, faces and bounding disks into padded arrays.

        Vectorised over all polygons at once: the obstacle memory builds a geometry of what
        it remembers at every scan (a Python loop per polygon: docs/design/measurements.md,
        TrueGeometry packing).
        """
        count = len(polygons)
        sizes = np.array([p.num_faces for p in polygons], dtype=np.int64)
        faces = int(sizes.max()) if count else 1
        if count:
            vertices = np.concatenate([p.vertices for p in polygons])
            normals = np.concatenate([p.A for p in polygons])
            offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]])
            # row r of polygon i is its face min(r, size - 1): padding repeats the last face
            local = np.minimum(np.arange(faces)[None, :], sizes[:, None] - 1)
            rows = offsets[:, None] + local
            following = offsets[:, None] + (local + 1) % sizes[:, None]
            self._starts = vertices[rows]
            self._edges = vertices[following] - vertices[rows]
            self._A = normals[rows]
            self._b = np.concatenate([p.b for p in polygons])[rows]
            centres = np.add.reduceat(vertices, offsets, axis=0) / sizes[:, None]
            spread = np.hypot(*(vertices - np.repeat(centres, sizes, axis=0)).T)
            bound = np.column_stack([centres, np.maximum.reduceat(spread, offsets)])
        else:
            self._starts = self._edges = self._A = np.zeros((0, faces, 2))
            self._b = np.zeros((0, faces))
            bound = np.zeros((0, 3))
        # Bounding disks: the circles themselves, then one per polygon.
        self._disks = np.vstack([self.circles, bound])

    def __len__(self) -> int:
        return int(len(self._disks))

    @classmethod
    def from_world(cls, world: World) -> TrueGeometry:
        """Pack everything physically present in a world (known and unknown, exact disks)."""
        return cls(world.physical_shapes())

    # ------------------------------------------------------------------ ray casting
    def cast(self, origin: Sequence[float], angle_min: float, angle_increment: float,
             beams: int, range_max: float) -> np.ndarray:
        """Return the distance along each beam to the nearest obstacle (inf where none).

        Beam k leaves origin at the world-frame angle angle_min + k * angle_increment. Hits
        beyond range_max are inf. A beam that starts inside an obstacle has range 0.

        Args:
            origin: (x, y) of the laser in the world frame.
            angle_min: World-frame angle of the first beam, radians.
            angle_increment: Angle between consecutive beams, radians (> 0).
            beams: Number of beams.
            range_max: Farthest hit that counts, metres.

        Returns:
            (beams,) ranges.

        """
        ranges = np.full(beams, np.inf)
        beam_idx, _, t = self.cast_pairs(origin, angle_min, angle_increment, beams, range_max)
        np.minimum.at(ranges, beam_idx, t)
        ranges[ranges > range_max] = np.inf
        return ranges

    def cast_pairs(self, origin: Sequence[float], angle_min: float, angle_increment: float,
                   beams: int, range_max: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return every (beam, obstacle) pair a beam may meet, with the distance of the hit.

        Obstacles are numbered circles first, then polygons, each in the given order. Only
        pairs whose obstacle's bounding cone contains the beam are listed; t is inf where the
        beam misses the obstacle itself, 0 where it starts inside.

        Args:
            origin: (x, y) of the beams' origin in the world frame.
            angle_min: World-frame angle of the first beam, radians.
            angle_increment: Angle between consecutive beams, radians (> 0).
            beams: Number of beams.
            range_max: Obstacles whose bounding disk is farther than this are skipped.

        Returns:
            (beam indices, obstacle indices, distances), three arrays of equal length.

        """
        if angle_increment < 0.0:  # a clockwise scan: cast it counter-clockwise, renumber
            last = angle_min + (beams - 1) * angle_increment
            beam_idx, disk_idx, t = self.cast_pairs(origin, last, -angle_increment, beams,
                                                    range_max)
            return beams - 1 - beam_idx, disk_idx, t
        ox, oy = float(origin[0]), float(origin[1])
        empty = np.zeros(0, dtype=np.int64)
        if not len(self._disks) or beams <= 0:
            return empty, empty, np.zeros(0)
        delta = self._disks[:, :2] - (ox, oy)
        dist = np.hypot(delta[:, 0], delta[:, 1])
        radius = self._disks[:, 2]
        near = np.flatnonzero(dist - radius <= range_max)
        if not len(near):
            return empty, empty, np.zeros(0)
        beam_idx, disk_idx = self._candidates(near, delta[near], dist[near], radius[near],
                                              angle_min, angle_increment, beams)
        theta = angle_min + beam_idx * angle_increment
        dx, dy = np.cos(theta), np.sin(theta)
        is_circle = disk_idx < self._num_circles
        t = np.full(len(beam_idx), np.inf)
        if np.any(is_circle):
            c = disk_idx[is_circle]
            t[is_circle] = self._circle_hits(ox, oy, dx[is_circle], dy[is_circle], c)
        if not np.all(is_circle):
            poly = ~is_circle
            p = disk_idx[poly] - self._num_circles
            t[poly] = self._polygon_hits(ox, oy, dx[poly], dy[poly], p)
        return beam_idx, disk_idx, t

    def _candidates(self, near: np.ndarray, delta: np.ndarray, dist: np.ndarray,
                    radius: np.ndarray, angle_min: float, increment: float,
                    beams: int) -> tuple[np.ndarray, np.ndarray]:
        """Pair each nearby bounding disk with the beams inside the cone it subtends.

        The cone is tried at its bearing and shifted by +-2 pi, so a cone across the beams'
        wrap-around is not missed; a disk around the laser gets every beam.
        """
        inside = dist <= radius
        half = np.where(inside, math.pi, np.arcsin(np.minimum(radius / np.maximum(dist, 1e-300),
                                                              1.0)))
        bearing = np.arctan2(delta[:, 1], delta[:, 0])
        centre = _wrap(bearing - angle_min - math.pi) + math.pi  # in [0, 2 pi)
        pad = 1e-9
        starts, counts, owners = [], [], []
        for shift in (-2.0 * math.pi, 0.0, 2.0 * math.pi):
            lo = np.ceil((centre + shift - half - pad) / increment).astype(np.int64)
            hi = np.floor((centre + shift + half + pad) / increment).astype(np.int64)
            lo = np.maximum(lo, 0)
            hi = np.minimum(hi, beams - 1)
            count = hi - lo + 1
            keep = count > 0
            starts.append(lo[keep])
            counts.append(count[keep])
            owners.append(near[keep])
        start = np.concatenate(starts)
        count = np.concatenate(counts)
        owner = np.concatenate(owners)
        total = int(count.sum())
        offsets = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
        return np.repeat(start, count) + offsets, np.repeat(owner, count)

    def _circle_hits(self, ox: float, oy: float, dx: np.ndarray, dy: np.ndarray,
                     index: np.ndarray) -> np.ndarray:
        """Return the first t >= 0 where o + t d meets each disk (inf if never, 0 inside)."""
        fx = ox - self.circles[index, 0]
        fy = oy - self.circles[index, 1]
        r = self.circles[index, 2]
        proj = fx * dx + fy * dy
        c = fx * fx + fy * fy - r * r
        disc = proj * proj - c
        with np.errstate(invalid='ignore'):
            t = -proj - np.sqrt(disc)
        hit = (disc >= 0.0) & (t >= 0.0)
        return np.where(c <= 0.0, 0.0, np.where(hit, t, np.inf))

    def _polygon_hits(self, ox: float, oy: float, dx: np.ndarray, dy: np.ndarray,
                      index: np.ndarray) -> np.ndarray:
        """Return the first t >= 0 where o + t d meets each polygon's edges (0 inside)."""
        sx = self._starts[index, :, 0] - ox  # (Q, F)
        sy = self._starts[index, :, 1] - oy
        ex = self._edges[index, :, 0]
        ey = self._edges[index, :, 1]
        dxq, dyq = dx[:, None], dy[:, None]
        denom = dxq * ey - dyq * ex
        ok = np.abs(denom) > _PARALLEL_TOL
        safe = np.where(ok, denom, 1.0)
        t = (sx * ey - sy * ex) / safe
        u = (sx * dyq - sy * dxq) / safe
        valid = ok & (t >= 0.0) & (u >= 0.0) & (u <= 1.0)
        first = np.min(np.where(valid, t, np.inf), axis=1)
        slack = self._b[index] - (self._A[index, :, 0] * ox + self._A[index, :, 1] * oy)
        return np.where(np.all(slack >= 0.0, axis=1), 0.0, first)

    # ------------------------------------------------------------------ distances
    def distance(self, point: Sequence[float], *, within: float = math.inf) -> float:
        """Return the Euclidean distance from point to the nearest obstacle (0 inside).

        Exact for disks and convex polygons (distance to the nearest edge segment, 0 when all
        faces hold). Obstacles whose bounding disk is farther than within are skipped: the
        answer is then only exact when it is <= within (else some value > within, or inf).

        Args:
            point: (x, y) in the world frame.
            within: Distance beyond which the caller does not care (speeds up the search).

        Returns:
            The distance, inf if there are no obstacles (within range).

        """
        px, py = float(point[0]), float(point[1])
        if not len(self._disks):
            return math.inf
        gap = np.hypot(self._disks[:, 0] - px, self._disks[:, 1] - py) - self._disks[:, 2]
        near = np.flatnonzero(gap <= within)
        best = math.inf
        circles = near[near < self._num_circles]
        if len(circles):
            best = float(np.max([0.0, np.min(gap[circles])]))
        polys = near[near >= self._num_circles] - self._num_circles
        if len(polys):
            rx = px - self._starts[polys, :, 0]
            ry = py - self._starts[polys, :, 1]
            ex = self._edges[polys, :, 0]
            ey = self._edges[polys, :, 1]
            length2 = np.maximum(ex * ex + ey * ey, 1e-300)
            u = np.clip((rx * ex + ry * ey) / length2, 0.0, 1.0)
            edge_dist = np.min(np.hypot(rx - u * ex, ry - u * ey), axis=1)
            slack = self._b[polys] - (self._A[polys, :, 0] * px + self._A[polys, :, 1] * py)
            edge_dist = np.where(np.all(slack >= 0.0, axis=1), 0.0, edge_dist)
            best = min(best, float(np.min(edge_dist)))
        return best
