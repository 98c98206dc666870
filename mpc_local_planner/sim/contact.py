# SPDX-License-Identifier: Apache-2.0
"""Contacts and clearances of the robot's TRUE footprint with the world's exact obstacles.

Like the simulated laser (sim/laser.py), these answer questions about the *true* world
(known and unknown obstacles, disks as disks), not about what the robot believes: a contact
is what the evaluation counts against the controller.

Contacts and clearances use the robot's TRUE footprint (`Footprint`): a disk, or a convex
polygon at the pose (x, y, theta). A Jackal's rectangle passes gaps its circumscribed circle
cannot, and hits things its inscribed circle would miss, so neither disk may stand in for it
when the score is "no contact". Polygon against convex polygon is exact by separating axes
(the edge normals of both polygons), polygon against disk by the signed distance from the
disk's centre to the polygon; both are one NumPy expression over the (pose, obstacle) pairs
whose bounding disks can meet, so the simulator's check every tick stays cheap in a BARN
world with hundreds of cylinders.
"""

from __future__ import annotations

import math
from typing import NamedTuple
import weakref

import numpy as np

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.perception.raycast import TrueGeometry

__all__ = ['contact', 'footprint_distances']

# Slack (m) on the bounding-disk tests that pick the (pose, obstacle) pairs to examine, so
# that rounding never drops a pair that exactly touches.
_BOUND_SLACK = 1e-9
# Poses per block when distances are computed for a whole trajectory (bounds the memory of
# the (poses, obstacles) bounding-disk matrix).
_POSE_BLOCK = 512


def contact(geometry: TrueGeometry, x: float, y: float, robot: float | Footprint,
            theta: float = 0.0) -> bool:
    """Say whether the robot at pose (x, y, theta) touches any obstacle.

    Touching counts (distance <= 0): the simulator counts contacts, and a robot that grazes a
    cylinder has hit it. Only obstacles whose bounding disk meets the robot's are examined,
    so the cost does not grow with the size of the world.

    Args:
        geometry: The world's exact obstacles (`TrueGeometry.from_world`).
        x: Robot origin x in the world frame.
        y: Robot origin y.
        robot: The robot's footprint, or the radius (m, >= 0) of a round robot.
        theta: Heading (rad); only a polygon footprint cares.

    Returns:
        True if the footprint meets an obstacle.

    Raises:
        ValueError: If the radius is negative or the pose is not finite.

    """
    radius = robot.radius if isinstance(robot, Footprint) else robot
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(radius)
            and math.isfinite(theta)) or radius < 0:
        msg = (f'contact needs a finite pose and radius >= 0, got ({x}, {y}, {theta}), '
               f'r={radius}')
        raise ValueError(msg)
    if not isinstance(robot, Footprint) or robot.is_circle:
        return geometry.distance((x, y), within=radius) <= radius
    packed = _packed(geometry)
    pose = np.array([[x, y, theta]])
    frame = _Frame.at(robot, pose)
    near = _near(packed, pose[:, :2], robot.radius)
    circles = near[near < packed.num_circles]
    if len(circles):
        gap = _point_signed_distance(frame, np.zeros(len(circles), dtype=np.int64),
                                     packed.disks[circles, :2]) - packed.disks[circles, 2]
        if np.any(gap <= 0.0):
            return True
    polygons = near[near >= packed.num_circles] - packed.num_circles
    if len(polygons):
        zeros = np.zeros(len(polygons), dtype=np.int64)
        return bool(np.any(_separation(frame, zeros, packed, polygons) <= 0.0))
    return False


