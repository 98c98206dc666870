# SPDX-License-Identifier: Apache-2.0
"""The base controller, as ros2_control's diff_drive_controller does it (Jazzy).

`DiffDrive` turns a twist command into wheel speeds at the controller's update rate:
a command older than ``cmd_vel_timeout`` becomes zero (the base brakes), the linear and the
angular command each pass its speed limiter (acceleration limited against the last
command, then velocity), and each side's wheels turn at (v -+ omega s / 2) / r with the
controller's wheel separation s (the URDF's times ``wheel_separation_multiplier``).

`WheelOdometry` integrates the pose from the wheels' joint angles as the controller's
odometry does (position feedback): the mean angle of each side's wheels times the radius,
increments into a linear (mean) and an angular ((right - left) / s) step, integrated
exactly on the arc (second-order Runge-Kutta when the turn is below 1e-6 rad); its twist
is the rolling mean of the last ``velocity_rolling_window_size`` updates. So odometry
believes the wheels: when they slip or scrub, it drifts from the true pose.

A robot's odometry is rarely the wheels' alone: the Jackal's stack fuses them with its IMU
(jackal/jackal ``jackal_control/config/robot_localization.yaml``: an EKF taking the wheels'
velocities and the IMU's orientation and yaw rate), and the Create 3 under the small robot
fuses its wheels, IMU and optical flow. `WheelOdometry.update` therefore takes an optional
heading change from a gyro: the turn is then the gyro's, the distance still the wheels'.
That is what such a filter converges to when it trusts the gyro for yaw (a skid-steer's
wheels are the worst sensor of it), without the filter's transients.
"""

from __future__ import annotations

from collections import deque
import math

import numpy as np

from mpc_local_planner.sim.physics.robots import DriveLimits

__all__ = ['DiffDrive', 'WheelOdometry']

# Below this turn per update (rad) diff_drive_controller integrates by Runge-Kutta 2.
_EXACT_TURN = 1e-6


class DiffDrive:
    """diff_drive_controller's command path: timeout, speed limiters, wheel speeds."""

    def __init__(self, limits: DriveLimits) -> None:
        self.limits = limits
        self.command = np.zeros(2)  # the last command received (v, omega)
        self.received: float | None = None  # when it was received (s)
        self.limited = np.zeros(2)  # the last limited command (what the wheels are sent)

    def receive(self, u: np.ndarray, now: float) -> None:
        """Take the command u (v, omega) received at now."""
        self.command = np.asarray(u, dtype=float)[:2].copy()
        self.received = float(now)

    def update(self, now: float, period: float) -> tuple[float, float]:
        """Return the (left, right) wheel speeds (rad/s) for the update at now.

        A command older than cmd_vel_timeout (or none yet) is zero; each component is then
        limited in acceleration against the last limited command, then in velocity.
        """
        stale = self.received is None or now - self.received > self.limits.cmd_vel_timeout
        wanted = np.zeros(2) if stale else self.command.copy()
        step = np.asarray(self.limits.max_acceleration, dtype=float) * period
        wanted = np.clip(wanted, self.limited - step, self.limited + step)
        top = np.asarray(self.limits.max_velocity, dtype=float)
        self.limited = np.clip(wanted, -top, top)
        v, omega = (float(c) for c in self.limited)
        half = 0.5 * omega * self.limits.wheel_separation
        radius = self.limits.wheel_radius
        return (v - half) / radius, (v + half) / radius


class WheelOdometry:
    """diff_drive_controller's odometry from the wheels' positions.

    Args:
        limits: The controller's separation, radius and rolling window.
        pose: The start pose (x, y, theta).

    """

    def __init__(self, limits: DriveLimits, pose: np.ndarray) -> None:
        self.limits = limits
        self.pose = np.asarray(pose, dtype=float)[:3].copy()
        self._last: tuple[float, float] | None = None
        self._linear: deque[float] = deque(maxlen=limits.velocity_window)
        self._angular: deque[float] = deque(maxlen=limits.velocity_window)

    @property
    def twist(self) -> np.ndarray:
        """The rolling mean of the measured (v, omega)."""
        if not self._linear:
            return np.zeros(2)
        return np.array([sum(self._linear) / len(self._linear),
                         sum(self._angular) / len(self._angular)])

    def update(self, left: float, right: float, period: float,
               gyro_turn: float | None = None) -> None:
        """Integrate from the mean (left, right) wheel angles (rad) over an update of period.

        gyro_turn, when given, is the heading change a gyro measured over the update (rad):
        it replaces the wheels' (fused odometry, see the module docstring).
        """
        left_m = left * self.limits.wheel_radius
        right_m = right * self.limits.wheel_radius
        if self._last is None:
            self._last = (left_m, right_m)
            return
        d_left, d_right = left_m - self._last[0], right_m - self._last[1]
        self._last = (left_m, right_m)
        linear = 0.5 * (d_right + d_left)
        angular = (d_right - d_left) / self.limits.wheel_separation
        if gyro_turn is not None:
            angular = float(gyro_turn)
        x, y, theta = (float(c) for c in self.pose)
        if abs(angular) < _EXACT_TURN:
            heading = theta + 0.5 * angular
            x += linear * math.cos(heading)
            y += linear * math.sin(heading)
        else:
            radius = linear / angular
            x += radius * (math.sin(theta + angular) - math.sin(theta))
            y -= radius * (math.cos(theta + angular) - math.cos(theta))
        self.pose = np.array([x, y, theta + angular])
        if period > 0.0:
            self._linear.append(linear / period)
            self._angular.append(angular / period)
