# SPDX-License-Identifier: Apache-2.0
"""The Dynamic Window Approach (Fox, Burgard, Thrun 1997) following a polyline: a baseline.

Each call samples the velocities (v, omega) reachable from the current velocity within one
control period (the dynamic window), simulates each as a constant-velocity arc over
``sim_time`` (all samples at once, in closed form), discards the inadmissible ones and
commands the cheapest of the rest. Scoring follows Nav2's DWB critics, in metres rather than
costmap cells:

- PathDist: distance of the arc's end to the path;
- GoalDist: distance of the arc's end to the local goal, the point ``local_goal_distance``
  ahead of the robot's projection on the path (DWB: the end of the plan in the local
  costmap; measured here in a straight line, not around obstacles);
- PathAlign, GoalAlign: the same two distances for the point ``forward_point_distance``
  ahead of the arc's end (so they score the heading);
- BaseObstacle: the costmap's inflation cost at the arc's closest approach,
  exp(-cost_scaling_factor * clearance) within ``inflation_radius`` of the footprint, 0
  beyond (1 at contact: Nav2's 252 normalised);
- and Fox's velocity term, which rewards speed.

Admissible: the footprint stays clear of every obstacle along the whole simulated arc, not
only at its samples (consecutive samples' clearances must sum to more than the distance a
footprint point can move between them), and Fox's braking condition holds over the free
distance the arc certifies: v^2 <= 2 decel_lim_x (|v| sim_time + clearance at the arc's end).
An arc that would touch an obstacle within sim_time is discarded even if the robot could
brake before it (as DWB does; Fox keeps it); its slower neighbours remain. When nothing in
the window is admissible, the robot rotates in place if that is admissible (v drops to 0 at
once), else stops.

The state of a unicycle is a pose; DWA needs the velocity too. The controller keeps the last
command it returned as the current velocity (the simulator executes commands exactly),
unless ``command`` is given the measured one; ``reset`` forgets it (the robot at rest).

Clearance, cheapest first: the obstacles' bounding circles against the footprint's radius;
for a polygon footprint, its faces against those circles; then, only for the (pose,
obstacle) pairs closer than an arc's sweep between two samples, where admissibility is
decided: a circle's exact distance, or the polygons' separating-axis gap (<= 0 exactly on
overlap, a lower bound on the distance otherwise, off by at most a few percent for BARN's
octagons). So a rectangular robot is not refused gaps only its circumscribed circle does not
fit through (its cost: docs/design/measurements.md, DWA's clearance).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import time
from typing import Sequence

import numpy as np

from mpc_local_planner.core.baselines.common import limited, plan_points, speed_limit
from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.footprint import CIRCLE, Footprint
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet
from mpc_local_planner.core.paths import Polyline, project_ahead, wrap_angle

__all__ = ['Dwa', 'DwaConfig']

# Squared segment lengths below this are points (padded faces of smaller polygons).
_TINY = 1e-18


@dataclass(frozen=True)
class DwaConfig:
    """Settings of `Dwa`; names follow Nav2's DWB where it has one.

    Defaults: the Unicycle's bounds; Nav2's DWB example for the accelerations (2.5 m/s^2,
    3.2 rad/s^2), sim_time (1.7 s) and critic weights, except that DWB's distances are in
    0.05 m cells and these in metres, and that the path critics weigh half of Nav2's 32
    (against 24 for the goal critics) so that the robot steps off the path around an
    obstacle reaching into its way instead of creeping up to it; the BARN challenge's DWA
    for the sample counts (6 x 20; Nav2's example samples 20 x 20, at 3 to 4 times the
    cost here).

    Attributes:
        max_vel_x: forward speed limit, m/s.
        min_vel_x: lowest speed, m/s (0: never backwards, DWB's default; < 0 reverses).
        max_vel_theta: turn rate limit (both ways), rad/s.
        acc_lim_x: linear acceleration limit, m/s^2.
        decel_lim_x: linear deceleration limit (a magnitude, > 0; Nav2 writes it negative),
            m/s^2; also the braking rate of the admissibility condition.
        acc_lim_theta: angular acceleration limit, both ways, rad/s^2.
        control_period: seconds between calls, the window's width (acc * period).
        sim_time: how long each arc is simulated, s.
        sim_granularity: time between the arc's samples, s (the clearance check is
            continuous between samples, so this trades resolution for speed only).
        vx_samples: linear velocities sampled across the window; the current one, 0 and,
            near the path's end, the speed whose arc ends on it are added when inside it.
        vtheta_samples: angular velocities sampled across the window (the current one and
            0 added likewise).
        path_dist_scale: weight of PathDist, per metre.
        goal_dist_scale: weight of GoalDist, per metre.
        path_align_scale: weight of PathAlign, per metre.
        goal_align_scale: weight of GoalAlign, per metre.
        forward_point_distance: how far ahead of an arc's end the alignment critics look, m.
        obstacle_scale: weight of BaseObstacle (its cost is 1 at contact).
        inflation_radius: clearance beyond which BaseObstacle costs nothing, m (Nav2's
            inflation layer's name and example value).
        cost_scaling_factor: decay rate of BaseObstacle's cost with clearance, 1/m (idem).
        velocity_scale: Fox's velocity term: velocity_scale * (max_vel_x - v) / max_vel_x.
        local_goal_distance: arc length from the robot's projection to the local goal, m;
            at least max_vel_x * sim_time, or the fastest arcs overshoot it.
        xy_goal_tolerance: the controller stops within this distance of the path's end, m.
        footprint: the robot's footprint (a circle of radius 0: a point).

    """

    max_vel_x: float = 0.31
    min_vel_x: float = 0.0
    max_vel_theta: float = 1.9
    acc_lim_x: float = 2.5
    decel_lim_x: float = 2.5
    acc_lim_theta: float = 3.2
    control_period: float = 0.2
    sim_time: float = 1.7
    sim_granularity: float = 0.1
    vx_samples: int = 6
    vtheta_samples: int = 20
    path_dist_scale: float = 16.0
    goal_dist_scale: float = 24.0
    path_align_scale: float = 16.0
    goal_align_scale: float = 24.0
    forward_point_distance: float = 0.325
    obstacle_scale: float = 5.0
    inflation_radius: float = 0.55
    cost_scaling_factor: float = 3.0
    velocity_scale: float = 1.0
    local_goal_distance: float = 1.5
    xy_goal_tolerance: float = 0.05
    footprint: Footprint = CIRCLE

    def __post_init__(self) -> None:
        """Refuse settings the window, the simulation or the scoring cannot use."""
        positive = ('max_vel_x', 'max_vel_theta', 'acc_lim_x', 'decel_lim_x', 'acc_lim_theta',
                    'control_period', 'sim_time', 'sim_granularity', 'local_goal_distance',
                    'xy_goal_tolerance')
        non_negative = ('path_dist_scale', 'goal_dist_scale', 'path_align_scale',
                        'goal_align_scale', 'forward_point_distance', 'obstacle_scale',
                        'inflation_radius', 'cost_scaling_factor', 'velocity_scale')
        problems = []
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                problems.append(f'{name} must be > 0 and finite, got {value!r}')
        for name in non_negative:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                problems.append(f'{name} must be >= 0 and finite, got {value!r}')
        if not (math.isfinite(self.min_vel_x) and self.min_vel_x < self.max_vel_x):
            problems.append(f'min_vel_x must be finite and < max_vel_x, got {self.min_vel_x!r}')
        if self.sim_granularity > self.sim_time:
            problems.append(f'sim_granularity ({self.sim_granularity}) must not exceed '
                            f'sim_time ({self.sim_time})')
        for name in ('vx_samples', 'vtheta_samples'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 2:
                problems.append(f'{name} must be an integer >= 2, got {value!r}')
        if not isinstance(self.footprint, Footprint):
            problems.append(f'footprint must be a Footprint, got {type(self.footprint).__name__}')
        if problems:
            msg = 'invalid DWA configuration: ' + '; '.join(problems)
            raise ValueError(msg)

    @property
    def steps(self) -> int:
        """Number of intervals an arc is simulated in (its samples: steps + 1, t = 0 included)."""
        return max(1, math.ceil(self.sim_time / self.sim_granularity - 1e-9))


class _Obstacles:
    """Convex polygons as padded arrays (faces, vertices, edges) and bounding circles.

    A polygon with fewer faces than the largest repeats its last face and its last vertex:
    the maximum over faces and the minimum over vertices do not change, and the repeated
    edge has length 0 (a point, which is a vertex already). The bounding circle (centre the
    vertices' mean, radius the farthest vertex) gives the cheap lower bound
    |p - centre| - radius on a point's distance, nearly exact for BARN's cylinders.
    """

    def __init__(self, polygons: Sequence[ConvexPolygon]) -> None:
        self.polygons = list(polygons)
        faces = max((p.num_faces for p in self.polygons), default=1)
        count = len(self.polygons)
        self.A = np.zeros((count, faces, 2))
        self.b = np.zeros((count, faces))
        self.vertices = np.zeros((count, faces, 2))
        self.edges = np.zeros((count, faces, 2))
        self.centres = np.zeros((count, 2))
        self.radii = np.zeros(count)
        for i, polygon in enumerate(self.polygons):
            rows = np.minimum(np.arange(faces), polygon.num_faces - 1)
            edges = np.roll(polygon.vertices, -1, axis=0) - polygon.vertices
            self.A[i], self.b[i] = polygon.A[rows], polygon.b[rows]
            self.vertices[i] = polygon.vertices[rows]
            self.edges[i] = np.where((np.arange(faces) < polygon.num_faces)[:, None],
                                     edges[rows], 0.0)
            self.centres[i] = np.mean(polygon.vertices, axis=0)
            self.radii[i] = np.max(np.linalg.norm(polygon.vertices - self.centres[i], axis=1))

    def __len__(self) -> int:
        return len(self.polygons)

    def circle_bound(self, points: np.ndarray, index: np.ndarray) -> np.ndarray:
        """Return |p - centre| - radius, (points, obstacles in index): <= the distance."""
        centres = self.centres[index]
        return np.hypot(points[:, None, 0] - centres[None, :, 0],
                        points[:, None, 1] - centres[None, :, 1]) - self.radii[index][None]


def _point_segment_distance(points: np.ndarray, starts: np.ndarray,
                            edges: np.ndarray) -> np.ndarray:
    """Distance of points (..., 2) to segments start + t edge, t in [0, 1], broadcast."""
    rel = points - starts
    length2 = np.sum(edges * edges, axis=-1)
    t = np.clip(np.sum(rel * edges, axis=-1) / np.maximum(length2, _TINY), 0.0, 1.0)
    gap = rel - t[..., None] * edges
    return np.sqrt(np.sum(gap * gap, axis=-1))


class Dwa:
    """Dynamic Window Approach follower of an (M, 2) polyline among convex obstacles.

    Args:
        waypoints: (M, 2) polyline (further columns, e.g. headings, are ignored), M >= 2
            distinct points.
        config: the controller's settings.
        obstacles: the convex obstacles to avoid, not inflated (the footprint is accounted
            for here), as polygons or an ObstacleSet.

    """

    def __init__(self, waypoints: np.ndarray | None = None, config: DwaConfig | None = None,
                 obstacles: Sequence[ConvexPolygon] | ObstacleSet = ()) -> None:
        self.config = config or DwaConfig()
        self._velocity = np.zeros(2)
        self._progress = 0.0
        self._path: Polyline | None = None
        self._speed_limit: float | None = None
        if waypoints is not None:
            self.set_path(waypoints)
        self.set_obstacles(obstacles)
        footprint = self.config.footprint
        self._radius = float(footprint.radius)
        # How far from the centre a footprint point that turning moves can be (0: a circle).
        self._arm = 0.0 if footprint.vertices is None else self._radius
        self._inradius = self._radius
        if footprint.vertices is not None:
            local = np.asarray(footprint.vertices, dtype=float)
            edges = np.roll(local, -1, axis=0) - local
            normals = np.column_stack([edges[:, 1], -edges[:, 0]])  # outward, CCW order
            normals /= np.linalg.norm(normals, axis=1, keepdims=True)
            self._local_vertices = local
            self._local_normals = normals
            self._local_offsets = np.einsum('ij,ij->i', normals, local)
            # The largest circle about the origin inside the polygon (its nearest face).
            self._inradius = float(max(np.min(self._local_offsets), 0.0))
        # Times of an arc's samples, t = 0 (where the robot is) included.
        self._times = np.linspace(0.0, self.config.sim_time, self.config.steps + 1)

    # --- what the caller sets -------------------------------------------------------------

    def set_path(self, waypoints: np.ndarray) -> None:
        """Follow a new polyline from its start (the progress is reset, the velocity kept)."""
        pts = np.asarray(waypoints, dtype=float)
        if pts.ndim == 2 and pts.shape[1] > 2:
            pts = pts[:, :2]
        self._path = Polyline(pts)
        self._progress = 0.0

    def set_obstacles(self, obstacles: Sequence[ConvexPolygon] | ObstacleSet) -> None:
        """Replace the obstacles (true geometry, not inflated)."""
        polygons = obstacles.obstacles if isinstance(obstacles, ObstacleSet) else obstacles
        self._obstacles = _Obstacles(list(polygons))

    def reset(self) -> None:
        """Forget the plan and start at rest (the kept velocity is cleared)."""
        self._path = None
        self._progress = 0.0
        self._velocity = np.zeros(2)

    # --- the local-controller interface (core/local_controller.py) -------------------------

    def set_plan(self, poses: np.ndarray) -> None:
        """Follow the plan's (M, 3) poses as a polyline (headings unused), as set_path does.

        Raises:
            ValueError: if the plan is not (M, >= 2) or its points are not a polyline.

        """
        self.set_path(plan_points(poses))

    def compute(self, pose: np.ndarray | None, twist: np.ndarray | None,
                now: float) -> ControlOutput:
        """Return the command for pose, timed, with the progress along the plan.

        The measured twist, when the base reports one, centres the window (`command`'s
        velocity, as DWB reads odometry's); without a plan or a pose the answer is a zero
        command with its reason.
        """
        if self._path is None:
            return ControlOutput(np.zeros(2), None, Reason.NO_PLAN, compute_time_s=0.0)
        if pose is None:
            self._velocity = np.zeros(2)
            return ControlOutput(np.zeros(2), None, Reason.NO_ODOM, compute_time_s=0.0)
        start = time.perf_counter()
        u = self.command(pose, velocity=twist)
        if self._speed_limit is not None:
            u = limited(u, self._speed_limit)
            self._velocity = u.copy()
        seconds = time.perf_counter() - start
        return ControlOutput(u, None, Reason.TRACKING,
                             progress=self._progress / max(self.length, 1e-9),
                             compute_time_s=seconds)

    def set_speed_limit(self, v_max: float | None) -> None:
        """Cap |v| at v_max from the next compute (the arc kept: omega scales with v)."""
        self._speed_limit = speed_limit(v_max)

    # --- what the rollout reads -----------------------------------------------------------

    @property
    def length(self) -> float:
        """Length of the polyline, metres (0 without one)."""
        return self._path.length if self._path is not None else 0.0

    @property
    def progress(self) -> float:
        """Arc length of the robot's current projection on the polyline, metres."""
        return self._progress

    @property
    def velocity(self) -> np.ndarray:
        """The velocity (v, omega) the next window is centred on: the last command."""
        return self._velocity.copy()

    def point_at(self, s: float) -> np.ndarray:
        """Return the point at arc length s (clipped to the path)."""
        assert self._path is not None, 'no path: call set_plan first'
        return self._path.point_at(s)

    # --- the decision ---------------------------------------------------------------------

    def command(self, x: np.ndarray, *, velocity: np.ndarray | None = None) -> np.ndarray:
        """Return the input [v, omega] for the pose x = (x, y, theta).

        Args:
            x: the robot's pose (further components are ignored).
            velocity: the measured (v, omega), if known; otherwise the last command is
                taken as the current velocity.

        Returns:
            (2,) finite input within [min_vel_x, max_vel_x] x [-max_vel_theta,
            max_vel_theta]; zero for a non-finite pose or velocity.

        """
        state = np.asarray(x, dtype=float).reshape(-1)
        current = self._velocity if velocity is None else np.asarray(velocity, dtype=float)
        if state.size < 3 or not np.all(np.isfinite(state[:3])) or current.shape != (2,) \
                or not np.all(np.isfinite(current)):
            self._velocity = np.zeros(2)
            return np.zeros(2)
        u = self._decide(state[:3], current)
        self._velocity = u
        return u.copy()

    def _decide(self, pose: np.ndarray, current: np.ndarray) -> np.ndarray:
        assert self._path is not None, 'no path: call set_plan first'
        c = self.config
        p = pose[:2]
        self._progress = self._project(p)
        end = self._path.points[-1]
        if self.length - self._progress <= c.local_goal_distance \
                and float(np.hypot(*(end - p))) <= c.xy_goal_tolerance:
            return np.zeros(2)
        v, omega, in_window = self._samples(pose, current)
        xy, theta = self._arcs(pose, v, omega)  # (S, K+1, 2), (S, K+1)
        sweep = self._sweep(v, omega)
        clearance = self.clearance(p, xy, theta, sweep + 1e-3)
        ok = self._admissible(v, sweep, clearance)
        candidates = ok & in_window
        if np.any(candidates):
            cost = self._cost(xy[:, -1], theta[:, -1], v, clearance)
            best = int(np.argmin(np.where(candidates, cost, np.inf)))
            return np.array([v[best], omega[best]])
        rotations = ok & ~in_window
        if np.any(rotations):
            # The fallback rotations come in the order (turn towards the local goal, away).
            return np.array([0.0, omega[int(np.flatnonzero(rotations)[0])]])
        return np.zeros(2)

    def _samples(self, pose: np.ndarray,
                 current: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (v, omega, in_window): the window's grid, then the fallback rotations."""
        c = self.config
        dt = c.control_period
        v_lo = float(np.clip(current[0] - c.decel_lim_x * dt, c.min_vel_x, c.max_vel_x))
        v_hi = float(np.clip(current[0] + c.acc_lim_x * dt, c.min_vel_x, c.max_vel_x))
        w_lo = float(np.clip(current[1] - c.acc_lim_theta * dt, -c.max_vel_theta,
                             c.max_vel_theta))
        w_hi = float(np.clip(current[1] + c.acc_lim_theta * dt, -c.max_vel_theta,
                             c.max_vel_theta))

        def axis(lo: float, hi: float, count: int, *extra: float) -> np.ndarray:
            values = [np.linspace(lo, hi, count), [0.0, *extra]]
            values = np.concatenate(values)
            return np.unique(values[(values >= lo) & (values <= hi)])

        # Besides the grid: the current velocity, standing still, and near the path's end
        # the speed whose arc ends on it (the grid's steps would stop short or overshoot).
        to_end = float(np.hypot(*(self._path.points[-1] - pose[:2])))
        arrive = to_end / c.sim_time if self.length - self._progress <= c.local_goal_distance \
            else v_hi
        vs = axis(v_lo, v_hi, c.vx_samples, float(current[0]), arrive)
        ws = axis(w_lo, w_hi, c.vtheta_samples, float(current[1]))
        v_grid, w_grid = (g.reshape(-1) for g in np.meshgrid(vs, ws, indexing='ij'))
        # Rotating in place at the window's extreme rates, towards the local goal first:
        # used only when nothing in the window is admissible (v drops to 0 at once then).
        goal = self.point_at(self._progress + c.local_goal_distance)
        error = float(wrap_angle(math.atan2(goal[1] - pose[1], goal[0] - pose[0]) - pose[2]))
        turn = [w_hi, w_lo] if error >= 0 else [w_lo, w_hi]
        v = np.concatenate([v_grid, [0.0, 0.0]])
        omega = np.concatenate([w_grid, turn])
        in_window = np.concatenate([np.ones(len(v_grid), dtype=bool), [False, False]])
        return v, omega, in_window

    def _arcs(self, pose: np.ndarray, v: np.ndarray,
              omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Constant-velocity arcs in closed form: positions (S, K+1, 2), headings (S, K+1).

        The chord of an arc of angle a = omega t has length v t sinc(a / 2) and points
        along theta + a / 2; np.sinc makes omega = 0 (a straight line) need no special case.
        """
        t = self._times[None, :]
        turned = omega[:, None] * t
        chord = v[:, None] * t * np.sinc(turned / (2.0 * math.pi))
        middle = pose[2] + turned / 2.0
        xy = np.stack([pose[0] + chord * np.cos(middle), pose[1] + chord * np.sin(middle)],
                      axis=-1)
        return xy, pose[2] + turned

    def clearance(self, robot: np.ndarray, xy: np.ndarray, theta: np.ndarray,
                   exact_below: np.ndarray) -> np.ndarray:
        """Return a lower bound on the footprint's clearance at each pose (m, <= 0: contact).

        Args:
            robot: (2,) where the robot is (the arcs stay within their length of it).
            xy: (S, K, 2) positions along S arcs.
            theta: (S, K) headings.
            exact_below: (S,) per arc, the clearance below which the value must be exact
                (the arc's sweep between two samples).

        Returns:
            (S, K) clearances, capped at max(inflation_radius, max(exact_below)).

        Where it is below its arc's exact_below (so every admissibility decision is made
        there): for a circle the exact clearance, for a
        polygon the separating-axis gap (<= 0 exactly when the polygons overlap, else a lower
        bound on their distance). Elsewhere a cheap bound from the obstacles' bounding
        circles (and, for a polygon, the footprint's faces), which is all BaseObstacle's cost
        needs. Obstacles further than the arcs' reach plus inflation_radius are left out: the
        clearance is capped there, where the cost is 0 anyway.
        """
        c = self.config
        obstacles = self._obstacles
        far = max(c.inflation_radius, float(np.max(exact_below)))
        arcs, samples = theta.shape
        points, headings = xy.reshape(-1, 2), theta.reshape(-1)
        exact_below = np.repeat(exact_below, samples)
        clearance = np.full(theta.shape, far)
        if not len(obstacles):
            return clearance
        reach = float(np.max(np.hypot(points[:, 0] - robot[0], points[:, 1] - robot[1])))
        everything = np.arange(len(obstacles))
        near = everything[obstacles.circle_bound(robot[None, :], everything)[0]
                          <= reach + self._radius + far]
        if not len(near):
            return clearance
        bound = obstacles.circle_bound(points, near) - self._radius  # (P, M)
        polygon = self._arm > 0.0
        if polygon:
            # The footprint's own faces bound its distance to an obstacle's circle better
            # than the circumscribed circle does, by at most radius - inradius. Refined: the
            # pairs the exact check would otherwise take, and those that may then hold
            # their arc's smallest bound (all the cost looks at).
            per_arc = bound.reshape(arcs, samples, len(near))
            lowest = np.min(per_arc, axis=(1, 2), keepdims=True) + self._radius - self._inradius
            wanted = (bound < exact_below[:, None]) | (
                (bound < far) & (per_arc < lowest).reshape(bound.shape))
            pose_index, slot = np.nonzero(wanted)
            footprint = self._footprint_at(points, headings)  # every pose once, then gathered
            bound[pose_index, slot] = np.maximum(
                bound[pose_index, slot],
                self._polygon_circle_bound(footprint, pose_index, near[slot]))
        pose_index, slot = np.nonzero(bound < exact_below[:, None])
        if len(pose_index):
            obstacle = near[slot]
            if polygon:
                exact = self._polygon_gap(footprint, pose_index, obstacle)
            else:
                exact = self._circle_clearance(points[pose_index], obstacle)
            bound[pose_index, slot] = np.maximum(bound[pose_index, slot], exact)
        return np.minimum(np.min(bound, axis=1), far).reshape(theta.shape)

    def _sweep(self, v: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """Return how far a footprint point can move between two samples of each arc.

        (|v| + |omega| r) dt, r = 0 for a circle (turning does not move it), the
        circumscribed radius for a polygon.
        """
        dt = self._times[1] - self._times[0]
        return (np.abs(v) + np.abs(omega) * self._arm) * dt

    def _circle_clearance(self, points: np.ndarray, obstacle: np.ndarray) -> np.ndarray:
        """Exact clearance of a round footprint: the centre's distance to the polygon - r."""
        o = self._obstacles
        A, b = o.A[obstacle], o.b[obstacle]
        inside = np.max(A[..., 0] * points[:, 0, None] + A[..., 1] * points[:, 1, None] - b,
                        axis=1)
        distance = np.min(_point_segment_distance(points[:, None, :], o.vertices[obstacle],
                                                  o.edges[obstacle]), axis=1)
        # Inside (face bound <= 0), the face bound is minus the depth: clearance negative.
        return np.where(inside > 0.0, distance, inside) - self._radius

    def _footprint_at(self, points: np.ndarray, headings: np.ndarray) -> tuple[np.ndarray, ...]:
        """Return the polygon at poses: vertices, outward normals and offsets.

        Shapes (P, K, 2), (P, K, 2) and (P, K): the footprint is {p : normals p <= offsets}.
        """
        cos, sin = np.cos(headings)[:, None], np.sin(headings)[:, None]
        lx, ly = self._local_vertices[:, 0], self._local_vertices[:, 1]
        nx, ny = self._local_normals[:, 0], self._local_normals[:, 1]
        vertices = np.stack([points[:, 0, None] + cos * lx - sin * ly,
                             points[:, 1, None] + sin * lx + cos * ly], axis=-1)
        normals = np.stack([cos * nx - sin * ny, sin * nx + cos * ny], axis=-1)
        offsets = self._local_offsets + normals[..., 0] * points[:, 0, None] \
            + normals[..., 1] * points[:, 1, None]
        return vertices, normals, offsets

    def _polygon_circle_bound(self, footprint: tuple[np.ndarray, ...], pose: np.ndarray,
                              obstacle: np.ndarray) -> np.ndarray:
        """Lower bound on the footprint's distance at poses to obstacles' bounding circles."""
        o = self._obstacles
        _, normals, offsets = footprint
        normals, offsets = normals[pose], offsets[pose]
        centres = o.centres[obstacle]
        gap = np.max(normals[..., 0] * centres[:, 0, None] + normals[..., 1] * centres[:, 1, None]
                     - offsets, axis=1)
        return gap - o.radii[obstacle]

    def _polygon_gap(self, footprint: tuple[np.ndarray, ...], pose: np.ndarray,
                     obstacle: np.ndarray) -> np.ndarray:
        """Separating-axis gap of a polygonal footprint at poses, one obstacle each.

        The largest gap along the faces' normals of both polygons: <= 0 exactly when they
        overlap, else a lower bound on their distance, exact when the closest points include
        a face (between two vertices, the cosine of half the angle between neighbouring
        normals: 0.92 for the Jackal against BARN's octagons). Vertex-edge distances would
        make it exact at eight times the cost; conservative is what admissibility needs.
        """
        o = self._obstacles
        robot, normals, offsets = (part[pose] for part in footprint)
        A, b = o.A[obstacle], o.b[obstacle]
        vertices = o.vertices[obstacle]
        # Obstacle faces against the robot's vertices, robot faces against the obstacle's:
        # (Q, faces, vertices) each.
        faces_obstacle = (A[:, :, None, 0] * robot[:, None, :, 0]
                          + A[:, :, None, 1] * robot[:, None, :, 1] - b[:, :, None])
        faces_robot = (normals[:, :, None, 0] * vertices[:, None, :, 0]
                       + normals[:, :, None, 1] * vertices[:, None, :, 1] - offsets[:, :, None])
        return np.maximum(np.max(np.min(faces_obstacle, axis=2), axis=1),
                          np.max(np.min(faces_robot, axis=2), axis=1))

    def _admissible(self, v: np.ndarray, sweep: np.ndarray,
                    clearance: np.ndarray) -> np.ndarray:
        """Fox's admissible velocities, with the clearance continuous along the arc.

        Between two samples a point of the footprint moves at most `sweep`, and the
        clearance changes no faster than that: the interval is clear if both clearances are
        positive and sum to more (the clearances are lower bounds: conservative). Braking:
        v^2 <= 2 decel d, d the free distance the arc certifies (its length plus the
        clearance at its end).
        """
        c = self.config
        clear = np.all(clearance > 0.0, axis=1) & np.all(
            clearance[:, :-1] + clearance[:, 1:] > sweep[:, None], axis=1)
        free = np.abs(v) * c.sim_time + clearance[:, -1]
        return clear & (v * v <= 2.0 * c.decel_lim_x * free)

    def _cost(self, end: np.ndarray, heading: np.ndarray, v: np.ndarray,
              clearance: np.ndarray) -> np.ndarray:
        """DWB's critics (PathDist, GoalDist, PathAlign, GoalAlign, BaseObstacle) and Fox's v."""
        c = self.config
        goal = self.point_at(self._progress + c.local_goal_distance)
        goal_dist = np.linalg.norm(end - goal, axis=1)
        # The forward point never looks past the local goal: at the path's end it would
        # otherwise punish arriving (DWB switches its alignment critics off near the goal).
        reach = np.minimum(c.forward_point_distance, goal_dist)
        forward = end + reach[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
        starts, edges = self._window_segments()
        path_dist = np.min(_point_segment_distance(end[:, None, :], starts, edges), axis=1)
        path_align = np.min(_point_segment_distance(forward[:, None, :], starts, edges), axis=1)
        goal_align = np.linalg.norm(forward - goal, axis=1)
        closest = np.min(clearance, axis=1)
        obstacle = np.where(closest < c.inflation_radius,
                            np.exp(-c.cost_scaling_factor * np.maximum(closest, 0.0)), 0.0)
        return (c.path_dist_scale * path_dist + c.goal_dist_scale * goal_dist
                + c.path_align_scale * path_align + c.goal_align_scale * goal_align
                + c.obstacle_scale * obstacle
                + c.velocity_scale * (c.max_vel_x - v) / c.max_vel_x)

    def _window_segments(self) -> tuple[np.ndarray, np.ndarray]:
        """Path segments from the robot's projection to the local goal (starts, edges)."""
        lo = self._progress
        hi = self._progress + self.config.local_goal_distance
        path = self._path
        keep = (path.arc[1:] >= lo) & (path.arc[:-1] <= hi)
        return path.points[:-1][keep], path.segments[keep]

    def _project(self, p: np.ndarray) -> float:
        """Closest arc length to p among the points not behind the current progress.

        As pure pursuit does: only within one local goal distance (plus the distance to the
        path) ahead, so that a path folding back on itself is not skipped.
        """
        return project_ahead(self._path.points, self._progress, p,
                             self.config.local_goal_distance)
