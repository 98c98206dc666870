# SPDX-License-Identifier: Apache-2.0
"""Lookahead pure pursuit of a polyline for a unicycle, classic or regulated as Nav2's RPP.

The follower keeps a monotone progress along the polyline (the closest point ahead of the
last one), aims at the point one lookahead distance further on, and commands the arc through
it: omega = 2 v sin(alpha) / L. It turns in place when the aim point is behind it, slows down
near the end and stops there.

The classic follower (`PurePursuitConfig()`) knows nothing of obstacles: where the path cuts
close to one, so may the robot. `PurePursuitConfig.regulated` is Nav2's Regulated Pure
Pursuit (nav2_regulated_pure_pursuit_controller, its default parameters) as a user sets it
up for a fast robot:

- the lookahead scales with the speed (``use_velocity_scaled_lookahead_dist``:
  |v| * lookahead_time within [min_lookahead, max_lookahead]), the measured speed when the
  base reports one, else the last command's;
- the speed is regulated by the arc's curvature (``regulated_linear_scaling_min_radius``:
  v * r / r_min on arcs tighter than r_min, not below ``regulated_linear_scaling_min_speed``)
  and on the approach to the end (v * distance / ``approach_velocity_scaling_dist``, not
  below ``min_approach_linear_velocity``);
- it rotates to the path when the aim point is more than ``rotate_to_heading_min_angle``
  off its heading, at ``rotate_to_heading_angular_vel``;
- collision detection (``use_collision_detection``): the footprint where the robot is, and
  along the command's arc up to ``max_allowed_time_to_collision_up_to_carrot`` seconds and no
  farther than the aim point; where it meets an obstacle there is no valid command (Nav2's
  controller fails and the robot stops): the follower commands zero (`collision_ahead`).

Left out, as a robot's stack does them elsewhere: the cost-regulated scaling (off by default
in Nav2), the angular acceleration limit of the turn in place and the velocity smoother (the
base's own limits apply them here, `sim/reality.py`).
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
from mpc_local_planner.core.models import unicycle_arc
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet, polygon_separation
from mpc_local_planner.core.paths import Polyline, project_ahead, wrap_angle

__all__ = ['PurePursuit', 'PurePursuitConfig']


@dataclass(frozen=True)
class PurePursuitConfig:
    """Settings of `PurePursuit`; the defaults are the classic follower (no regulation).

    Attributes:
        lookahead: distance along the path from the robot's projection to the aim point, m
            (with lookahead_time 0).
        v_max: forward speed limit, m/s (Nav2's desired_linear_vel).
        omega_max: turn rate limit, rad/s.
        goal_tolerance: the follower stops within this distance of the path's end, m.
        slowdown: gain of v = slowdown * distance-to-end near the end, 1/s (with
            approach_distance 0).
        turn_in_place: above this |alpha| (rad) the robot turns in place first.
        turn_rate: rate of that turn, rad/s (at most omega_max); 0 = omega_max.
        lookahead_time: > 0: the lookahead is |v| times this, s, within [min_lookahead,
            max_lookahead] (Nav2's use_velocity_scaled_lookahead_dist); 0 = fixed.
        min_lookahead: least velocity-scaled lookahead, m.
        max_lookahead: largest velocity-scaled lookahead, m.
        regulated_min_radius: > 0: on arcs of a smaller radius the speed is scaled by
            radius / regulated_min_radius (Nav2's regulated_linear_scaling_min_radius).
        regulated_min_speed: the curvature's regulation does not go below this, m/s.
        approach_distance: > 0: within this path length of the end, the speed is scaled by
            the distance to the end over it (Nav2's approach_velocity_scaling_dist), in
            place of slowdown.
        min_approach_speed: the approach's scaling does not go below this, m/s.
        collision_time: > 0: the footprint where the robot is, and along the command's arc
            for this many seconds ahead up to the aim point, is checked against the
            obstacles (Nav2's max_allowed_time_to_collision_up_to_carrot); 0 = no check.
        collision_step: distance between two checked poses of that arc, m (Nav2 takes the
            costmap's resolution).
        footprint: the robot's outline for the collision check.

    """

    lookahead: float = 0.4
    v_max: float = 0.31
    omega_max: float = 1.9
    goal_tolerance: float = 0.03
    slowdown: float = 1.0
    turn_in_place: float = math.pi / 2
    turn_rate: float = 0.0
    lookahead_time: float = 0.0
    min_lookahead: float = 0.3
    max_lookahead: float = 0.9
    regulated_min_radius: float = 0.0
    regulated_min_speed: float = 0.25
    approach_distance: float = 0.0
    min_approach_speed: float = 0.05
    collision_time: float = 0.0
    collision_step: float = 0.05
    footprint: Footprint = CIRCLE

    def __post_init__(self) -> None:
        """Refuse non-positive settings (negative or non-finite for the optional ones)."""
        for name in ('lookahead', 'v_max', 'omega_max', 'goal_tolerance', 'slowdown',
                     'turn_in_place', 'min_lookahead', 'max_lookahead', 'collision_step'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                msg = f'{name} must be > 0 and finite, got {value}'
                raise ValueError(msg)
        for name in ('turn_rate', 'lookahead_time', 'regulated_min_radius',
                     'regulated_min_speed', 'approach_distance', 'min_approach_speed',
                     'collision_time'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                msg = f'{name} must be >= 0 and finite, got {value}'
                raise ValueError(msg)
        if self.collision_time > 0.0 and not self.footprint.radius > 0.0:
            msg = 'collision_time > 0 needs a footprint of some size (a polygon or a radius > 0)'
            raise ValueError(msg)
        if self.min_lookahead > self.max_lookahead:
            msg = (f'min_lookahead must be <= max_lookahead, got {self.min_lookahead} > '
                   f'{self.max_lookahead}')
            raise ValueError(msg)

    @classmethod
    def regulated(cls, v_max: float, omega_max: float, *, footprint: Footprint,
                  goal_tolerance: float = 0.03) -> PurePursuitConfig:
        """Return Nav2's Regulated Pure Pursuit, its defaults, for a robot's limits.

        Nav2's default parameters (nav2_regulated_pure_pursuit_controller's
        params/regulated_pure_pursuit_params.yaml) with the lookahead scaled by the speed,
        as its documentation advises for a robot of several speeds.
        """
        return cls(v_max=v_max, omega_max=omega_max, goal_tolerance=goal_tolerance,
                   turn_in_place=0.785, turn_rate=1.8, lookahead_time=1.5,
                   min_lookahead=0.3, max_lookahead=0.9, regulated_min_radius=0.9,
                   regulated_min_speed=0.25, approach_distance=0.6, min_approach_speed=0.05,
                   collision_time=1.0, footprint=footprint)


class PurePursuit:
    """Pure-pursuit follower of an (M, 2) polyline.

    Args:
        waypoints: (M, 2) polyline, M >= 2 distinct points.
        config: the follower's settings.

    """

    def __init__(self, waypoints: np.ndarray | None = None,
                 config: PurePursuitConfig | None = None) -> None:
        self.config = config or PurePursuitConfig()
        self._path: Polyline | None = None
        self._progress = 0.0
        if waypoints is not None:
            self.set_path(waypoints)
        self._obstacles = ObstacleSet([])
        self._last_speed = 0.0
        self._speed_limit: float | None = None
        self.collision_ahead = False  # the last command was refused by the collision check

    def set_path(self, waypoints: np.ndarray) -> None:
        """Follow a new polyline from its start (the progress is reset, the speed kept)."""
        self._path = Polyline(waypoints)
        self._progress = 0.0

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

        The measured twist scales the regulated follower's lookahead (`command`'s
        velocity); without a plan or a pose the answer is a zero command with its reason.
        """
        if self._path is None:
            return ControlOutput(np.zeros(2), None, Reason.NO_PLAN, compute_time_s=0.0)
        if pose is None:
            return ControlOutput(np.zeros(2), None, Reason.NO_ODOM, compute_time_s=0.0)
        start = time.perf_counter()
        u = limited(np.asarray(self.command(pose, velocity=twist), dtype=float),
                     self._speed_limit)
        seconds = time.perf_counter() - start
        return ControlOutput(u, None, Reason.TRACKING,
                             progress=self._progress / max(self.length, 1e-9),
                             compute_time_s=seconds)

    def set_speed_limit(self, v_max: float | None) -> None:
        """Cap |v| at v_max from the next compute (the arc kept: omega scales with v)."""
        self._speed_limit = speed_limit(v_max)

    @property
    def length(self) -> float:
        """Length of the polyline, metres (0 without one)."""
        return self._path.length if self._path is not None else 0.0

    @property
    def progress(self) -> float:
        """Arc length of the robot's current projection on the polyline, metres."""
        return self._progress

    def reset(self) -> None:
        """Forget the plan (a new run starts with set_plan); the speed limit stays."""
        self._path = None
        self._progress = 0.0

    def set_obstacles(self, obstacles: Sequence[ConvexPolygon] | ObstacleSet) -> None:
        """Replace the obstacles the collision check uses (with collision_time > 0)."""
        self._obstacles = (obstacles if isinstance(obstacles, ObstacleSet)
                           else ObstacleSet(list(obstacles)))

    def point_at(self, s: float) -> np.ndarray:
        """Return the point at arc length s (clipped to the path)."""
        assert self._path is not None, 'no path: call set_plan first'
        return self._path.point_at(s)

    def lookahead(self, speed: float) -> float:
        """The lookahead at this speed (m/s): fixed, or scaled by it (lookahead_time)."""
        c = self.config
        if c.lookahead_time <= 0.0:
            return c.lookahead
        return float(np.clip(abs(speed) * c.lookahead_time, c.min_lookahead, c.max_lookahead))

    def command(self, x: np.ndarray, *, velocity: np.ndarray | None = None) -> np.ndarray:
        """Return the input [v, omega] for the pose x = (x, y, theta).

        Args:
            x: The robot's pose.
            velocity: The measured (v, omega), when the base reports it: the speed that
                scales the lookahead (else the last command's).

        """
        speed = float(velocity[0]) if velocity is not None else self._last_speed
        u, aim_distance = self._command(np.asarray(x, dtype=float), self.lookahead(speed))
        self.collision_ahead = bool(u.any()) and self._collision_ahead(x, u, aim_distance)
        if self.collision_ahead:
            u = np.zeros(2)
        self._last_speed = float(u[0])
        return u

    def _command(self, x: np.ndarray, lookahead: float) -> tuple[np.ndarray, float]:
        """The pursuit's command with the lookahead, before the collision check.

        Returns:
            The command, and the distance from the robot to its aim point (0 where there is
            none to aim at).

        """
        c = self.config
        assert self._path is not None, 'no path: call set_plan first'
        p = x[:2]
        theta = float(x[2])
        self._progress = project_ahead(self._path.points, self._progress, p, lookahead)
        end = self._path.points[-1]
        to_end = float(np.linalg.norm(end - p))
        remaining = self.length - self._progress
        if remaining <= lookahead and to_end <= c.goal_tolerance:
            return np.zeros(2), 0.0
        aim = self.point_at(self._progress + lookahead)
        if remaining <= lookahead:
            aim = end
        delta = aim - p
        distance = float(np.linalg.norm(delta))
        if distance < 1e-9:
            return np.zeros(2), distance
        alpha = float(wrap_angle(math.atan2(delta[1], delta[0]) - theta))
        if abs(alpha) > c.turn_in_place:
            rate = min(c.turn_rate, c.omega_max) if c.turn_rate > 0.0 else c.omega_max
            return np.array([0.0, math.copysign(rate, alpha)]), distance
        v = self._regulated_speed(alpha, distance, remaining, to_end, lookahead)
        omega = 2.0 * v * math.sin(alpha) / max(distance, 1e-6)
        if abs(omega) > c.omega_max:
            # Keep the arc's curvature: scale both inputs down together.
            v *= c.omega_max / abs(omega)
            omega = math.copysign(c.omega_max, omega)
        return np.array([v, omega]), distance

    def _regulated_speed(self, alpha: float, distance: float, remaining: float,
                         to_end: float, lookahead: float) -> float:
        """The speed: v_max, regulated by the arc's curvature and on the approach to the end.

        In Nav2's order: the curvature's scaling, not below regulated_min_speed, then the
        approach's, not below min_approach_speed, then at most v_max.
        """
        c = self.config
        v = c.v_max
        if c.regulated_min_radius > 0.0:
            curvature = 2.0 * abs(math.sin(alpha)) / max(distance, 1e-6)
            if curvature * c.regulated_min_radius > 1.0:
                v *= 1.0 / (curvature * c.regulated_min_radius)
            v = max(v, c.regulated_min_speed)
        if c.approach_distance > 0.0:
            if remaining < c.approach_distance:
                approach = max(v * to_end / c.approach_distance, c.min_approach_speed)
                v = min(v, approach)
        elif remaining <= lookahead:
            v = min(v, c.slowdown * to_end)
        return min(v, c.v_max)

    def _collision_ahead(self, x: np.ndarray, u: np.ndarray, aim_distance: float) -> bool:
        """Whether the footprint meets an obstacle on the command's arc (collision_time).

        As Nav2's RPP projects its command: the pose now, then poses every collision_step
        metres of the arc (or of the farthest vertex's turn in place) up to collision_time
        seconds ahead, and no farther than the aim point's distance.
        """
        c = self.config
        if c.collision_time <= 0.0 or not len(self._obstacles):
            return False
        v, omega = float(u[0]), float(u[1])
        if abs(v) > 1e-9:
            reach = min(abs(v) * c.collision_time, aim_distance)
            times = np.arange(0, int(reach / c.collision_step) + 1) * (c.collision_step / abs(v))
        else:
            radius = max(c.footprint.radius, c.collision_step)
            step = c.collision_step / (radius * abs(omega))
            times = np.arange(0, int(c.collision_time / step) + 1) * step
        poses = np.array([unicycle_arc(x, v, omega, float(t)) for t in times])
        separation, _ = polygon_separation(c.footprint.at_poses(poses), self._obstacles)
        return bool(np.any(separation <= 0.0))