def footprint_distances(geometry: TrueGeometry, footprint: Footprint,
                        poses: np.ndarray) -> np.ndarray:
    """Return, per pose, the signed distance from the footprint to the nearest obstacle.

    Positive: the clearance (exact Euclidean distance between the shapes); zero: touching;
    negative: minus the penetration depth (the shortest translation that separates them).
    One definition for disks and polygons, so a clearance measured with the Jackal's
    rectangle compares with one measured with its circle.

    Args:
        geometry: The world's exact obstacles.
        footprint: The robot's shape.
        poses: (n, 3) poses x, y, theta (a circle footprint also accepts (n, 2) points).

    Returns:
        (n,) signed distances, inf where the world has no obstacle.

    Raises:
        ValueError: If poses are not finite, or a polygon footprint gets no headings.

    """
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    if poses.ndim == 2 and poses.shape[1] == 2 and footprint.is_circle:
        poses = np.column_stack([poses, np.zeros(len(poses))])
    if poses.ndim != 2 or poses.shape[1] < 3:
        msg = f'poses must be (n, 3) [x, y, theta], got shape {poses.shape}'
        raise ValueError(msg)
    poses = poses[:, :3]
    if not np.all(np.isfinite(poses)):
        msg = 'poses must be finite'
        raise ValueError(msg)
    packed = _packed(geometry)
    result = np.full(len(poses), np.inf)
    if not len(packed.disks):
        return result
    for first in range(0, len(poses), _POSE_BLOCK):
        block = poses[first:first + _POSE_BLOCK]
        result[first:first + _POSE_BLOCK] = _block_distances(packed, footprint, block)
    return result


class _Packed(NamedTuple):
    """The world's obstacles as arrays for the footprint checks (built once per geometry).

    Polygons are padded to the largest number of faces by repeating their last vertex and
    face, which changes no minimum or maximum below.
    """

    disks: np.ndarray  # (C + M, 3) bounding disks: the circles themselves, then the polygons
    num_circles: int
    starts: np.ndarray  # (M, F, 2) vertices, counter-clockwise
    edges: np.ndarray  # (M, F, 2) from each vertex to the next
    normals: np.ndarray  # (M, F, 2) outward unit normals
    offsets: np.ndarray  # (M, F): normals . p <= offsets inside


# One packing per TrueGeometry, dropped with it: the simulator checks every tick.
_PACKINGS: weakref.WeakKeyDictionary[TrueGeometry, _Packed] = weakref.WeakKeyDictionary()


def _packed(geometry: TrueGeometry) -> _Packed:
    """Return the arrays of geometry's obstacles, built on first use."""
    packed = _PACKINGS.get(geometry)
    if packed is not None:
        return packed
    polygons = geometry.polygons
    faces = max((p.num_faces for p in polygons), default=1)
    starts = np.zeros((len(polygons), faces, 2))
    edges = np.zeros((len(polygons), faces, 2))
    normals = np.zeros((len(polygons), faces, 2))
    offsets = np.zeros((len(polygons), faces))
    bounds = np.zeros((len(polygons), 3))
    for i, polygon in enumerate(polygons):
        rows = np.minimum(np.arange(faces), polygon.num_faces - 1)
        vertices = polygon.vertices
        starts[i] = vertices[rows]
        edges[i] = np.roll(vertices, -1, axis=0)[rows] - vertices[rows]
        normals[i], offsets[i] = polygon.A[rows], polygon.b[rows]
        centre = vertices.mean(axis=0)
        bounds[i] = (*centre, np.max(np.linalg.norm(vertices - centre, axis=1)))
    circles = np.asarray(geometry.circles, dtype=float).reshape(-1, 3)
    packed = _Packed(disks=np.vstack([circles, bounds]), num_circles=len(circles),
                     starts=starts, edges=edges, normals=normals, offsets=offsets)
    _PACKINGS[geometry] = packed
    return packed


