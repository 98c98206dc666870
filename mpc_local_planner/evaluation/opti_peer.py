# SPDX-License-Identifier: Apache-2.0
"""The benchmark's peer: problem (6) as a competent CasADi user writes it, with Opti and IPOPT.

A fair peer, not a straw man: casadi.Opti with IPOPT and expand=True (SX functions inside
the solver), warm-started from the shifted previous solution and its multipliers, the same
model, cost, terminal condition and Farkas obstacle rows as the package's NLP. mpc_bench
compares the package's backends against it.
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple, Sequence

import casadi as ca
import numpy as np

from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import ReferencePath
from mpc_local_planner.evaluation.rollout import ControlStep

__all__ = ['OptiMpc', 'OptiSolution']


class OptiSolution(NamedTuple):
    """What the Opti peer reports of a step beyond the rollout's ControlStep."""

    iterations: int


class OptiMpc:
    """The same OCP as a competent CasADi user writes it: Opti + IPOPT, expand, warm start.

    The problem is the package's without its machinery: decision variables X, U, s and a
    Farkas multiplier per obstacle, face and step, the same stage cost, terminal equality on
    the path, input bounds and obstacles inflated by the same MpcConfig.inflation; all
    obstacles are always in the problem (no constraint generation) and there is no
    candidate verification. What makes it a fair peer rather than a straw man:

    - ``expand=True``: the MX graph is expanded to SX, so IPOPT's callbacks are cheap;
    - warm start: each solve starts from the previous solution shifted one step (X, U, the
      multipliers mu, and the constraint multipliers lam_g, stage by stage) with IPOPT's
      ``warm_start_init_point`` and a small ``mu_init``, the usual recipe for a primal-dual
      warm start; the first solve starts from the robot standing still, mu uniform.
    """

    LABEL = 'Opti + IPOPT, expand, warm start'

    def __init__(self, model: Unicycle, config: MpcConfig, obstacles: Sequence[ConvexPolygon],
                 path: ReferencePath) -> None:
        n, h = config.horizon, config.step
        inflation = config.inflation(float(model.u_max[0]))
        opti = ca.Opti()
        X = opti.variable(3, n + 1)
        U = opti.variable(2, n)
        s = opti.variable()
        x0 = opti.parameter(3)
        x_s = path.symbolic(s, [])
        cost = 0
        for i in range(n):
            dx = X[:, i] - x_s
            cost += (dx[0] ** 4 + dx[1] ** 4 + config.weight_heading * dx[2] ** 4
                     + U[0, i] ** 4 + U[1, i] ** 4)
        opti.minimize(cost + config.offset_weight * (1 - s) ** 2)
        F = model.discrete(h)
        # Rows of g (and of lam_g) per prediction step, so that the multipliers can be shifted
        # like the primal trajectory: Opti stacks the constraints in the order they are added.
        stage_rows: list[list[np.ndarray]] = [[] for _ in range(n)]

        def constrain(constraint: Any, stage: int | None = None) -> None:
            first = opti.ng
            opti.subject_to(constraint)
            if stage is not None:
                stage_rows[stage].append(np.arange(first, opti.ng))

        constrain(X[:, 0] == x0)
        for i in range(n):
            constrain(X[:, i + 1] == F(X[:, i], U[:, i]), i)
            constrain(opti.bounded(model.u_min, U[:, i], model.u_max), i)
        constrain(X[:, n] == x_s)
        constrain(opti.bounded(0, s, 1))
        multipliers = []
        for obstacle in obstacles:
            grown = obstacle.inflate(inflation)
            mu = opti.variable(grown.num_faces, n)
            multipliers.append(mu)
            for i in range(n):
                constrain(mu[:, i] >= 0, i)
                constrain(ca.sum1(mu[:, i]) == 1, i)
                p = X[0:2, i + 1]
                constrain(ca.dot(ca.mtimes(grown.A, p) - grown.b, mu[:, i])
                          >= config.farkas_margin, i)
        # lam_g[shift] moves every stage's multipliers one stage earlier; the last stage and
        # the stage-free rows (initial state, terminal state, s) keep theirs.
        shift = np.arange(opti.ng)
        for i in range(n - 1):
            shift[np.concatenate(stage_rows[i])] = np.concatenate(stage_rows[i + 1])
        opti.solver('ipopt', {'print_time': False, 'expand': True},
                    {'print_level': 0, 'sb': 'yes', 'warm_start_init_point': 'yes',
                     'mu_init': 1e-4})
        self._opti, self._x0, self._X, self._U, self._s = opti, x0, X, U, s
        self._mu = multipliers
        self._shift = shift
        self._previous: tuple[np.ndarray, np.ndarray, float, list[np.ndarray],
                              np.ndarray] | None = None

    def reset(self) -> None:
        """Forget the previous solution: the next solve starts cold."""
        self._previous = None

    def step(self, x: np.ndarray) -> ControlStep:
        """Return the rollout's step: u0, solve time, success, iterations in detail."""
        u, seconds, iterations, ok = self.solve(x)
        return ControlStep(u=u, solve_time_s=seconds, success=ok,
                           detail=OptiSolution(iterations=iterations))

    def _initial_guess(self, x: np.ndarray) -> None:
        opti = self._opti
        if self._previous is None:
            opti.set_initial(self._X, np.tile(np.asarray(x, dtype=float).reshape(3, 1),
                                              (1, self._X.shape[1])))
            opti.set_initial(self._U, 0.0)
            opti.set_initial(self._s, 0.0)
            for mu in self._mu:
                opti.set_initial(mu, np.full(mu.shape, 1.0 / mu.shape[0]))
            opti.set_initial(opti.lam_g, 0.0)
            return
        X, U, s, mus, lam_g = self._previous
        opti.set_initial(self._X, np.hstack([X[:, 1:], X[:, -1:]]))
        opti.set_initial(self._U, np.hstack([U[:, 1:], np.zeros((2, 1))]))
        opti.set_initial(self._s, s)
        for mu, value in zip(self._mu, mus, strict=True):
            opti.set_initial(mu, np.hstack([value[:, 1:], value[:, -1:]]))
        opti.set_initial(opti.lam_g, lam_g[self._shift])

    def solve(self, x: np.ndarray) -> tuple[np.ndarray, float, int, bool]:
        """Return (u0, solve seconds, iterations, success); the time is opti.solve() only."""
        opti = self._opti
        opti.set_value(self._x0, x)
        self._initial_guess(x)
        start = time.perf_counter()
        try:
            value = opti.solve().value
            ok = True
        except RuntimeError:
            value = opti.debug.value
            ok = False
        seconds = time.perf_counter() - start
        X = np.asarray(value(self._X), dtype=float).reshape(3, -1)
        U = np.asarray(value(self._U), dtype=float).reshape(2, -1)
        self._previous = (X, U, float(value(self._s)),
                          [np.asarray(value(mu), dtype=float).reshape(mu.shape)
                           for mu in self._mu],
                          np.asarray(value(opti.lam_g), dtype=float).reshape(-1))
        return U[:, 0], seconds, int(opti.stats().get('iter_count', 0)), ok
