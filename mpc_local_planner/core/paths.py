# SPDX-License-Identifier: Apache-2.0
"""Reference paths p(s), s in [0, 1], evaluable in NumPy and as CasADi expressions.

The MPC optimises the path progress s_k, so the path must be a symbolic function of s; and
a new plan must not rebuild the solver, so a path's shape enters as a parameter vector of
fixed size (its *family* and capacity decide the solver's structure, its values do not).

Waypoint paths (what a nav_msgs/Path carries) have corners. The paper's Assumption 1.4 asks
for a Lipschitz g_p, so each corner becomes a turn-in-place segment: the position stays,
the heading rotates. The pose is then piecewise linear in s, continuous, with the heading
unwrapped, and s is proportional to length plus turn_length per radian turned. Its knots are
rounded over `smoothing` metres of path parameter so that g_p is continuously
differentiable: the terminal condition x_N = g_p(s) of a kinked g_p has no derivative at a
knot, and where the horizon's reach ends at a corner the optimum sits on that knot, where
Newton's method (fatrop's and IPOPT's) cannot converge (docs/design/measurements.md, Corner
smoothing). A knot joins a straight segment and a
turn, so the rounding only moves the turn's start and end a little along s: the positions
stay on the polyline, and a pose differs from the sharp polyline's at the same s by at most
smoothing / 4 in position and smoothing / (4 turn_length) in heading. A footprint with
circumradius r_c there moves at most smoothing / 4 (1 + r_c / turn_length) from the pose the
planner checked: 2.9 cm for the Jackal at the defaults, within the planner's clearance.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
import hashlib
import math
from typing import Any, Callable, NamedTuple

import casadi as ca
import numpy as np

__all__ = [
    'AnalyticPath',
    'CORNER_SMOOTHING',
    'ReferencePath',
    'WaypointPath',
    'analytic_path',
    'distinct_waypoints',
    'paper_sinusoid',
    'points_along',
    'Polyline',
    'project_ahead',
    'remaining_polyline',
    'RemainingPlan',
    'simplify_polyline',
    'smooth_ramp',
    'waypoints_to_poses',
    'wrap_angle',
]

Symbolic = Any
PROJECTION_SAMPLES = 2001
# Metres of path parameter over which a waypoint path's knots are rounded (see the module's
# note and docs/design/measurements.md, Corner smoothing).
CORNER_SMOOTHING = 0.05


def smooth_ramp(z: Any, width: Any) -> Any:
    """Return max(z, 0) with its kink rounded over |z| < width (C1; NumPy or CasADi).

    Equal to max(z, 0) outside the band and to (z + width)^2 / (4 width) inside it, written
    so that nothing cancels when width is small: max(z - width, 0) + min(max(z + width, 0),
    2 width)^2 / (4 width).
    """
    if isinstance(z, (ca.SX, ca.MX, ca.DM)) or isinstance(width, (ca.SX, ca.MX, ca.DM)):
        fmin, fmax = ca.fmin, ca.fmax
    else:
        fmin, fmax = np.minimum, np.maximum
    return fmax(z - width, 0) + fmin(fmax(z + width, 0), 2 * width) ** 2 / (4 * width)


def wrap_angle(angle: np.ndarray | float) -> np.ndarray | float:
    """Wrap an angle to [-pi, pi)."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


