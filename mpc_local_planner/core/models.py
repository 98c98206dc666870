# SPDX-License-Identifier: Apache-2.0
"""Robot models: the dynamics written once, as CasADi Functions.

The MPC's equality constraints and the simulator both call the same RK4 Function, so there
is no second copy of the equations (the habit of do-mpc). A model also knows its steady
states: the paper's g_p maps a path configuration to the steady state (x_s, u_s) the
prediction must end in, and that map is a property of the robot, not of the MPC.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import lru_cache
import math
from typing import Any

import casadi as ca
import numpy as np

__all__ = ['RobotModel', 'STRAIGHT_OMEGA', 'Unicycle', 'held_input',
           'ramp_rk4', 'rk4', 'unicycle_arc']

Symbolic = Any  # a CasADi SX/MX expression or a NumPy array


def rk4(rhs: ca.Function, x: Symbolic, u: Symbolic, h: float) -> Symbolic:
    """Integrate dx/dt = rhs(x, u) over one step h with constant u (classical RK4)."""
    k1 = rhs(x, u)
    k2 = rhs(x + h / 2 * k1, u)
    k3 = rhs(x + h / 2 * k2, u)
    k4 = rhs(x + h * k3, u)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def ramp_rk4(rhs: ca.Function, x: Symbolic, q: Symbolic, u: Symbolic, h: float) -> Symbolic:
    """Integrate dx/dt = rhs(x, v(t)) over one step h with v ramping linearly from q to u.

    Classical RK4 with the input at the times it samples: q at the start, the mean (q + u) / 2
    at the midpoint, u at the end (a first-order hold; q = u is rk4).
    """
    mid = (q + u) / 2
    k1 = rhs(x, q)
    k2 = rhs(x + h / 2 * k1, mid)
    k3 = rhs(x + h / 2 * k2, mid)
    k4 = rhs(x + h * k3, u)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def held_input(inputs: np.ndarray, tau: float,
               first: np.ndarray | None = None) -> np.ndarray | None:
    """Return the input tau steps into a plan of inputs (N, nu), or None past its end.

    A zero hold (first None): inputs[l] over step l (a step's end, to rounding, is the next
    step). A first-order hold: the ramp from first to inputs[0] over step 0, then from knot
    to knot (MpcConfig.input_hold). What the controller commands between solves, and what
    braking scales, are read here.
    """
    inputs = np.asarray(inputs, dtype=float)
    if first is None:
        index = int(tau + 1e-9)
        return inputs[index].copy() if index < len(inputs) else None
    index = int(tau)
    if index >= len(inputs):
        return None
    start = np.asarray(first, dtype=float) if index == 0 else inputs[index - 1]
    return start + (tau - index) * (inputs[index] - start)


class RobotModel(ABC):
    """What the MPC needs of a robot: dynamics, input bounds, the pose map g and g_p.

    A state's first three components are the pose (x, y, theta) in this package; other
    models may add states after them (a bicycle's steering angle, a velocity).

    A model is immutable and hashable by value (a frozen dataclass): its discretisations
    and the NLPs built on it are kept per model (core/mpc/built_nlps.py).
    """

    state_names: tuple[str, ...]
    input_names: tuple[str, ...]

    @property
    def nx(self) -> int:
        """Number of states."""
        return len(self.state_names)

    @property
    def nu(self) -> int:
        """Number of inputs."""
        return len(self.input_names)

    @property
    @abstractmethod
    def u_min(self) -> np.ndarray:
        """Lower input bounds."""

    @property
    @abstractmethod
    def u_max(self) -> np.ndarray:
        """Upper input bounds."""

    @abstractmethod
    def rhs(self, x: Symbolic, u: Symbolic) -> Symbolic:
        """Continuous dynamics dx/dt as a CasADi expression."""

    @abstractmethod
    def steady_state(self, pose: Symbolic) -> tuple[Symbolic, Symbolic]:
        """Return (x_s, u_s): the steady state whose pose is pose (the paper's g_p)."""

    @property
    def x_min(self) -> np.ndarray:
        """Lower state bounds (unbounded unless a model says otherwise)."""
        return np.full(self.nx, -np.inf)

    @property
    def x_max(self) -> np.ndarray:
        """Upper state bounds."""
        return np.full(self.nx, np.inf)

    @property
    def angle_index(self) -> int:
        """Index of the heading in the state, the one component that wraps at +-pi."""
        return 2

    def rhs_function(self) -> ca.Function:
        """Return the continuous dynamics as a CasADi Function f(x, u)."""
        x = ca.SX.sym('x', self.nx)
        u = ca.SX.sym('u', self.nu)
        return ca.Function('f', [x, u], [self.rhs(x, u)], ['x', 'u'], ['dx'])

    def discrete(self, h: float) -> ca.Function:
        """Return the RK4 discretisation at step h as a CasADi Function F(x, u) -> x_next."""
        return _discrete(self, float(h))

    def discrete_ramp(self, h: float) -> ca.Function:
        """Return the first-order-hold step F(x, q, u) -> x_next: the input ramps from q to u.

        Two RK4 sub-steps of h / 2 (ramp_rk4), so that a turn at the Jackal's limits over a
        ramp stays within a millimetre of the exact motion.
        """
        return _discrete_ramp(self, float(h))

    def saturate(self, u: np.ndarray) -> np.ndarray:
        """Clip an input to the bounds (what real motor drivers do)."""
        return np.clip(np.asarray(u, dtype=float), self.u_min, self.u_max)

    def step(self, x: np.ndarray, u: np.ndarray, h: float) -> np.ndarray:
        """Advance the state by h with the input saturated: the simulator's make_step."""
        u_applied = self.saturate(u)
        return np.asarray(self.discrete(h)(x, u_applied), dtype=float).reshape(-1)

    def pose(self, x: np.ndarray) -> np.ndarray:
        """Return g(x): the configuration (x, y, theta) of a state."""
        return np.asarray(x, dtype=float)[:3]


@lru_cache(maxsize=64)
def _discrete(model: RobotModel, h: float) -> ca.Function:
    x = ca.SX.sym('x', model.nx)
    u = ca.SX.sym('u', model.nu)
    x_next = rk4(model.rhs_function(), x, u, h)
    return ca.Function('F', [x, u], [x_next], ['x', 'u'], ['x_next'])


@lru_cache(maxsize=64)
def _discrete_ramp(model: RobotModel, h: float) -> ca.Function:
    x = ca.SX.sym('x', model.nx)
    q = ca.SX.sym('q', model.nu)
    u = ca.SX.sym('u', model.nu)
    rhs = model.rhs_function()
    mid = (q + u) / 2
    x_mid = ramp_rk4(rhs, x, q, mid, h / 2)
    x_next = ramp_rk4(rhs, x_mid, mid, u, h / 2)
    return ca.Function('F_ramp', [x, q, u], [x_next], ['x', 'q', 'u'], ['x_next'])


@dataclass(frozen=True)
class Unicycle(RobotModel):
    """Differential-drive robot: x = [p_x, p_y, theta], u = [v, omega] (the paper's model).

    Defaults are the paper's Turtlebot 4 bounds. Every pose is a steady state with u = 0,
    so g_p(s) = p(s) and u_s = 0.
    """

    v_max: float = 0.31
    omega_max: float = 1.9
    v_min: float | None = None  # None: -v_max (the paper drives backwards too)

    state_names = ('x', 'y', 'theta')
    input_names = ('v', 'omega')

    def __post_init__(self) -> None:
        if not (self.v_max > 0 and self.omega_max > 0):
            msg = f'v_max and omega_max must be > 0, got {self.v_max}, {self.omega_max}'
            raise ValueError(msg)
        if self.v_min is not None and not self.v_min < self.v_max:
            msg = f'v_min must be < v_max, got {self.v_min} >= {self.v_max}'
            raise ValueError(msg)

    @property
    def u_min(self) -> np.ndarray:
        """Lower input bounds [v_min, -omega_max]."""
        v_min = -self.v_max if self.v_min is None else self.v_min
        return np.array([v_min, -self.omega_max])

    @property
    def u_max(self) -> np.ndarray:
        """Upper input bounds [v_max, omega_max]."""
        return np.array([self.v_max, self.omega_max])

    def rhs(self, x: Symbolic, u: Symbolic) -> Symbolic:
        """Unicycle kinematics [v cos(theta), v sin(theta), omega]."""
        return ca.vertcat(u[0] * ca.cos(x[2]), u[0] * ca.sin(x[2]), u[1])

    def steady_state(self, pose: Symbolic) -> tuple[Symbolic, Symbolic]:
        """Stand still at the pose."""
        return pose, ca.DM.zeros(2)


# Below this yaw rate (rad/s) the arc is taken as the straight line (no division by omega).
STRAIGHT_OMEGA = 1e-9


def unicycle_arc(pose: np.ndarray, v: float, omega: float, dt: float) -> np.ndarray:
    """Return pose (x, y, theta) moved for dt seconds at the constant twist (v, omega).

    The exact unicycle motion: a circular arc of radius v / omega, or the straight line
    when omega is (numerically) zero. The heading is not wrapped (as the odometry's).
    """
    x, y, theta = (float(c) for c in pose[:3])
    turn = omega * dt
    if abs(omega) < STRAIGHT_OMEGA:
        return np.array([x + v * dt * math.cos(theta), y + v * dt * math.sin(theta),
                         theta + turn])
    radius = v / omega
    return np.array([x + radius * (math.sin(theta + turn) - math.sin(theta)),
                     y - radius * (math.cos(theta + turn) - math.cos(theta)),
                     theta + turn])
