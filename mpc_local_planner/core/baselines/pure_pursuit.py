# Copyright 2026 mpc_local_planner developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Classic lookahead pure pursuit of a polyline for a unicycle: a baseline with no obstacles.

The follower keeps a monotone progress along the polyline (the closest point ahead of the
last one), aims at the point one lookahead distance further on, and commands the arc through
it: omega = 2 v sin(alpha) / L. It turns in place when the aim point is behind it, slows down
near the end and stops there. It knows nothing of obstacles: where the path cuts close to
one, so may the robot.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from mpc_local_planner.core.paths import distinct_waypoints, project_ahead, wrap_angle

__all__ = ['PurePursuit', 'PurePursuitConfig']


@dataclass(frozen=True)
class PurePursuitConfig:
    """Settings of `PurePursuit`.

    Attributes:
        lookahead: distance along the path from the robot's projection to the aim point, m.
        v_max: forward speed limit, m/s.
        omega_max: turn rate limit, rad/s.
        goal_tolerance: the follower stops within this distance of the path's end, m.
        slowdown: gain of v = slowdown * distance-to-end near the end, 1/s.
        turn_in_place: above this |alpha| (rad) the robot turns in place first.

    """

    lookahead: float = 0.4
    v_max: float = 0.31
    omega_max: float = 1.9
    goal_tolerance: float = 0.03
    slowdown: float = 1.0
    turn_in_place: float = math.pi / 2

    def __post_init__(self) -> None:
        """Refuse non-positive settings."""
        for name in ('lookahead', 'v_max', 'omega_max', 'goal_tolerance', 'slowdown',
                     'turn_in_place'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                msg = f'{name} must be > 0 and finite, got {value}'
                raise ValueError(msg)


class PurePursuit:
    """Pure-pursuit follower of an (M, 2) polyline.

    Args:
        waypoints: (M, 2) polyline, M >= 2 distinct points.
        config: the follower's settings.

    """

    def __init__(self, waypoints: np.ndarray, config: PurePursuitConfig | None = None) -> None:
        pts = distinct_waypoints(waypoints, tolerance=1e-9)
        self.config = config or PurePursuitConfig()
        self._pts = pts
        seg = np.diff(pts, axis=0)
        self._seg = seg
        self._seg_len = np.linalg.norm(seg, axis=1)
        self._cum = np.concatenate([[0.0], np.cumsum(self._seg_len)])
        self._progress = 0.0

    @property
    def length(self) -> float:
        """Length of the polyline, metres."""
        return float(self._cum[-1])

    @property
    def progress(self) -> float:
        """Arc length of the robot's current projection on the polyline, metres."""
        return self._progress

    def reset(self) -> None:
        """Start again from the beginning of the path."""
        self._progress = 0.0

    def point_at(self, s: float) -> np.ndarray:
        """Return the point at arc length s (clipped to the path)."""
        s = float(np.clip(s, 0.0, self._cum[-1]))
        i = int(np.clip(np.searchsorted(self._cum, s, side='right') - 1, 0, len(self._seg) - 1))
        t = (s - self._cum[i]) / self._seg_len[i]
        return self._pts[i] + t * self._seg[i]

    def _project(self, p: np.ndarray) -> float:
        """Closest arc length to p among the points not behind the current progress."""
        return project_ahead(self._pts, self._progress, p, self.config.lookahead)

    def command(self, x: np.ndarray) -> np.ndarray:
        """Return the input [v, omega] for the pose x = (x, y, theta)."""
        c = self.config
        p = np.asarray(x[:2], dtype=float)
        theta = float(x[2])
        self._progress = self._project(p)
        end = self._pts[-1]
        to_end = float(np.linalg.norm(end - p))
        remaining = self.length - self._progress
        if remaining <= c.lookahead and to_end <= c.goal_tolerance:
            return np.zeros(2)
        aim = self.point_at(self._progress + c.lookahead)
        if remaining <= c.lookahead:
            aim = end
        delta = aim - p
        distance = float(np.linalg.norm(delta))
        if distance < 1e-9:
            return np.zeros(2)
        alpha = float(wrap_angle(math.atan2(delta[1], delta[0]) - theta))
        if abs(alpha) > c.turn_in_place:
            return np.array([0.0, math.copysign(c.omega_max, alpha)])
        v = c.v_max
        if remaining <= c.lookahead:
            v = min(v, c.slowdown * to_end)
        omega = 2.0 * v * math.sin(alpha) / max(distance, 1e-6)
        if abs(omega) > c.omega_max:
            # Keep the arc's curvature: scale both inputs down together.
            v *= c.omega_max / abs(omega)
            omega = math.copysign(c.omega_max, omega)
        return np.array([v, omega])