class ReferencePath(ABC):
    """A continuous path s in [0, 1] -> pose (x, y, theta) with an unwrapped heading."""

    @property
    @abstractmethod
    def family(self) -> str:
        """Key of the symbolic structure: paths of one family share a built solver."""

    @property
    @abstractmethod
    def num_params(self) -> int:
        """Length of the parameter vector that symbolic() reads."""

    @abstractmethod
    def parameters(self) -> np.ndarray:
        """Return the values of the parameter vector for this path."""

    @abstractmethod
    def symbolic(self, s: Symbolic, params: Symbolic) -> Symbolic:
        """Return p(s) as a 3-vector CasADi expression, the shape read from params."""

    @abstractmethod
    def pose(self, s: np.ndarray | float) -> np.ndarray:
        """Return p(s) numerically: (3,) for a scalar s, (n, 3) for an array."""

    def sample(self, count: int = PROJECTION_SAMPLES) -> tuple[np.ndarray, np.ndarray]:
        """Return (s, poses) at count evenly spaced values of s."""
        s = np.linspace(0.0, 1.0, count)
        return s, self.pose(s)

    @property
    def start(self) -> np.ndarray:
        """p(0), the robot's configuration when the path was planned."""
        return self.pose(0.0)

    @property
    def goal(self) -> np.ndarray:
        """p(1), the target configuration."""
        return self.pose(1.0)

    def length(self) -> float:
        """Return the length of the path's position trace in metres."""
        _, poses = self.sample()
        return float(np.sum(np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1)))

    def lipschitz_estimate(self) -> float:
        """Estimate the Lipschitz constant of g_p from finite differences (Assumption 1.4)."""
        s, poses = self.sample()
        return float(np.max(np.linalg.norm(np.diff(poses, axis=0), axis=1) / np.diff(s)))

    def project(
        self,
        pose: np.ndarray,
        *,
        s_min: float = 0.0,
        s_max: float = 1.0,
        heading_weight: float = 0.1,
    ) -> float:
        """Return the s in [s_min, s_max] whose pose is nearest to pose.

        Distance is squared position error plus heading_weight times the squared wrapped
        heading error, so that at a turn-in-place corner the matching heading is chosen.
        """
        pose = np.asarray(pose, dtype=float)
        s, poses = self.sample()
        mask = (s >= s_min - 1e-12) & (s <= s_max + 1e-12)
        if not np.any(mask):
            mask[np.argmin(np.abs(s - s_min))] = True
        s, poses = s[mask], poses[mask]
        err = np.sum((poses[:, :2] - pose[:2]) ** 2, axis=1)
        err = err + heading_weight * wrap_angle(poses[:, 2] - pose[2]) ** 2
        return float(s[int(np.argmin(err))])


class AnalyticPath(ReferencePath):
    """A path given by a closed-form expression in s (no parameters)."""

    def __init__(self, name: str, expression: Callable[[Symbolic], Symbolic]) -> None:
        self._name = name
        self._expression = expression
        s = ca.SX.sym('s')
        self._function = ca.Function(name, [s], [ca.vec(expression(s))])
        # the expression is in the NLP: two paths of one name but other numbers (two
        # amplitudes of a sinusoid) must not share a solver
        digest = hashlib.sha256(self._function.serialize().encode()).hexdigest()[:16]
        self._family = f'analytic:{name}:{digest}'

    @property
    def family(self) -> str:
        """One family per expression: its name and the hash of the serialized expression."""
        return self._family

    @property
    def name(self) -> str:
        """The path's name, as world files refer to it."""
        return self._name

    @property
    def num_params(self) -> int:
        """No parameters: the expression is fixed."""
        return 0

    def parameters(self) -> np.ndarray:
        """Return an empty vector."""
        return np.zeros(0)

    def symbolic(self, s: Symbolic, params: Symbolic) -> Symbolic:
        """Return the expression itself."""
        return self._function(s)

    def pose(self, s: np.ndarray | float) -> np.ndarray:
        """Evaluate the expression numerically."""
        s_arr = np.atleast_1d(np.asarray(s, dtype=float))
        values = np.asarray(self._function.map(len(s_arr))(s_arr.reshape(1, -1))).T
        return values[0] if np.ndim(s) == 0 else values


def paper_sinusoid() -> AnalyticPath:
    """The paper's example path p(s) = [2.5 s, 1.1 sin(pi s), atan(1.1 pi cos(pi s) / 2.5)]."""
    return AnalyticPath(
        'paper_sinusoid',
        lambda s: ca.vertcat(
            2.5 * s, 1.1 * ca.sin(ca.pi * s), ca.atan(1.1 * ca.pi * ca.cos(ca.pi * s) / 2.5)
        ),
    )