class _Frame(NamedTuple):
    """A footprint placed at poses: its vertices, edges and faces in the world frame.

    For a circle footprint (no vertices) only ``centres`` and ``radius`` are meaningful.
    """

    centres: np.ndarray  # (P, 2) robot origins
    radius: float  # circle footprint: its radius (0 for a polygon)
    vertices: np.ndarray  # (P, K, 2)
    edges: np.ndarray  # (P, K, 2)
    normals: np.ndarray  # (P, K, 2) outward unit normals
    offsets: np.ndarray  # (P, K)

    @classmethod
    def at(cls, footprint: Footprint, poses: np.ndarray) -> _Frame:
        """Place the footprint at each pose (x, y, theta)."""
        centres = poses[:, :2]
        if footprint.vertices is None:
            empty = np.zeros((len(poses), 0, 2))
            return cls(centres, footprint.radius, empty, empty, empty, empty[..., 0])
        local = footprint.vertices
        local_edges = np.roll(local, -1, axis=0) - local
        local_normals = np.column_stack([local_edges[:, 1], -local_edges[:, 0]])
        local_normals /= np.linalg.norm(local_normals, axis=1, keepdims=True)
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        rotation = np.stack([np.stack([c, -s], axis=1), np.stack([s, c], axis=1)], axis=1)
        vertices = np.einsum('pij,kj->pki', rotation, local) + centres[:, None, :]
        edges = np.einsum('pij,kj->pki', rotation, local_edges)
        normals = np.einsum('pij,kj->pki', rotation, local_normals)
        offsets = np.einsum('pki,pki->pk', normals, vertices)
        return cls(centres, 0.0, vertices, edges, normals, offsets)


def _near(packed: _Packed, centres: np.ndarray, radius: float) -> np.ndarray:
    """Return the obstacles whose bounding disk meets the disk around one robot origin."""
    gap = np.hypot(packed.disks[:, 0] - centres[0, 0], packed.disks[:, 1] - centres[0, 1])
    return np.flatnonzero(gap - packed.disks[:, 2] <= radius + _BOUND_SLACK)


def _segment_distances(points: np.ndarray, starts: np.ndarray,
                       edges: np.ndarray) -> np.ndarray:
    """Return the distance from every point to every segment, per pair.

    Args:
        points: (Q, A, 2) points of each pair.
        starts: (Q, B, 2) segment starts of each pair.
        edges: (Q, B, 2) segment vectors.

    Returns:
        (Q,) the smallest point-to-segment distance of each pair.

    """
    rel = points[:, :, None, :] - starts[:, None, :, :]  # (Q, A, B, 2)
    length2 = np.maximum(np.einsum('qbi,qbi->qb', edges, edges), 1e-300)
    u = np.clip(np.einsum('qabi,qbi->qab', rel, edges) / length2[:, None, :], 0.0, 1.0)
    gap = rel - u[..., None] * edges[:, None, :, :]
    return np.min(np.hypot(gap[..., 0], gap[..., 1]), axis=(1, 2))


