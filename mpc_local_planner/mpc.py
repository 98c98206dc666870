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

"""The paper's path-reference MPC (problem (6)) and the tracking-MPC baseline.

Both are one NLP, built once with CasADi's nlpsol over SX: the measured state, the path, the
weights and the obstacles are solver *parameters*, so a control step only fills in numbers.

Decision variables, in this order: X (N+1 states), U (N inputs; u_N is the steady-state
input, a constant), the path progress s (PathReferenceMPC) and, per obstacle slot and step
l = 1..N, a Farkas multiplier mu >= 0 with sum(mu) = 1 and (A p_l - b)^T mu >= margin.

The closed-loop guarantee rests on V_N not increasing. The proof compares the optimum at
k+1 with a candidate: the previous solution shifted by one step, with the terminal steady
state appended. A local NLP solver may return something worse than that candidate, or fail;
this module therefore always builds the candidate, and applies whichever of the two is
verified feasible and cheaper. So V_N is non-increasing by construction, not by luck.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import time
from typing import NamedTuple, Sequence

import casadi as ca
import numpy as np

from .config import MpcConfig, STRUCTURAL_FIELDS
from .models import RobotModel
from .obstacles import ConvexPolygon
from .paths import ReferencePath, wrap_angle

__all__ = ['MpcSolution', 'PathReferenceMPC', 'TrackingMPC']

# Constraint-violation bound for accepting a solution or a candidate (metres, rad, m/s).
FEASIBILITY_TOLERANCE = 1e-5
# Slack on the closed-loop decrease check, relative to V_N plus an absolute floor.
LYAPUNOV_TOLERANCE = 1e-6


class MpcSolution(NamedTuple):
    """Result of one control step.

    Attributes:
        u0: the input to apply now (always within the model's bounds).
        x_pred: (N+1, nx) predicted states.
        u_pred: (N, nu) predicted inputs.
        s: path progress s_k of the artificial steady state (nan for TrackingMPC).
        value: V_N, the cost of what is applied (the Lyapunov function).
        success: the NLP solver converged to a verified solution.
        status: the solver's return status, or why the candidate was used.
        solve_time_s: wall time of the NLP solve.
        iterations: solver iterations.
        source: 'solver', 'candidate' (the proof's shifted solution) or 'stop'.
        lyapunov_ok: V_N(x_k) <= V_N(x_{k-1}) - l(x_{k-1}, u_{k-1}) + tolerance, or None at
            the first step after a reset.
        failures: consecutive steps without a verified solver solution.

    """

    u0: np.ndarray
    x_pred: np.ndarray
    u_pred: np.ndarray
    s: float
    value: float
    success: bool
    status: str
    solve_time_s: float
    iterations: int
    source: str
    lyapunov_ok: bool | None
    failures: int


@dataclass
class _Plan:
    """A predicted trajectory with everything needed to shift it."""

    x: np.ndarray  # (N+1, nx)
    u: np.ndarray  # (N, nu)
    s: float
    mu: np.ndarray  # flat multipliers
    value: float


class _MpcBase:
    """Shared OCP machinery; subclasses choose the terminal condition and offset cost."""

    uses_path: bool = True

    def __init__(
        self,
        model: RobotModel,
        config: MpcConfig | None = None,
        *,
        obstacles: Sequence[ConvexPolygon] = (),
        path: ReferencePath | None = None,
        target: np.ndarray | None = None,
    ) -> None:
        self._model = model
        self._config = config or MpcConfig()
        self._raw_obstacles: list[ConvexPolygon] = []
        self._inflated: list[ConvexPolygon] = []
        self._path = path
        self._target = None if target is None else np.asarray(target, dtype=float)
        self._slots = self._config.obstacle_slots
        self._solver: ca.Function | None = None
        self._structure_key: tuple | None = None
        self.set_obstacles(obstacles)
        self.reset()

    # ----------------------------------------------------------------- configuration
    @property
    def config(self) -> MpcConfig:
        """The settings in force."""
        return self._config

    @property
    def model(self) -> RobotModel:
        """The robot model."""
        return self._model

    @property
    def path(self) -> ReferencePath | None:
        """The reference path in force (None before one is set)."""
        return self._path

    @property
    def inflated_obstacles(self) -> list[ConvexPolygon]:
        """The obstacles as the constraints see them (grown by radius and margin)."""
        return list(self._inflated)

    def update_config(self, config: MpcConfig) -> None:
        """Apply new settings at the next solve; shape changes rebuild the NLP there."""
        old = self._config
        self._config = config
        if any(getattr(old, name) != getattr(config, name) for name in STRUCTURAL_FIELDS):
            self._solver = None
            self._slots = max(self._slots, config.obstacle_slots)
            self.reset()
        if old.inflation(self._model.u_max[0]) != config.inflation(self._model.u_max[0]):
            self.set_obstacles(self._raw_obstacles)

    def set_obstacles(self, obstacles: Sequence[ConvexPolygon]) -> None:
        """Replace the obstacles (as described, not inflated)."""
        faces = self._config.faces_per_obstacle
        for obstacle in obstacles:
            if obstacle.num_faces > faces:
                msg = (f'an obstacle has {obstacle.num_faces} faces, more than '
                       f'faces_per_obstacle={faces}')
                raise ValueError(msg)
        self._raw_obstacles = list(obstacles)
        inflation = self._config.inflation(float(self._model.u_max[0]))
        self._inflated = [o.inflate(inflation) for o in self._raw_obstacles]

    def set_path(self, path: ReferencePath) -> None:
        """Use a new reference path; s restarts at the robot's projection onto it."""
        self._path = path
        self.reset()

    def set_target(self, target: np.ndarray) -> None:
        """Set the target pose (TrackingMPC; PathReferenceMPC takes it from the path)."""
        self._target = np.asarray(target, dtype=float)
        self.reset()

    def reset(self) -> None:
        """Forget the previous solution (warm start, candidate, Lyapunov history)."""
        self._plan: _Plan | None = None
        self._previous_value: float | None = None
        self._previous_stage: float = 0.0
        self._failures = 0

    # ----------------------------------------------------------------- building
    def _structure(self) -> tuple:
        c = self._config
        family = self._path.family if (self.uses_path and self._path) else 'target'
        return (c.horizon, c.step, c.cost_exponent, c.farkas_margin, self._slots,
                c.faces_per_obstacle, c.solver, c.max_iterations, c.tolerance,
                tuple(sorted(c.solver_options.items())), family)

    def _ensure_built(self) -> None:
        key = self._structure()
        if self._solver is None or key != self._structure_key:
            self._build()
            self._structure_key = key

    def _terminal(
        self, x_n: ca.SX, s: ca.SX, p_path: ca.SX, weights: ca.SX
    ) -> tuple[ca.SX, ca.SX]:
        """Return (terminal equality residual, offset cost without its weight)."""
        raise NotImplementedError

    def _num_path_params(self) -> int:
        raise NotImplementedError

    def _build(self) -> None:
        c = self._config
        m = self._model
        n, nx, nu = c.horizon, m.nx, m.nu
        faces, slots = c.faces_per_obstacle, self._slots
        F = m.discrete(c.step)

        # decision variables
        X = ca.SX.sym('X', nx, n + 1)
        U = ca.SX.sym('U', nu, n)
        s = ca.SX.sym('s')
        mu = ca.SX.sym('mu', faces, slots * n)

        # parameters: x0, weights, obstacles (A rows then b), path
        x0 = ca.SX.sym('x0', nx)
        weights = ca.SX.sym('w', 5)
        obs = ca.SX.sym('obs', 3 * faces * slots)
        n_path = self._num_path_params()
        p_path = ca.SX.sym('path', n_path)

        # objective: stage cost towards the terminal (artificial) steady state
        x_s = X[:, n]
        terminal_residual, offset = self._terminal(x_s, s, p_path, weights)
        stage = self._stage_function()
        cost = sum(stage(X[:, i], U[:, i], x_s, weights) for i in range(n))
        cost = cost + weights[4] * offset

        # constraints, each block with its bounds
        g, lbg, ubg = [], [], []

        def add(expr: ca.SX, lower: float | np.ndarray, upper: float | np.ndarray) -> None:
            size = expr.numel()
            g.append(ca.vec(expr))
            lbg.append(np.broadcast_to(lower, (size,)).astype(float))
            ubg.append(np.broadcast_to(upper, (size,)).astype(float))

        add(X[:, 0] - x0, 0.0, 0.0)
        for i in range(n):
            add(X[:, i + 1] - F(X[:, i], U[:, i]), 0.0, 0.0)
        # drop entries that are identically zero (a free steady state): an empty Jacobian
        # row makes the KKT system singular and IPOPT wanders off
        residual = [terminal_residual[i] for i in range(terminal_residual.numel())
                    if not terminal_residual[i].is_zero()]
        if residual:
            add(ca.vertcat(*residual), 0.0, 0.0)
        for j in range(slots):
            base = 3 * faces * j
            A = ca.reshape(obs[base:base + 2 * faces], faces, 2)
            b = obs[base + 2 * faces:base + 3 * faces]
            for i in range(n):
                col = j * n + i
                p = X[0:2, i + 1]
                add(ca.dot(ca.mtimes(A, p) - b, mu[:, col]), c.farkas_margin, ca.inf)
                add(ca.sum1(mu[:, col]), 1.0, 1.0)

        w = ca.veccat(X, U, s, mu)
        params = ca.vertcat(x0, weights, obs, p_path)
        self._lbw, self._ubw = self._variable_bounds(n, faces * slots * n)
        self._lbg = np.concatenate(lbg)
        self._ubg = np.concatenate(ubg)
        nlp = {'x': w, 'p': params, 'f': cost, 'g': ca.vertcat(*g)}
        self._solver = ca.nlpsol('mpc', c.solver if c.solver == 'ipopt' else 'ipopt', nlp,
                                 self._solver_options())
        self._cost_fn = ca.Function('cost', [w, params], [cost])
        self._g_fn = ca.Function('g', [w, params], [ca.vertcat(*g)])
        self._stage_fn = stage
        self._sizes = (nx, nu, n, faces, slots)

    def _stage_function(self) -> ca.Function:
        """Return l(x - x_s, u - u_s) as a Function of (x, u, x_s, weights)."""
        m, q = self._model, self._config.cost_exponent
        x, x_s = ca.SX.sym('x', m.nx), ca.SX.sym('x_s', m.nx)
        u, weights = ca.SX.sym('u', m.nu), ca.SX.sym('w', 5)
        _, u_s = m.steady_state(x_s[:3])
        state_w = ca.vertcat(weights[0], weights[0], weights[1], *([weights[1]] * (m.nx - 3)))
        input_w = ca.vertcat(weights[2], weights[3], *([weights[3]] * (m.nu - 2)))
        cost = ca.dot(state_w, (x - x_s) ** q) + ca.dot(input_w, (u - u_s) ** q)
        return ca.Function('stage', [x, u, x_s, weights], [cost])

    def _solver_options(self) -> dict:
        c = self._config
        options = {
            'print_time': False,
            'ipopt.print_level': 0,
            'ipopt.sb': 'yes',
            'ipopt.max_iter': c.max_iterations,
            'ipopt.tol': c.tolerance,
            'ipopt.acceptable_tol': 1e-6,
            # the initial guess is the proof's candidate, feasible by construction: keep
            # the interior-point iterates near it instead of pushing them off the bounds
            'ipopt.bound_push': 1e-8,
            'ipopt.bound_frac': 1e-8,
            'ipopt.mu_init': 1e-4,
        }
        options.update(c.solver_options)
        return options

    def _variable_bounds(self, n: int, n_mu: int) -> tuple[np.ndarray, np.ndarray]:
        m = self._model
        lbx = np.tile(m.x_min, n + 1)
        ubx = np.tile(m.x_max, n + 1)
        lbu = np.tile(m.u_min, n)
        ubu = np.tile(m.u_max, n)
        lbs, ubs = (0.0, 1.0) if self.uses_path else (0.0, 0.0)
        lb = np.concatenate([lbx, lbu, [lbs], np.zeros(n_mu)])
        ub = np.concatenate([ubx, ubu, [ubs], np.full(n_mu, np.inf)])
        return lb, ub

    # ----------------------------------------------------------------- packing
    def _pack(self, plan: _Plan) -> np.ndarray:
        return np.concatenate([plan.x.reshape(-1), plan.u.reshape(-1), [plan.s], plan.mu])

    def _unpack(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
        nx, nu, n, _, _ = self._sizes
        k = nx * (n + 1)
        x = w[:k].reshape(n + 1, nx)
        u = w[k:k + nu * n].reshape(n, nu)
        s = float(w[k + nu * n])
        mu = w[k + nu * n + 1:]
        return x, u, s, mu

    def _selected_obstacles(self, x0: np.ndarray) -> list[ConvexPolygon]:
        """Return the inflated obstacles the horizon can reach, nearest first."""
        c = self._config
        reach = float(np.max(np.abs(self._model.u_max[:1]))) * c.step * c.horizon + 1e-3
        nearby = []
        for obstacle in self._inflated:
            d = float(obstacle.distance(x0[:2])[0])
            if d <= reach:
                nearby.append((d, obstacle))
        nearby.sort(key=lambda item: item[0])
        return [obstacle for _, obstacle in nearby]

    def _obstacle_params(self, selected: list[ConvexPolygon]) -> np.ndarray:
        faces, slots = self._config.faces_per_obstacle, self._slots
        values = []
        for j in range(slots):
            if j < len(selected):
                # pad by repeating a real face: a padding face with a huge offset would
                # let a multiplier of -1e-9 (within the solver's bound tolerance) buy a
                # fake separation of 1e6 * 1e-9
                o = selected[j]
                rows = np.minimum(np.arange(faces), o.num_faces - 1)
                A, b = o.A[rows], o.b[rows]
            else:
                A = np.zeros((faces, 2))
                b = np.full(faces, -1.0)  # an empty slot: (0 p + 1)^T mu = 1 >= margin
            values.append(np.concatenate([A.reshape(-1, order='F'), b]))
        return np.concatenate(values) if values else np.zeros(0)

    def _multipliers(self, x: np.ndarray, selected: list[ConvexPolygon]) -> np.ndarray:
        """Put each multiplier on the most separating face: a feasible mu for clear points."""
        nx, nu, n, faces, slots = self._sizes
        mu = np.zeros((slots * n, faces))
        for j in range(slots):
            for i in range(n):
                if j < len(selected):
                    face = int(np.argmax(selected[j].A @ x[i + 1, :2] - selected[j].b))
                else:
                    face = 0
                mu[j * n + i, face] = 1.0
        return mu.reshape(-1)

    def _weights(self) -> np.ndarray:
        return np.array(self._config.weights())

    # ----------------------------------------------------------------- solving
    def _initial_s(self, x0: np.ndarray) -> float:
        raise NotImplementedError

    def _unwrap(self, x: np.ndarray) -> np.ndarray:
        """Put the measured heading on the branch nearest the prediction (or the path)."""
        x = np.array(x, dtype=float)
        k = self._model.angle_index
        if self._plan is not None:
            reference = self._plan.x[1, k]
        elif self.uses_path and self._path is not None:
            reference = float(self._path.pose(self._path.project(x[:3]))[2])
        elif self._target is not None:
            reference = float(self._target[2])
        else:
            reference = 0.0
        x[k] = reference + float(wrap_angle(x[k] - reference))
        return x

    def _rollout(self, x0: np.ndarray, u: np.ndarray) -> np.ndarray:
        F = self._model.discrete(self._config.step)
        xs = [x0]
        for u_i in u:
            xs.append(np.asarray(F(xs[-1], u_i)).reshape(-1))
        return np.array(xs)

    def _candidate(self, x0: np.ndarray, selected: list[ConvexPolygon]) -> _Plan:
        """The proof's candidate: shift the last plan and append the terminal steady state."""
        n = self._config.horizon
        if self._plan is None:
            s0 = self._initial_s(x0)
            u = np.zeros((n, self._model.nu))
            x = np.tile(x0, (n + 1, 1))
            x_s = self._terminal_state(s0, x0)
            x[-1] = x_s if x_s is not None else x0
            plan = _Plan(x=x, u=u, s=s0, mu=np.zeros(0), value=math.inf)
        else:
            prev = self._plan
            _, u_s = self._model.steady_state(prev.x[-1, :3])
            u = np.vstack([prev.u[1:], np.asarray(u_s, dtype=float).reshape(1, -1)])
            x = self._rollout(x0, u)
            plan = _Plan(x=x, u=u, s=prev.s, mu=np.zeros(0), value=math.inf)
        plan.mu = self._multipliers(plan.x, selected)
        return plan

    def _terminal_state(self, s: float, x0: np.ndarray) -> np.ndarray | None:
        raise NotImplementedError

    def _violation(self, w: np.ndarray, params: np.ndarray,
                   selected: list[ConvexPolygon]) -> float:
        """Return the largest constraint violation, collisions checked geometrically.

        The geometric check does not trust the multipliers: whatever the solver did with
        them, every predicted position l = 1..N must clear every selected obstacle.
        """
        g = np.asarray(self._g_fn(w, params)).reshape(-1)
        viol = np.maximum(self._lbg - g, 0) + np.maximum(g - self._ubg, 0)
        viol_w = np.maximum(self._lbw - w, 0) + np.maximum(w - self._ubw, 0)
        worst = max(np.max(viol, initial=0.0), np.max(viol_w, initial=0.0))
        positions = self._unpack(w)[0][1:, :2]
        for obstacle in selected:
            depth = self._config.farkas_margin - obstacle.signed_distance_lower_bound(positions)
            worst = max(worst, float(np.max(depth, initial=0.0)))
        return float(worst)

    def _run_solver(
        self, w0: np.ndarray, params: np.ndarray, selected: list[ConvexPolygon]
    ) -> tuple[bool, np.ndarray, float, str, int, float]:
        """Solve from w0; return (verified, w, value, status, iterations, seconds)."""
        start = time.perf_counter()
        result = self._solver(x0=w0, p=params, lbx=self._lbw, ubx=self._ubw,
                              lbg=self._lbg, ubg=self._ubg)
        seconds = time.perf_counter() - start
        stats = self._solver.stats()
        status = str(stats.get('return_status', 'unknown'))
        iterations = int(stats.get('iter_count', 0))
        w_opt = np.asarray(result['x']).reshape(-1)
        solved = bool(stats.get('success', False)) and bool(np.all(np.isfinite(w_opt)))
        solved = solved and self._violation(w_opt, params, selected) <= FEASIBILITY_TOLERANCE
        value = float(result['f']) if solved else math.inf
        return solved, w_opt, value, status, iterations, seconds

    def _guided_guess(self, x0: np.ndarray, selected: list[ConvexPolygon]) -> _Plan:
        """An infeasible but informative start: drive forward at half speed."""
        n = self._config.horizon
        u = np.zeros((n, self._model.nu))
        u[:, 0] = 0.5 * self._model.u_max[0]
        x = self._rollout(x0, u)
        s0 = self._initial_s(x0)
        s = self._path.project(x[-1, :3], s_min=s0) if self.uses_path and self._path else s0
        terminal = self._terminal_state(s, x0)
        if terminal is not None:
            x[-1] = terminal
        return _Plan(x=x, u=u, s=s, mu=self._multipliers(x, selected), value=math.inf)

    def _check_ready(self) -> None:
        if self.uses_path and self._path is None:
            msg = 'no reference path: call set_path() first'
            raise RuntimeError(msg)
        if not self.uses_path and self._target is None:
            msg = 'no target: call set_target() first'
            raise RuntimeError(msg)

    def solve(self, x: np.ndarray) -> MpcSolution:
        """Compute the input for the measured state x.

        Raises:
            ValueError: if x is not a finite state of the model's size.
            RuntimeError: if no path (or target) has been set.

        """
        x = np.asarray(x, dtype=float).reshape(-1)
        if x.shape != (self._model.nx,) or not np.all(np.isfinite(x)):
            msg = f'state must be {self._model.nx} finite numbers, got {x}'
            raise ValueError(msg)
        self._check_ready()
        x0 = self._unwrap(x)
        selected = self._selected_obstacles(x0)
        if len(selected) > self._slots:
            self._slots = len(selected)  # grow: rebuilt below, between two control steps
        self._ensure_built()
        params = np.concatenate([x0, self._weights(), self._obstacle_params(selected),
                                 self._path_params()])

        candidate = self._candidate(x0, selected)
        w_candidate = self._pack(candidate)
        candidate_ok = self._violation(w_candidate, params, selected) <= FEASIBILITY_TOLERANCE
        candidate_value = float(self._cost_fn(w_candidate, params)) if candidate_ok else math.inf

        solved, w_opt, value, status, iterations, solve_time = self._run_solver(
            w_candidate, params, selected)
        if not solved and self._plan is None:
            # "stay put" zeroes every derivative of the quartic cost, and IPOPT may stall
            # there; a second start rolled out along the path usually converges
            retry = self._run_solver(self._pack(self._guided_guess(x0, selected)), params,
                                     selected)
            solved, w_opt, value, status, iterations = retry[:5]
            solve_time += retry[5]

        if solved and value <= candidate_value + LYAPUNOV_TOLERANCE * (1 + abs(candidate_value)):
            x_p, u_p, s_p, mu_p = self._unpack(w_opt)
            plan, source = _Plan(x=x_p, u=u_p, s=s_p, mu=mu_p, value=value), 'solver'
            self._failures = 0
        elif candidate_ok:
            candidate.value = candidate_value
            plan, source = candidate, 'candidate'
            if not solved:
                self._failures += 1
                status = f'{status} (applied the shifted candidate)'
            else:
                status = f'{status} (candidate cheaper than solver solution)'
        else:
            self._failures += 1
            return self._stop(x0, status, solve_time, iterations)

        lyapunov_ok = None
        if self._previous_value is not None:
            bound = self._previous_value - self._previous_stage
            lyapunov_ok = plan.value <= bound + LYAPUNOV_TOLERANCE * (1 + abs(bound))
        x_s = plan.x[-1]
        self._previous_stage = float(self._stage_fn(plan.x[0], plan.u[0], x_s, self._weights()))
        self._previous_value = plan.value
        self._plan = plan
        u0 = np.clip(plan.u[0], self._model.u_min, self._model.u_max)
        return MpcSolution(
            u0=u0, x_pred=plan.x.copy(), u_pred=plan.u.copy(),
            s=plan.s if self.uses_path else math.nan, value=plan.value,
            success=source == 'solver', status=status, solve_time_s=solve_time,
            iterations=iterations, source=source, lyapunov_ok=lyapunov_ok,
            failures=self._failures,
        )

    def _stop(self, x0: np.ndarray, status: str, solve_time: float,
              iterations: int) -> MpcSolution:
        """No verified plan: command the steady-state input (stand still) and start over."""
        n = self._config.horizon
        _, u_s = self._model.steady_state(x0[:3])
        u_s = np.asarray(u_s, dtype=float).reshape(-1)
        failures = self._failures
        self.reset()
        self._failures = failures
        return MpcSolution(
            u0=u_s, x_pred=np.tile(x0, (n + 1, 1)), u_pred=np.tile(u_s, (n, 1)),
            s=math.nan, value=math.nan, success=False,
            status=f'{status} (no feasible candidate: stopping)', solve_time_s=solve_time,
            iterations=iterations, source='stop', lyapunov_ok=None, failures=failures,
        )

    def _path_params(self) -> np.ndarray:
        raise NotImplementedError


class PathReferenceMPC(_MpcBase):
    """The paper's MPC: the prediction ends in a steady state on the path, x_N = g_p(s_k).

    Args:
        model: the robot model.
        config: settings (MpcConfig()).
        obstacles: convex obstacles as described; inflated here by config.inflation().
        path: the reference path p(s); p(0) should be the robot's start pose.

    """

    uses_path = True

    def _num_path_params(self) -> int:
        assert self._path is not None
        return self._path.num_params

    def _path_params(self) -> np.ndarray:
        assert self._path is not None
        return self._path.parameters()

    def _terminal(
        self, x_n: ca.SX, s: ca.SX, p_path: ca.SX, weights: ca.SX
    ) -> tuple[ca.SX, ca.SX]:
        assert self._path is not None
        x_s, _ = self._model.steady_state(self._path.symbolic(s, p_path))
        return x_n - x_s, (1 - s) ** 2

    def _initial_s(self, x0: np.ndarray) -> float:
        assert self._path is not None
        return self._path.project(x0[:3])

    def _terminal_state(self, s: float, x0: np.ndarray) -> np.ndarray | None:
        assert self._path is not None
        x_s, _ = self._model.steady_state(self._path.pose(s))
        return np.asarray(x_s, dtype=float).reshape(-1)


class TrackingMPC(_MpcBase):
    """Baseline (Limon et al. 2018): an artificial steady state anywhere, offset to the target.

    The same model, stage cost and constraints as PathReferenceMPC, but no path: the offset
    cost is offset_weight times the squared distance of the artificial steady state's pose to
    the target (heading weighted by weight_heading). With a non-convex free space its
    convergence argument does not apply, and it stops in front of the paper's obstacle.
    """

    uses_path = False

    def _num_path_params(self) -> int:
        return 3

    def _path_params(self) -> np.ndarray:
        assert self._target is not None
        return self._target[:3]

    def _terminal(
        self, x_n: ca.SX, s: ca.SX, p_path: ca.SX, weights: ca.SX
    ) -> tuple[ca.SX, ca.SX]:
        x_s, _ = self._model.steady_state(x_n[:3])
        err = x_n[:3] - p_path
        return x_n - x_s, err[0] ** 2 + err[1] ** 2 + weights[1] * err[2] ** 2

    def _initial_s(self, x0: np.ndarray) -> float:
        return 0.0

    def _terminal_state(self, s: float, x0: np.ndarray) -> np.ndarray | None:
        return None