ANALYTIC_PATHS: dict[str, Callable[[], AnalyticPath]] = {'paper_sinusoid': paper_sinusoid}


def analytic_path(name: str) -> AnalyticPath:
    """Return the named analytic path (world files name them)."""
    try:
        return ANALYTIC_PATHS[name]()
    except KeyError:
        msg = f'unknown analytic path {name!r}; known: {sorted(ANALYTIC_PATHS)}'
        raise ValueError(msg) from None


class WaypointPath(ReferencePath):
    """A polyline with turn-in-place corners, parametrised by length plus turning.

    Symbolically p(s) = p_0 + k_0 s + sum_i dk_i smooth_ramp(s - s_i, d_i): the first
    segment's slope, then one rounded hinge per interior knot s_i where the slope changes by
    dk_i, rounded over |s - s_i| < d_i (smoothing, kept inside [0, 1] so that p(0) and p(1)
    are the start and the goal exactly). The solver's structure depends only on the
    capacity (the maximum number of segments); unused hinges are padded with dk_i = 0.
    """

    PARAMS_PER_SEGMENT = 5  # s_i, d_i, dk_x, dk_y, dk_theta

    def __init__(
        self,
        waypoints: np.ndarray,
        *,
        start_heading: float | None = None,
        goal_heading: float | None = None,
        turn_length: float = 0.25,
        capacity: int = 64,
        smoothing: float = CORNER_SMOOTHING,
    ) -> None:
        """Build the path.

        Args:
            waypoints: (M, 2) positions; consecutive duplicates are dropped.
            start_heading: the robot's heading at the start; the path first turns in place
                from it to the first segment's direction (None: no initial turn).
            goal_heading: heading at the goal; the path ends turning in place to it.
            turn_length: metres of path parameter per radian turned in place (> 0), so
                that g_p stays Lipschitz at corners.
            capacity: maximum number of segments (straight and turning) the solver holds.
            smoothing: metres of path parameter over which each knot is rounded (> 0),
                so that g_p is differentiable (see the module's note).

        Raises:
            ValueError: on non-finite input, fewer than two distinct points, or more
                segments than capacity.

        """
        pts = distinct_waypoints(waypoints, tolerance=1e-6)
        for heading in (start_heading, goal_heading):
            if heading is not None and not math.isfinite(heading):
                msg = 'start and goal headings must be finite'
                raise ValueError(msg)
        if turn_length <= 0:
            msg = f'turn_length must be > 0, got {turn_length}'
            raise ValueError(msg)
        if not (math.isfinite(smoothing) and smoothing > 0):
            msg = f'smoothing must be > 0 and finite, got {smoothing}'
            raise ValueError(msg)
        self._turn_length = float(turn_length)
        self._capacity = int(capacity)
        self._knots = self._knot_poses(pts, start_heading, goal_heading)
        if len(self._knots) - 1 > self._capacity:
            msg = (
                f'path has {len(self._knots) - 1} segments, more than the capacity '
                f'{self._capacity}; simplify it (simplify_polyline) or raise the capacity'
            )
            raise ValueError(msg)
        weights = np.array([1.0, 1.0, self._turn_length])
        lengths = np.linalg.norm(np.diff(self._knots, axis=0) * weights, axis=1)
        total = float(np.sum(lengths))
        self._s_knots = np.concatenate([[0.0], np.cumsum(lengths)]) / total
        self._waypoints = pts
        slopes = np.diff(self._knots, axis=0) / np.diff(self._s_knots)[:, None]
        interior = self._s_knots[1:-1]
        self._first_slope = slopes[0]
        self._hinges = np.column_stack([
            interior,
            np.minimum.reduce([np.full(len(interior), smoothing / total), interior,
                               1.0 - interior]),
            np.diff(slopes, axis=0),
        ]).reshape(-1, self.PARAMS_PER_SEGMENT)

    @staticmethod
    def _knot_poses(
        pts: np.ndarray, start_heading: float | None, goal_heading: float | None
    ) -> np.ndarray:
        directions = np.arctan2(np.diff(pts[:, 1]), np.diff(pts[:, 0]))
        knots: list[list[float]] = []
        heading = directions[0] if start_heading is None else float(start_heading)
        knots.append([pts[0, 0], pts[0, 1], heading])
        for i, direction in enumerate(directions):
            new_heading = heading + float(wrap_angle(direction - heading))
            if abs(new_heading - heading) > 1e-9:
                knots.append([pts[i, 0], pts[i, 1], new_heading])
            heading = new_heading
            knots.append([pts[i + 1, 0], pts[i + 1, 1], heading])
        if goal_heading is not None:
            new_heading = heading + float(wrap_angle(goal_heading - heading))
            if abs(new_heading - heading) > 1e-9:
                knots.append([pts[-1, 0], pts[-1, 1], new_heading])
        return np.array(knots)

    @classmethod
    def from_poses(cls, poses: np.ndarray, **kwargs: Any) -> WaypointPath:
        """Build from (M, 3) poses: positions plus the first and last headings."""
        poses = np.asarray(poses, dtype=float)
        if poses.ndim != 2 or poses.shape[1] != 3:
            msg = f'poses must have shape (M, 3), got {poses.shape}'
            raise ValueError(msg)
        kwargs.setdefault('start_heading', float(poses[0, 2]))
        kwargs.setdefault('goal_heading', float(poses[-1, 2]))
        return cls(poses[:, :2], **kwargs)

    @property
    def family(self) -> str:
        """All waypoint paths of one capacity share a solver."""
        return f'waypoints:{self._capacity}'

    @property
    def capacity(self) -> int:
        """Maximum number of segments."""
        return self._capacity

    @property
    def knots(self) -> np.ndarray:
        """(K, 3) poses at the segment ends, heading unwrapped."""
        return self._knots.copy()

    @property
    def s_knots(self) -> np.ndarray:
        """(K,) the path parameter s of each knot: 0 at the start, 1 at the goal."""
        return self._s_knots.copy()

    @property
    def waypoints(self) -> np.ndarray:
        """(M, 2) the distinct input positions."""
        return self._waypoints.copy()

    @property
    def num_params(self) -> int:
        """3 for p_0, 3 for the first slope k_0, plus 5 per hinge slot."""
        return 6 + self.PARAMS_PER_SEGMENT * self._capacity

    def parameters(self) -> np.ndarray:
        """Pack p_0, k_0 and (s_i, d_i, dk_i) per hinge, padded with flat hinges at s = 1."""
        hinges = np.zeros((self._capacity, self.PARAMS_PER_SEGMENT))
        hinges[:, 0:2] = 1.0  # dk = 0: contributes nothing (d = 1 keeps it finite)
        hinges[:len(self._hinges)] = self._hinges
        return np.concatenate([self._knots[0], self._first_slope, hinges.reshape(-1)])

    def symbolic(self, s: Symbolic, params: Symbolic) -> Symbolic:
        """p_0 + k_0 s plus one rounded hinge per slot."""
        p = params[0:3] + params[3:6] * s
        for i in range(self._capacity):
            base = 6 + self.PARAMS_PER_SEGMENT * i
            ramp = smooth_ramp(s - params[base], params[base + 1])
            p = p + ramp * params[base + 2:base + 5]
        return p

    def pose(self, s: np.ndarray | float) -> np.ndarray:
        """Evaluate the same sum as symbolic() in NumPy, for every s at once."""
        s_arr = np.clip(np.atleast_1d(np.asarray(s, dtype=float)), 0.0, 1.0)
        h = self._hinges
        ramps = smooth_ramp(s_arr[:, None] - h[None, :, 0], h[None, :, 1])
        values = self._knots[0] + s_arr[:, None] * self._first_slope + ramps @ h[:, 2:]
        return values[0] if np.ndim(s) == 0 else values