def _point_signed_distance(frame: _Frame, pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Return the signed distance from each point to the polygon footprint at its pose.

    Inside a convex polygon the largest face residual is minus the distance to the boundary
    (exact, not a bound); outside, the distance to the nearest edge.

    Args:
        frame: The footprint placed at the poses.
        pose: (Q,) index of each point's pose in frame.
        points: (Q, 2) points, e.g. the centres of circular obstacles.

    """
    residual = np.max(np.einsum('qki,qi->qk', frame.normals[pose], points)
                      - frame.offsets[pose], axis=1)
    outside = _segment_distances(points[:, None, :], frame.vertices[pose], frame.edges[pose])
    return np.where(residual <= 0.0, residual, outside)


def _separation(frame: _Frame, pose: np.ndarray, packed: _Packed,
                polygon: np.ndarray) -> np.ndarray:
    """Return the largest separation along the edge normals of both polygons, per pair.

    By the separating axis theorem, two convex polygons are disjoint iff it is > 0. When they
    overlap, it is minus the penetration depth (the shortest separating translation is along
    one of these normals); when they are apart it is only a lower bound on their distance.

    Args:
        frame: The footprint placed at the poses.
        pose: (Q,) pose index of each pair.
        packed: The obstacles.
        polygon: (Q,) polygon index of each pair (among the polygons).

    """
    vertices = frame.vertices[pose]  # (Q, K, 2)
    normals = packed.normals[polygon]  # (Q, F, 2)
    # the footprint beyond obstacle face f: min over its vertices of a_f . w - b_f
    beyond_obstacle = np.min(np.einsum('qfi,qki->qfk', normals, vertices), axis=2) \
        - packed.offsets[polygon]
    # the obstacle beyond footprint face k: min over its vertices of n_k . o - c_k
    beyond_footprint = np.min(np.einsum('qki,qfi->qkf', frame.normals[pose],
                                        packed.starts[polygon]), axis=2) - frame.offsets[pose]
    return np.maximum(np.max(beyond_obstacle, axis=1), np.max(beyond_footprint, axis=1))


def _polygon_signed_distance(frame: _Frame, pose: np.ndarray, packed: _Packed,
                             polygon: np.ndarray) -> np.ndarray:
    """Return the signed distance between the footprint and a polygon obstacle, per pair.

    Apart, the distance of two convex polygons is attained at a vertex of one of them, so the
    smallest vertex-to-edge distance both ways is exact; overlapping, the separating axes give
    minus the penetration depth.
    """
    separation = _separation(frame, pose, packed, polygon)
    apart = np.flatnonzero(separation > 0.0)
    result = separation.copy()
    if len(apart):
        p, o = pose[apart], polygon[apart]
        result[apart] = np.minimum(
            _segment_distances(frame.vertices[p], packed.starts[o], packed.edges[o]),
            _segment_distances(packed.starts[o], frame.vertices[p], frame.edges[p]))
    return result


def _block_distances(packed: _Packed, footprint: Footprint, poses: np.ndarray) -> np.ndarray:
    """Return `footprint_distances` for a block of poses (the world has obstacles).

    Only pairs that can be the nearest are examined: with bounding disks of radii R_f (the
    footprint, about the robot origin) and R_m (obstacle m) at centre distance D, the signed
    distance lies in [D - R_f - R_m, D + R_f + R_m] (the lower end only when apart), so an
    obstacle whose lower end exceeds some other's upper end cannot be the nearest.
    """
    frame = _Frame.at(footprint, poses)
    disks = packed.disks
    centre_gap = np.hypot(poses[:, None, 0] - disks[None, :, 0],
                          poses[:, None, 1] - disks[None, :, 1])  # (P, N)
    reach = footprint.radius + disks[None, :, 2]
    best = np.min(centre_gap + reach, axis=1)
    pose, obstacle = np.nonzero(centre_gap - reach <= best[:, None] + _BOUND_SLACK)
    distance = np.empty(len(pose))
    is_circle = obstacle < packed.num_circles
    c, pc = obstacle[is_circle], pose[is_circle]
    if footprint.is_circle:
        distance[is_circle] = centre_gap[pc, c] - disks[c, 2] - footprint.radius
    else:
        distance[is_circle] = _point_signed_distance(frame, pc, disks[c, :2]) - disks[c, 2]
    pp = pose[~is_circle]
    m = obstacle[~is_circle] - packed.num_circles
    if len(m):
        if footprint.is_circle:
            distance[~is_circle] = _circle_polygon_signed_distance(
                packed, poses[pp, :2], m) - footprint.radius
        else:
            distance[~is_circle] = _polygon_signed_distance(frame, pp, packed, m)
    result = np.full(len(poses), np.inf)
    np.minimum.at(result, pose, distance)
    return result


def _circle_polygon_signed_distance(packed: _Packed, points: np.ndarray,
                                    polygon: np.ndarray) -> np.ndarray:
    """Return the signed distance from each point to its polygon obstacle (minus inside)."""
    residual = np.max(np.einsum('qfi,qi->qf', packed.normals[polygon], points)
                      - packed.offsets[polygon], axis=1)
    outside = _segment_distances(points[:, None, :], packed.starts[polygon],
                                 packed.edges[polygon])
    return np.where(residual <= 0.0, residual, outside)
