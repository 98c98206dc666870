# SPDX-License-Identifier: Apache-2.0
"""The simulated robot base: velocity commands in, motion out, as its `Reality` says.

The unicycle_simulator node and the ROS-free rollout both step a `Base`, so the suites
measure the plant the nodes drive; a physics plant would offer the same calls.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Sequence

import numpy as np

from mpc_local_planner.core.models import Unicycle, unicycle_arc
from mpc_local_planner.sim.commands import CommandQueue
from mpc_local_planner.sim.reality import Reality

__all__ = ['Base']


@dataclass
class Base:
    """A robot base driven by velocity commands, as `Reality` says a real one behaves.

    Time is the caller's (seconds, from 0 at start). `command` hands a command over at a
    time; `advance` integrates up to a later time in sub-steps of ``dt``: the command in
    force at each sub-step is the last one sent at least ``latency`` earlier (zero before
    any), saturated to the model's bounds; the wheels' velocity follows it through the lag
    and the acceleration limits; the true pose moves on the exact arc of that velocity,
    odometry on its drifted copy. With an ideal reality the base is the model: ``advance``
    by h after ``command(u)`` equals ``model.step(x, u, h)`` (RK4 of the same unicycle, to
    its rounding), so that ideal runs stay what they were.

    Args:
        model: the unicycle (its input bounds are the motor drivers' saturation).
        reality: how far from ideal the base is.
        pose: the start pose (x, y, theta).
        dt: the sub-step (s): the simulator's tick, 0.01 s in the rollout.

    """

    model: Unicycle
    reality: Reality
    pose: np.ndarray
    dt: float = 0.01
    time: float = 0.0
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(2))
    odom_pose: np.ndarray = field(init=False)
    _commands: CommandQueue = field(init=False, repr=False)
    _rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Start at rest with odometry at the true pose."""
        if not (math.isfinite(self.dt) and self.dt > 0):
            msg = f'dt must be > 0, got {self.dt}'
            raise ValueError(msg)
        self.pose = np.asarray(self.pose, dtype=float)[:3].copy()
        self.odom_pose = self.pose.copy()
        self._commands = CommandQueue()
        self._rng = np.random.default_rng(self.reality.seed)

    def command(self, u: Sequence[float], t: float | None = None) -> None:
        """Send the command u at time t (default: now); it acts from t + latency.

        A command that is not two finite numbers is a broken sender: it is taken as zero
        (stop), as the simulator node does (`CommandQueue`).
        """
        self._commands.send(u, self.time if t is None else t, self.model, self.reality.latency)

    def stop(self, t: float | None = None) -> None:
        """Send a zero command (a command timeout, a dead controller)."""
        self.command(np.zeros(2), t)

    @property
    def target(self) -> np.ndarray:
        """The command reaching the motors now."""
        return self._commands.applied

    def advance(self, until: float) -> None:
        """Integrate from the base's time up to until (a whole number of sub-steps, at most).

        With an ideal base the velocity is the command (no sub-steps are needed: one exact
        RK4 step of the whole interval, as the model's step).
        """
        span = float(until) - self.time
        if span <= 1e-12:
            return
        if self.reality.ideal_base:
            self._commands.take(until)
            self.velocity = self._commands.applied
            self.pose = self.model.step(self.pose, self.velocity, span)
            self.odom_pose = self.pose.copy()
            self.time = float(until)
            return
        steps = max(int(math.ceil(span / self.dt - 1e-9)), 1)
        dt = span / steps
        for _ in range(steps):
            end = self.time + dt
            # a command reaching the motors inside the sub-step acts from its instant, not
            # from the next sub-step: the latency is the reality's whatever the tick
            while (arrival := self._commands.next_arrival) is not None \
                    and self.time + 1e-9 < arrival < end - 1e-9:
                self._commands.take(self.time)
                self._move(arrival - self.time)
            self._commands.take(self.time)
            self._move(end - self.time)
        self.time = float(until)

    def odometry(self) -> tuple[np.ndarray, np.ndarray]:
        """Return what odometry reports now: (pose with noise and drift, measured twist).

        The twist is the wheels' velocity with the drift's scale error (what the encoders
        count), without the pose's white noise.
        """
        pose = self.odom_pose.copy()
        std_position, std_heading = self.reality.odom_noise
        if std_position > 0.0 or std_heading > 0.0:
            pose += self._rng.normal(0.0, 1.0, 3) * np.array(
                [std_position, std_position, std_heading])
        return pose, self.twist()

    def twist(self) -> np.ndarray:
        """Return the twist odometry reports (as odometry() does, without drawing noise)."""
        scale, bias = self.reality.odom_drift
        v, omega = (float(u) for u in self.velocity)
        return np.array([(1.0 + scale) * v, omega + bias * abs(v)])

    def _move(self, dt: float) -> None:
        """Move the wheels and the poses over dt with the command in force."""
        self._follow(dt)
        v, omega = (float(u) for u in self.velocity)
        self.pose = unicycle_arc(self.pose, v, omega, dt)
        scale, bias = self.reality.odom_drift
        self.odom_pose = unicycle_arc(self.odom_pose, (1.0 + scale) * v,
                                        omega + bias * abs(v), dt)
        self.time += dt

    def _follow(self, dt: float) -> None:
        """Move the wheels' velocity toward the command over dt: lag, then rate limits."""
        target = self._commands.applied
        wanted = target.copy()
        for i, tau in enumerate(self.reality.lag):
            if tau > 0.0:
                wanted[i] = self.velocity[i] + (target[i] - self.velocity[i]) * (
                    1.0 - math.exp(-dt / tau))
        limit = np.asarray(self.reality.acceleration, dtype=float) * dt
        self.velocity = self.velocity + np.clip(wanted - self.velocity, -limit, limit)
