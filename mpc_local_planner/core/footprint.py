# SPDX-License-Identifier: Apache-2.0
"""The robot's footprint: a circle (``robot_radius``) or a convex polygon (``footprint``).

Nav2 users give a footprint as the string ``"[[x, y], [x, y], ...]"`` (the robot frame,
x forward) or a radius; both are accepted here under Nav2's names. A polygon must be convex
with a non-empty interior: the exact separation of two convex polygons is what the MPC's
hard constraint is built on, so a non-convex or degenerate footprint is refused rather than
silently replaced by its hull.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
import math
from typing import Sequence

import numpy as np
import yaml

from mpc_local_planner.core.obstacles import ConvexPolygon

__all__ = ['CIRCLE', 'FROM_WORLD', 'Footprint', 'JACKAL', 'parse_footprint', 'radius_in_force',
           'resolve']

# The nodes' robot_radius default: the world file's robot_radius (0 without a world). Any
# radius >= 0 is the robot's, smaller than the world's too.
FROM_WORLD = -1.0
# Smallest turn (cross product, m^2) between consecutive edges that counts as a corner.
_COLLINEAR_TOLERANCE = 1e-12


@dataclass(frozen=True)
class Footprint:
    """A circle of ``radius`` (vertices None), or a convex polygon in the robot frame.

    Attributes:
        radius: the circle's radius; for a polygon, the circumscribed radius (the farthest
            vertex from the robot's origin), which bounds the sweep of a turn.
        vertices: (K, 2) counter-clockwise vertices of the polygon, or None for a circle.

    """

    radius: float
    vertices: np.ndarray | None = None

    @classmethod
    def circle(cls, radius: float) -> Footprint:
        """Return a round robot of radius (m, >= 0)."""
        radius = float(radius)
        if not math.isfinite(radius) or radius < 0.0:
            msg = f'robot_radius must be a finite number >= 0, got {radius}'
            raise ValueError(msg)
        return cls(radius=radius)

    @classmethod
    def polygon(cls, vertices: Sequence[Sequence[float]] | np.ndarray) -> Footprint:
        """Return a convex polygonal robot; vertices in either orientation, no repeats.

        Raises:
            ValueError: fewer than 3 vertices, non-finite values, repeated or collinear
                vertices (no interior), or a polygon that is not convex.

        """
        points = np.asarray(vertices, dtype=float)
        if points.ndim != 2 or points.shape[1] != 2 or len(points) < 3:
            msg = f'a footprint polygon needs at least 3 [x, y] vertices, got {points.tolist()}'
            raise ValueError(msg)
        if not np.all(np.isfinite(points)):
            msg = 'footprint vertices must be finite numbers'
            raise ValueError(msg)
        edges = np.roll(points, -1, axis=0) - points
        if np.any(np.linalg.norm(edges, axis=1) <= 0.0):
            msg = 'footprint has a repeated vertex'
            raise ValueError(msg)
        turns = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] \
            - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
        if np.any(np.abs(turns) <= _COLLINEAR_TOLERANCE):
            msg = 'footprint has collinear consecutive vertices (no corner there) or no interior'
            raise ValueError(msg)
        if not (np.all(turns > 0) or np.all(turns < 0)):
            msg = 'footprint polygon is not convex'
            raise ValueError(msg)
        headings = np.arctan2(edges[:, 1], edges[:, 0])
        exterior = np.angle(np.exp(1j * (np.roll(headings, -1) - headings)))
        if abs(abs(float(np.sum(exterior))) - 2 * math.pi) > 1e-6:
            msg = 'footprint polygon crosses itself (it turns around more than once)'
            raise ValueError(msg)
        if turns[0] < 0:
            points = points[::-1]  # counter-clockwise, as ConvexPolygon keeps them
        return cls(radius=float(np.max(np.linalg.norm(points, axis=1))), vertices=points)

    @property
    def is_circle(self) -> bool:
        """A round robot (the fast special case: exact with a single inflation)."""
        return self.vertices is None

    @cached_property
    def body(self) -> ConvexPolygon:
        """The polygon in the robot frame as {y : G y <= g} with unit rows (G = A, g = b).

        The MPC's exact separation of robot and obstacle is written with these half-planes.
        Built once (Qhull): every scan asks for it, to tell the robot's own returns apart.

        Raises:
            ValueError: for a circle (it has no faces; obstacles are inflated instead).

        """
        if self.vertices is None:
            msg = 'a round footprint has no faces: obstacles are inflated by its radius'
            raise ValueError(msg)
        return ConvexPolygon.from_vertices(self.vertices)

    def contains(self, points: np.ndarray, *, margin: float = 0.0) -> np.ndarray:
        """Say, per point in the robot frame, whether it is within the footprint grown by margin.

        A circle grows to radius + margin; a polygon's faces move out by margin, its corners
        staying sharp (a rectangle's reach 1.41 margin from the vertex rather than margin:
        nothing for the millimetre the scan self-filter uses).

        Args:
            points: (N, 2) points, or (2,), in the robot frame (x forward).
            margin: How far outside the footprint still counts as inside, metres (>= 0).

        Returns:
            (N,) booleans; the boundary counts as inside.

        """
        pts = np.atleast_2d(np.asarray(points, dtype=float))[:, :2]
        if self.vertices is None:
            return np.hypot(pts[:, 0], pts[:, 1]) <= self.radius + margin
        return self.body.contains(pts, margin=margin)

    def at_poses(self, poses: np.ndarray) -> np.ndarray:
        """Return the vertices at each pose, (M, V, 2), counter-clockwise; one NumPy expression.

        Args:
            poses: (M, >= 3) poses (x, y, theta, ...); further columns are ignored.

        """
        poses = np.atleast_2d(np.asarray(poses, dtype=float))
        local = self._outline()
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        x = c[:, None] * local[None, :, 0] - s[:, None] * local[None, :, 1]
        y = s[:, None] * local[None, :, 0] + c[:, None] * local[None, :, 1]
        return np.stack([x + poses[:, :1], y + poses[:, 1:2]], axis=-1)

    def _outline(self) -> np.ndarray:
        """The polygon, or for a circle the 16-gon circumscribing it (drawing only)."""
        if self.vertices is not None:
            return self.vertices
        angles = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
        scale = self.radius / math.cos(math.pi / 16)
        return scale * np.column_stack([np.cos(angles), np.sin(angles)])

    def at(self, pose: Sequence[float]) -> np.ndarray:
        """Return the polygon's vertices at pose (x, y, theta) in the world frame.

        For a circle, a 16-gon circumscribing it (for drawing, e.g. RViz's PolygonStamped).
        """
        x, y, theta = (float(v) for v in pose[:3])
        local = self._outline()
        c, s = math.cos(theta), math.sin(theta)
        return local @ np.array([[c, s], [-s, c]]) + np.array([x, y])


# The BARN challenge's robot, a Clearpath Jackal: 0.508 m long, 0.430 m wide, centred.
JACKAL = Footprint.polygon([[0.254, 0.215], [-0.254, 0.215], [-0.254, -0.215], [0.254, -0.215]])
CIRCLE = Footprint.circle(0.0)


def parse_footprint(footprint: str | Sequence[Sequence[float]] | None,
                    robot_radius: float = 0.0) -> Footprint:
    """Return the footprint Nav2's parameters describe.

    Args:
        footprint: ``"[[x, y], ...]"`` (Nav2's string form), a list of [x, y], or
            ``''``/``'[]'``/None for a round robot.
        robot_radius: the radius used when no polygon is given.

    Raises:
        ValueError: a string that is not a list of [x, y] pairs, or an invalid polygon.

    """
    if isinstance(footprint, str):
        text = footprint.strip()
        if text in ('', '[]'):
            return Footprint.circle(robot_radius)
        try:
            footprint = yaml.safe_load(text)
        except yaml.YAMLError as err:
            msg = f'footprint {text!r} is not of the form "[[x, y], [x, y], ...]"'
            raise ValueError(msg) from err
        if not isinstance(footprint, list):
            msg = f'footprint {text!r} is not of the form "[[x, y], [x, y], ...]"'
            raise ValueError(msg)
    if footprint is None or len(footprint) == 0:
        return Footprint.circle(robot_radius)
    try:
        vertices = np.asarray(footprint, dtype=float)
    except (TypeError, ValueError) as err:
        msg = f'footprint {footprint!r} is not a list of [x, y] pairs'
        raise ValueError(msg) from err
    return Footprint.polygon(vertices)


def radius_in_force(robot_radius: float, world_radius: float) -> float:
    """Return a round robot's radius: robot_radius, or the world's when it is FROM_WORLD.

    A radius the user gives (>= 0) is the robot's, whatever the world file says; FROM_WORLD
    (any negative value) takes the world file's robot_radius.
    """
    return float(world_radius) if robot_radius < 0.0 else float(robot_radius)


def resolve(parameter: str | Sequence[Sequence[float]] | None,
            robot_radius: float = FROM_WORLD, world_footprint: Footprint | None = None,
            world_radius: float = 0.0) -> Footprint:
    """Return the robot's shape by Nav2's precedence, as every node and closed_loop apply it.

    1. the ``footprint`` parameter's convex polygon;
    2. the world file's footprint, when it is a polygon;
    3. a circle of ``robot_radius``, or of the world's radius when it is FROM_WORLD
       (radius_in_force).

    So a world that describes its robot is run with that robot unless a parameter says
    otherwise, and a radius (closed_loop sets it from the world's covering radius) never
    turns a polygon back into its circumscribed circle.

    Raises:
        ValueError: the parameter is not Nav2's "[[x, y], ...]" form of a convex polygon,
            with the reason.

    """
    try:
        shape = parse_footprint(parameter)
    except ValueError as err:
        msg = f'footprint {parameter!r}: {err}'
        raise ValueError(msg) from None
    if not shape.is_circle:
        return shape
    if world_footprint is not None and not world_footprint.is_circle:
        return world_footprint
    return Footprint.circle(radius_in_force(float(robot_radius), float(world_radius)))