def distinct_waypoints(waypoints: np.ndarray, *, tolerance: float) -> np.ndarray:
    """Return (M, 2) waypoints without consecutive repeats (closer than tolerance).

    Raises:
        ValueError: if the shape is not (M, 2), a value is not finite, or fewer than two
            distinct points remain.

    """
    pts = np.asarray(waypoints, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2:
        msg = f'waypoints must have shape (M, 2), got {pts.shape}'
        raise ValueError(msg)
    if not np.all(np.isfinite(pts)):
        msg = 'waypoints contain NaN or inf'
        raise ValueError(msg)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > tolerance])
    pts = pts[keep]
    if len(pts) < 2:
        msg = 'a path needs at least two distinct waypoints'
        raise ValueError(msg)
    return pts


class Polyline:
    """A follower's polyline: its distinct points, segments and arc lengths, and points by arc.

    What pure pursuit and the DWA both keep of a plan (`project_ahead` finds their progress).

    Args:
        waypoints: (M, 2) points; consecutive repeats (within 1e-9 m) are dropped.

    Raises:
        ValueError: as `distinct_waypoints`.

    """

    def __init__(self, waypoints: np.ndarray) -> None:
        self.points = distinct_waypoints(waypoints, tolerance=1e-9)
        self.segments = np.diff(self.points, axis=0)
        self.segment_lengths = np.linalg.norm(self.segments, axis=1)
        # the arc length at each point: 0 at the first, the polyline's length at the last
        self.arc = np.concatenate([[0.0], np.cumsum(self.segment_lengths)])

    @property
    def length(self) -> float:
        """Length of the polyline, metres."""
        return float(self.arc[-1])

    def point_at(self, s: float) -> np.ndarray:
        """Return the point at arc length s (clipped to the polyline)."""
        s = float(np.clip(s, 0.0, self.arc[-1]))
        i = int(np.clip(np.searchsorted(self.arc, s, side='right') - 1, 0,
                        len(self.segments) - 1))
        t = (s - self.arc[i]) / self.segment_lengths[i]
        return self.points[i] + t * self.segments[i]


