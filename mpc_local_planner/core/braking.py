# SPDX-License-Identifier: Apache-2.0
"""Stop a moving robot along its last verified plan, within the base's deceleration limits.

A zero command is not a stop: a base with deceleration limits (and a command latency) coasts
on, straight ahead or on its last arc, into space no plan has checked. Every plan the MPC
applies has been verified collision-free over its whole horizon and ends at rest (x_N =
g_p(s), u_N = 0), so the curve it traces is known to be clear. A unicycle traces the same
curve at any speed if v and omega are scaled alike, so the robot brakes ON that curve: the
command is sigma u_plan(tau), where tau runs through the plan at the scaled speed (dtau =
sigma dt) and sigma falls from 1 to 0 at the rate that keeps each input's deceleration within
its limit. The robot stops within the plan's curve (it brakes at least as hard as the plan,
which also stops by its end), so the stop stays where the verification was.

What it does not cover: an obstacle that appears on that curve after the plan was verified
(nothing can stop a robot faster than its base allows) and the base's own lag (the base
follows the braking commands late, as it followed the plan's).
"""

from __future__ import annotations

import copy
import math

import numpy as np

from mpc_local_planner.core.models import held_input, RobotModel

__all__ = ['Brake', 'PREVIEW_SUBSTEPS']

# Integration steps per MPC step of a braking preview (the states a stop passes through).
PREVIEW_SUBSTEPS = 4


class Brake:
    """Braking along a plan: start it with the plan's inputs, then ask for commands.

    Args:
        max_decel: the base's deceleration limits (m/s^2, rad/s^2); inf: stop at once.

    """

    def __init__(self, max_decel: tuple[float, float]) -> None:
        self.max_decel = np.asarray(max_decel, dtype=float)
        self._inputs: np.ndarray | None = None
        self._first: np.ndarray | None = None
        self._h = 0.0
        self._tau = 0.0
        self._scale = 0.0
        self._rate = math.inf

    @property
    def active(self) -> bool:
        """The robot is braking (the scale has not reached zero)."""
        return self._inputs is not None and self._scale > 0.0

    def start(self, inputs: np.ndarray, h: float, elapsed: float,
              first: np.ndarray | None = None) -> None:
        """Brake along a plan of piecewise constant inputs (N, 2) of step h, elapsed s in.

        With first, the plan is a first-order hold (MpcConfig.input_hold): its velocity ramps
        from first to inputs[0] over the first step, then from knot to knot; the curve is
        the same at any speed scale, so braking on it works alike.

        The rate at which the scale falls makes the largest input of the plan decelerate at
        its limit: every command's |d(sigma u_i)/dt| from braking is at most max_decel_i.
        (The plan's own accelerations come on top, scaled by sigma: within its max_accel.)
        """
        inputs = np.asarray(inputs, dtype=float).reshape(-1, 2)
        self._first = None if first is None else np.asarray(first, dtype=float).reshape(2)
        if self._first is not None:
            inputs_all = np.vstack([self._first.reshape(1, 2), inputs])
        else:
            inputs_all = inputs
        peak = np.max(np.abs(inputs_all), axis=0) if len(inputs_all) else np.zeros(2)
        rates = np.where(peak > 0.0, self.max_decel / np.maximum(peak, 1e-12), math.inf)
        self._rate = float(np.min(rates))
        self._inputs = inputs
        self._h = float(h)
        self._tau = max(float(elapsed), 0.0)
        self._scale = 1.0 if math.isfinite(self._rate) else 0.0

    def stop(self) -> None:
        """Forget the plan (a fresh solve, a new plan, arrival)."""
        self._inputs = None
        self._scale = 0.0

    def command(self, dt: float) -> np.ndarray:
        """Return the braking command dt after the previous one (zero once stopped)."""
        if self._inputs is None or self._scale <= 0.0:
            return np.zeros(2)
        dt = max(float(dt), 0.0)
        self._tau += self._scale * dt
        self._scale = max(self._scale - self._rate * dt, 0.0)
        if self._h <= 0 or self._scale <= 0.0:
            return np.zeros(2)
        # the plan's input (a first-order hold: its ramp through first, u_0, ..., u_{N-1})
        u = held_input(self._inputs, self._tau / self._h, self._first)
        return np.zeros(2) if u is None else self._scale * u

    def preview(self, x: np.ndarray, model: RobotModel, step: float, stages: int,
                substeps: int = PREVIEW_SUBSTEPS) -> np.ndarray:
        """Return (stages+1, nx): the states at t = 0, step, ... of braking from x, as commanded.

        The commands this brake would give from now on (a copy of it is run: this one is
        left as it is), integrated by the model in substeps per step. Not braking: standing.
        """
        x = np.asarray(x, dtype=float).reshape(-1)
        if not self.active:
            return np.tile(x, (stages + 1, 1))
        brake, dt = copy.deepcopy(self), step / substeps
        states = [x]
        for _ in range(stages):
            for _ in range(substeps):
                x = model.step(x, brake.command(dt), dt)
            states.append(x)
        return np.array(states)