def simplify_polyline(points: np.ndarray, tolerance: float) -> np.ndarray:
    """Drop points within tolerance of the line through their neighbours (Ramer-Douglas-Peucker).

    Iterative, vectorised per segment: a 100,000-pose nav_msgs/Path simplifies in
    milliseconds instead of overflowing the recursion limit.
    """
    pts = np.asarray(points, dtype=float)
    if len(pts) < 3:
        return pts.copy()
    keep = np.zeros(len(pts), dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, len(pts) - 1)]
    while stack:
        first, last = stack.pop()
        if last - first < 2:
            continue
        a, b = pts[first], pts[last]
        inner = pts[first + 1:last]
        ab = b - a
        norm = np.linalg.norm(ab)
        if norm < 1e-12:
            dist = np.linalg.norm(inner - a, axis=1)
        else:
            dist = np.abs(ab[0] * (inner[:, 1] - a[1]) - ab[1] * (inner[:, 0] - a[0])) / norm
        index = int(np.argmax(dist))
        if dist[index] > tolerance:
            split = first + 1 + index
            keep[split] = True
            stack.append((first, split))
            stack.append((split, last))
    return pts[keep]


class RemainingPlan(NamedTuple):
    """What is left of a plan: its points from the projection, and the projection's segment."""

    points: np.ndarray
    segment: int


def remaining_polyline(waypoints: np.ndarray, point: np.ndarray, *,
                       forward_from: int = 0) -> RemainingPlan:
    """Return the part of a polyline after the point's projection onto it.

    What is left of a plan for a robot at point: the nearest point of the polyline on
    segment forward_from or a later one (the first segment wins a tie), then the later
    vertices. A re-planner checks this part only: what the robot has passed cannot block it.
    The controller passes the segment of its previous projection (projections only move
    forward along a plan, so a plan that comes back near itself is not cut short); the
    planner, which keeps no projection, 0 (the nearest point of the whole plan).

    Args:
        waypoints: (M, 2+) vertices, M >= 1 (further columns are ignored).
        point: (2+,) the robot's position (further entries are ignored).
        forward_from: the first segment the projection may lie on (clipped to the last).

    Returns:
        (K, 2) vertices, K >= 1, starting at the projection, and the projection's segment.

    """
    pts = np.atleast_2d(np.asarray(waypoints, dtype=float))[:, :2]
    p = np.asarray(point, dtype=float).reshape(-1)[:2]
    if len(pts) < 2:
        return RemainingPlan(pts.copy(), 0)
    start = min(max(int(forward_from), 0), len(pts) - 2)
    a, d = pts[start:-1], np.diff(pts[start:], axis=0)
    length2 = np.einsum('ij,ij->i', d, d)
    t = np.clip(np.einsum('ij,ij->i', p - a, d) / np.maximum(length2, 1e-18), 0.0, 1.0)
    nearest = a + t[:, None] * d
    k = int(np.argmin(np.hypot(*(nearest - p).T)))
    return RemainingPlan(np.vstack([nearest[k], pts[start + k + 1:]]), start + k)


def points_along(waypoints: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Return points along a polyline at most spacing apart, and their arc lengths.

    Every vertex is among the points (a segment's end is the next one's start, twice).

    Args:
        waypoints: (M, 2+) vertices, M >= 1 (further columns are ignored).
        spacing: Largest distance between consecutive points, metres (> 0).

    Returns:
        ((K, 2) points, (K,) arc lengths), the first point the first vertex.

    """
    pts = np.atleast_2d(np.asarray(waypoints, dtype=float))[:, :2]
    if len(pts) < 2:
        return pts.copy(), np.zeros(len(pts))
    delta = np.diff(pts, axis=0)
    length = np.hypot(delta[:, 0], delta[:, 1])
    counts = np.ceil(length / spacing).astype(np.int64) + 1
    seg = np.repeat(np.arange(len(delta)), counts)
    step = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    frac = step / np.maximum(counts[seg] - 1, 1)
    start = np.concatenate([[0.0], np.cumsum(length)[:-1]])
    return pts[seg] + frac[:, None] * delta[seg], start[seg] + frac * length[seg]


def waypoints_to_poses(waypoints: np.ndarray, start_yaw: float, goal_yaw: float) -> np.ndarray:
    """Return (M, 3) poses: each waypoint heads along its outgoing segment.

    The first pose keeps the robot's yaw and the last the goal's, so that a controller
    turns in place at the ends (as `WaypointPath.from_poses` reads them).
    """
    pts = np.asarray(waypoints, dtype=float)[:, :2]
    directions = np.arctan2(np.diff(pts[:, 1]), np.diff(pts[:, 0]))
    yaw = np.concatenate([[start_yaw], directions[1:], [goal_yaw]])
    return np.column_stack([pts, yaw])


def project_ahead(points: np.ndarray, progress: float, position: np.ndarray,
                  ahead: float) -> float:
    """Return the arc length of the polyline's point nearest position, not behind progress.

    A follower's projection: only the stretch from progress to ``ahead`` plus the distance
    to the path beyond it is searched, so that a path folding back on itself is not skipped,
    and progress never decreases.

    Args:
        points: (M, 2) vertices, M >= 2, consecutive ones distinct.
        progress: The arc length reached so far, metres.
        position: (2,) the robot's position.
        ahead: How far beyond progress (plus the distance to the path) to look, metres.

    """
    pts = np.asarray(points, dtype=float)[:, :2]
    segments = np.diff(pts, axis=0)
    lengths = np.hypot(segments[:, 0], segments[:, 1])
    arc = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
    rel = np.asarray(position, dtype=float)[:2] - pts[:-1]
    t = np.clip(np.sum(rel * segments, axis=1) / lengths**2, 0.0, 1.0)
    closest = pts[:-1] + t[:, None] * segments
    dist = np.hypot(*(closest - np.asarray(position, dtype=float)[:2]).T)
    s = arc + t * lengths
    window = progress + ahead + float(np.min(dist)) + 1e-9
    valid = (s >= progress - 1e-9) & (s <= window)
    if not np.any(valid):
        return float(progress)
    return float(max(progress, s[int(np.argmin(np.where(valid, dist, np.inf)))]))
