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

Obstacles enter the NLP lazily (constraint generation): every obstacle the horizon can reach
is checked geometrically, but only those near the candidate trajectory get Farkas
multipliers. If the solution comes too close to one left out, it is added and the NLP solved
again. A solution of the smaller problem that clears every reachable obstacle is optimal
for the full one too (the full feasible set is a subset), so nothing is given up but
variables that could not have been active.
"""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass
import hashlib
import logging
import math
import os
from pathlib import Path
import subprocess
import tempfile
import threading
import time
from typing import Callable, NamedTuple, Sequence

import casadi as ca
import numpy as np

from mpc_local_planner.core.config import MpcConfig, STRUCTURAL_FIELDS
from mpc_local_planner.core.models import RobotModel
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet
from mpc_local_planner.core.paths import ReferencePath, wrap_angle

__all__ = ['MpcSolution', 'PathReferenceMPC', 'TrackingMPC', 'compile_cache_dir']

_LOG = logging.getLogger(__name__)

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
        success: the applied plan is the solver's (source == 'solver').
        status: the solver's return status, or why the candidate was used.
        solve_time_s: wall time of the NLP solve.
        iterations: solver iterations.
        source: 'solver', 'candidate' (the proof's shifted solution) or 'stop'.
        lyapunov_ok: V_N(x_k) <= V_N(x_{k-1}) - l(x_{k-1}, u_{k-1}) + tolerance, or None at
            the first step after a reset.
        failures: consecutive steps on which the solver gave no verified solution (a verified
            one that the candidate beat is not a failure: see solver_verified).
        obstacles_in_reach: obstacles the horizon can reach (all checked geometrically).
        obstacles_active: those the NLP held as Farkas constraints (see solve()).
        rounds: NLP solves this step (more than one when obstacles had to be added).
        solver_verified: the solver returned a verified solution, applied or not.

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
    obstacles_in_reach: int = 0
    obstacles_active: int = 0
    rounds: int = 1
    solver_verified: bool = False


@dataclass
class _Plan:
    """A predicted trajectory with everything needed to shift it."""

    x: np.ndarray  # (N+1, nx)
    u: np.ndarray  # (N, nu)
    s: float
    mu: np.ndarray  # flat multipliers
    value: float


# NLPs kept per MPC, keyed by (obstacle slots, faces): building one takes tens of ms.
MAX_CACHED_NLPS = 32
# Re-solves with more obstacles when a solution came too close to one left out of the NLP.
MAX_ACTIVATION_ROUNDS = 3


@dataclass
class _Nlp:
    """One built NLP (for a given number of obstacle slots) and its index layout."""

    solver: ca.Function
    backend: str
    slots: int
    faces: int
    lbw: np.ndarray
    ubw: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    cost_fn: ca.Function
    g_fn: ca.Function
    ix: np.ndarray  # (N+1, nx) indices of the states in w
    ir: np.ndarray  # (N+1, nr) indices of the reference copies
    iu: np.ndarray  # (N, nu) indices of the inputs
    imu: np.ndarray  # (N, slots * faces) indices of the multipliers of steps 1..N
    build_time_s: float
    plugin: str = ''
    options: dict | None = None
    compiled: bool = False
    pending: Future | None = None  # a compilation running in the background
    fallback: ca.Function | None = None  # IPOPT on the same NLP, when the backend fails
    fallback_factory: Callable[[], ca.Function] | None = None

    def fallback_solver(self) -> ca.Function | None:
        """Return the IPOPT fallback, building it the first time it is needed."""
        if self.fallback is None and self.fallback_factory is not None:
            self.fallback = self.fallback_factory()
        return self.fallback


def _ipopt_options(config: MpcConfig) -> dict:
    return {
        'ipopt.print_level': 0,
        'ipopt.sb': 'yes',
        'ipopt.max_iter': config.max_iterations,
        'ipopt.tol': config.tolerance,
        'ipopt.acceptable_tol': 1e-6,
        # the initial guess is the proof's candidate, feasible by construction: keep the
        # interior-point iterates near it instead of pushing them off the bounds
        'ipopt.bound_push': 1e-8,
        'ipopt.bound_frac': 1e-8,
        'ipopt.mu_init': 1e-4,
    }


def _fatrop_options(config: MpcConfig, structure: dict) -> dict:
    return {
        'structure_detection': 'manual',
        'N': structure['N'],
        'nx': structure['nx'],
        'nu': structure['nu'],
        'ng': structure['ng'],
        # fatrop's bound_push/bound_frac defaults (1e-2) are kept: IPOPT's warm-start settings
        # above make fatrop stall when an obstacle enters the horizon; mu_init 1e-2 (not 0.1)
        # keeps the first step (everything at rest, every quartic derivative zero) short
        'fatrop': {
            'print_level': 0,
            'mu_init': 1e-2,
            'max_iter': config.max_iterations,
            'tol': config.tolerance,
        },
    }


def backend_options(config: MpcConfig, structure: dict) -> tuple[str, dict]:
    """Return (nlpsol plugin, options) for config.solver."""
    common = {'print_time': False, 'error_on_fail': False}
    name = config.solver
    if name == 'ipopt':
        plugin, options = 'ipopt', _ipopt_options(config)
    elif name == 'fatrop':
        plugin, options = 'fatrop', _fatrop_options(config, structure)
    else:
        msg = f'unknown solver {name!r}'
        raise ValueError(msg)
    options.update(common)
    options.update(config.solver_options)
    return plugin, options


# C compiler and flags for config.compile; CC overrides the compiler as usual.
COMPILE_FLAGS = ('-O2', '-fPIC', '-shared')
# One compilation at a time (the machine may have two cores and a control loop to run).
_COMPILE_LOCK = threading.Lock()


def _submit_compilation(source: str, library: Path) -> Future:
    """Compile in a daemon thread: a node stopped with Ctrl-C must not wait for gcc.

    A ThreadPoolExecutor's workers are joined at interpreter exit, which kept a stopped
    controller alive for the whole compilation; a daemon thread is simply dropped (the
    library is renamed into place atomically, so an interrupted build leaves no bad file).
    """
    future: Future = Future()

    def work() -> None:
        with _COMPILE_LOCK:
            try:
                future.set_result(_compile(source, library))
            except BaseException as err:  # noqa: BLE001 - handed to the waiting solver
                future.set_exception(err)

    threading.Thread(target=work, name='mpc_compile', daemon=True).start()
    return future


def compile_cache_dir() -> Path:
    """Return where compiled NLPs are kept ($MPC_LOCAL_PLANNER_CACHE or ~/.cache/...)."""
    env = os.environ.get('MPC_LOCAL_PLANNER_CACHE')
    if env:
        return Path(env)
    base = os.environ.get('XDG_CACHE_HOME') or str(Path.home() / '.cache')
    return Path(base) / 'mpc_local_planner'


def _nlp_source(problem: dict, solver: ca.Function) -> str:
    """Return C code of the NLP functions the solver plugin evaluates (and the oracle)."""
    generator = ca.CodeGenerator('mpc_nlp.c', {'with_header': False})
    generator.add(ca.Function('nlp', [problem['x'], problem['p']],
                              [problem['f'], problem['g']], ['x', 'p'], ['f', 'g']))
    for name in solver.get_function():
        generator.add(solver.get_function(name))
    return generator.dump()


def _library_path(source: str) -> Path:
    compiler = os.environ.get('CC', 'gcc')
    key = hashlib.sha256('\n'.join(
        [ca.__version__, compiler, *COMPILE_FLAGS, source]).encode()).hexdigest()[:24]
    return compile_cache_dir() / f'mpc_nlp_{key}.so'


def _compile(source: str, library: Path) -> Path:
    """Compile source into library (atomically: a half-written file is never loaded)."""
    library.parent.mkdir(parents=True, exist_ok=True)
    compiler = os.environ.get('CC', 'gcc')
    with tempfile.TemporaryDirectory(dir=library.parent) as tmp:
        c_file = Path(tmp) / 'mpc_nlp.c'
        c_file.write_text(source)
        out = Path(tmp) / library.name
        result = subprocess.run([compiler, *COMPILE_FLAGS, str(c_file), '-o', str(out), '-lm'],
                                capture_output=True, text=True, timeout=600, check=False)
        if result.returncode != 0:
            msg = f'{compiler} failed ({result.returncode}): {result.stderr.strip()[:500]}'
            raise RuntimeError(msg)
        os.replace(out, library)
    return library


def _start_compilation(nlp: _Nlp, problem: dict) -> None:
    """Use a cached compiled library now, or compile one in the background."""
    try:
        source = _nlp_source(problem, nlp.solver)
        library = _library_path(source)
        if library.exists():
            nlp.solver = ca.nlpsol('mpc', nlp.plugin, str(library), nlp.options)
            nlp.compiled = True
            return
        nlp.pending = _submit_compilation(source, library)
    except Exception as err:  # noqa: BLE001 - any failure falls back to the interpreter
        _LOG.warning('compiling the MPC NLP failed, using the interpreted functions: %s', err)


def _finish_compilation(nlp: _Nlp, *, wait: bool = False) -> None:
    """Swap in the compiled solver once its background compilation is done."""
    future = nlp.pending
    if future is None or not (wait or future.done()):
        return
    nlp.pending = None
    try:
        library = future.result()
        nlp.solver = ca.nlpsol('mpc', nlp.plugin, str(library), nlp.options)
        nlp.compiled = True
    except Exception as err:  # noqa: BLE001 - any failure falls back to the interpreter
        _LOG.warning('compiling the MPC NLP failed, using the interpreted functions: %s', err)


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
        self._nlps: dict[tuple[int, int], _Nlp] = {}
        self._structure_key: tuple | None = None
        self._last_nlp: _Nlp | None = None
        self._last_build_time = 0.0
        self._rollouts: dict[tuple[float, int], ca.Function] = {}
        self._stage_fn = self._stage_function()
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
            self._nlps.clear()
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
        self._obstacle_set = ObstacleSet(self._inflated)

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
        return (c.horizon, c.step, c.cost_exponent, c.farkas_margin, c.faces_per_obstacle,
                c.solver, c.max_iterations, c.tolerance, c.compile,
                tuple(sorted((k, repr(v)) for k, v in c.solver_options.items())), family,
                self._num_path_params())

    def _slot_shape(self, selected: list[ConvexPolygon]) -> tuple[int, int]:
        """Return (slots, faces) of the NLP that holds the selected obstacles."""
        c = self._config
        if not c.adaptive_slots:
            return max(self._slots, len(selected)), c.faces_per_obstacle
        if not selected:
            return 0, 0
        # faces rounded up to a multiple of 4 so that boxes and octagons share few builds
        faces = max(o.num_faces for o in selected)
        faces = min(c.faces_per_obstacle, 4 * math.ceil(faces / 4)) if faces > 4 else faces
        return len(selected), max(faces, 3)

    def _nlp_for(self, slots: int, faces: int) -> _Nlp:
        """Return the NLP for this obstacle shape, built (or fetched from the cache) now."""
        key = self._structure()
        if key != self._structure_key:
            self._nlps.clear()
            self._structure_key = key
        nlp = self._nlps.get((slots, faces))
        if nlp is None:
            if len(self._nlps) >= MAX_CACHED_NLPS:
                self._nlps.pop(next(iter(self._nlps)))
            nlp = self._build(slots, faces)
            self._nlps[(slots, faces)] = nlp
        return nlp

    def prepare(self, max_obstacles: int | None = None) -> None:
        """Build the NLPs for 0..max_obstacles obstacles in reach, so no control step waits.

        Args:
            max_obstacles: the largest count to prepare (config.obstacle_slots by default).

        """
        count = self._config.obstacle_slots if max_obstacles is None else max_obstacles
        for k in range(count + 1):
            self._nlp_for(*self._slot_shape(self._inflated[:k] if self._inflated else []))

    def _reference_dim(self) -> int:
        """Size of the reference variable r carried along the horizon (s, or x_s)."""
        raise NotImplementedError

    def _reference_state(self, r: ca.SX, p_path: ca.SX) -> ca.SX:
        """Return the artificial steady state x_s(r)."""
        raise NotImplementedError

    def _terminal(
        self, x_n: ca.SX, r: ca.SX, p_path: ca.SX, weights: ca.SX
    ) -> tuple[ca.SX, ca.SX]:
        """Return (terminal equality residual, offset cost without its weight)."""
        raise NotImplementedError

    def _reference_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def _reference_value(self, plan: _Plan) -> np.ndarray:
        raise NotImplementedError

    def _num_path_params(self) -> int:
        raise NotImplementedError

    def _build(self, slots: int, faces: int) -> _Nlp:
        """Build the NLP in the stage-wise order structure-exploiting solvers need.

        Variables: z_0, u_0, z_1, u_1, mu_1, ..., z_{N-1}, u_{N-1}, mu_{N-1}, z_N, mu_N with
        z_k = (x_k, r_k): the reference r (s, or the artificial steady state) is copied
        along the horizon (r_{k+1} = r_k) so that each stage cost l(x_k - x_s(r_k), ...)
        only touches its own stage. Constraints, per stage k: the gap-closing
        z_{k+1} = (F(x_k, u_k), r_k), then the stage's own constraints (x_0 = x0 at k = 0,
        the Farkas rows of x_k at k >= 1, the terminal condition at k = N).
        """
        c = self._config
        m = self._model
        n, nx, nu = c.horizon, m.nx, m.nu
        nr = self._reference_dim()
        nz = nx + nr
        nm = faces * slots
        F = m.discrete(c.step)

        x0 = ca.SX.sym('x0', nx)
        weights = ca.SX.sym('w', 5)
        obs = ca.SX.sym('obs', 3 * faces * slots)
        p_path = ca.SX.sym('path', self._num_path_params())

        Z = [ca.SX.sym(f'z{k}', nz) for k in range(n + 1)]
        U = [ca.SX.sym(f'u{k}', nu) for k in range(n)]
        MU = [None] + [ca.SX.sym(f'mu{k}', nm) for k in range(1, n + 1)]
        order: list[ca.SX] = []
        for k in range(n + 1):
            order.append(Z[k])
            if k < n:
                order.append(U[k])
            if k >= 1:
                order.append(MU[k])
        w = ca.vertcat(*order)
        index = np.arange(w.numel())
        layout: dict[str, list[np.ndarray]] = {'x': [], 'r': [], 'u': [], 'mu': []}
        offset = 0
        for k in range(n + 1):
            layout['x'].append(index[offset:offset + nx])
            layout['r'].append(index[offset + nx:offset + nz])
            offset += nz
            if k < n:
                layout['u'].append(index[offset:offset + nu])
                offset += nu
            if k >= 1:
                layout['mu'].append(index[offset:offset + nm])
                offset += nm

        stage = self._stage_function()
        self._stage_fn = stage
        A_list, b_list = [], []
        for j in range(slots):
            base = 3 * faces * j
            A_list.append(ca.reshape(obs[base:base + 2 * faces], faces, 2))
            b_list.append(obs[base + 2 * faces:base + 3 * faces])

        g, lbg, ubg = [], [], []
        ng_stage = []

        def add(expr: ca.SX, lower: float, upper: float) -> int:
            size = expr.numel()
            g.append(ca.vec(expr))
            lbg.append(np.full(size, lower, dtype=float))
            ubg.append(np.full(size, upper, dtype=float))
            return size

        cost = 0
        for k in range(n + 1):
            x_k, r_k = Z[k][:nx], Z[k][nx:]
            if k < n:
                cost = cost + stage(x_k, U[k], self._reference_state(r_k, p_path), weights)
                add(Z[k + 1] - ca.vertcat(F(x_k, U[k]), r_k), 0.0, 0.0)
            rows = 0
            if k == 0:
                rows += add(x_k - x0, 0.0, 0.0)
            else:
                for j in range(slots):
                    mu = MU[k][j * faces:(j + 1) * faces]
                    p = x_k[0:2]
                    rows += add(ca.dot(ca.mtimes(A_list[j], p) - b_list[j], mu),
                                c.farkas_margin, ca.inf)
                    rows += add(ca.sum1(mu), 1.0, 1.0)
            if k == n:
                residual, offset_cost = self._terminal(x_k, r_k, p_path, weights)
                # drop entries that are identically zero (a free steady state): an empty
                # Jacobian row makes the KKT system singular and the solver wanders off
                kept = [residual[i] for i in range(residual.numel())
                        if not residual[i].is_zero()]
                if kept:
                    rows += add(ca.vertcat(*kept), 0.0, 0.0)
                cost = cost + weights[4] * offset_cost
            ng_stage.append(rows)

        g_all = ca.vertcat(*g)
        params = ca.vertcat(x0, weights, obs, p_path)
        lbr, ubr = self._reference_bounds()
        lbw, ubw = np.zeros(w.numel()), np.zeros(w.numel())
        for k in range(n + 1):
            lbw[layout['x'][k]], ubw[layout['x'][k]] = m.x_min, m.x_max
            lbw[layout['r'][k]], ubw[layout['r'][k]] = lbr, ubr
            if k < n:
                lbw[layout['u'][k]], ubw[layout['u'][k]] = m.u_min, m.u_max
            if k >= 1:
                lbw[layout['mu'][k - 1]], ubw[layout['mu'][k - 1]] = 0.0, np.inf
        structure = {
            'N': n,
            'nx': [nz] * (n + 1),
            'nu': [nu] + [nu + nm] * (n - 1) + [nm] if n > 1 else [nu, nm],
            'ng': ng_stage,
        }
        problem = {'x': w, 'p': params, 'f': cost, 'g': g_all}
        start = time.perf_counter()
        plugin, options = backend_options(c, structure)
        built = _Nlp(
            solver=ca.nlpsol('mpc', plugin, problem, options), backend=c.solver,
            slots=slots, faces=faces,
            lbw=lbw, ubw=ubw, lbg=np.concatenate(lbg), ubg=np.concatenate(ubg),
            cost_fn=ca.Function('cost', [w, params], [cost]),
            g_fn=ca.Function('g', [w, params], [g_all]),
            ix=np.array(layout['x']), ir=np.array(layout['r']), iu=np.array(layout['u']),
            imu=np.array(layout['mu']).reshape(n, nm), build_time_s=0.0,
            plugin=plugin, options=options,
        )
        if c.solver != 'ipopt':
            # a structure-exploiting backend is fast but less robust far from its warm
            # start (seen: fatrop failing near the box's corner under timing jitter);
            # IPOPT, the reference, gets the same problem before the controller gives up.
            # Built on first use: building it with every NLP doubled the start-up time.
            fb_plugin, fb_options = backend_options(c.with_changes(solver='ipopt'), structure)
            built.fallback_factory = lambda: ca.nlpsol('mpc_fallback', fb_plugin, problem,
                                                       fb_options)
        if c.compile:
            _start_compilation(built, problem)
        built.build_time_s = time.perf_counter() - start
        return built

    def wait_compiled(self) -> None:
        """Block until the background compilations of the built NLPs are done (or failed)."""
        for nlp in self._nlps.values():
            _finish_compilation(nlp, wait=True)

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

    # ----------------------------------------------------------------- packing
    def _pack(self, plan: _Plan, nlp: _Nlp) -> np.ndarray:
        w = np.zeros(nlp.lbw.shape[0])
        w[nlp.ix] = plan.x
        w[nlp.ir] = self._reference_value(plan)
        w[nlp.iu] = plan.u
        w[nlp.imu] = plan.mu.reshape(nlp.imu.shape)
        return w

    def _unpack(
        self, w: np.ndarray, nlp: _Nlp
    ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
        x = w[nlp.ix]
        u = w[nlp.iu]
        s = float(w[nlp.ir[-1, 0]]) if self.uses_path else 0.0
        mu = w[nlp.imu].reshape(-1)
        return x, u, s, mu

    @property
    def last_build_time_s(self) -> float:
        """Seconds spent building the NLP used by the last solve (0 if it was cached)."""
        return self._last_build_time

    @property
    def backend(self) -> str:
        """The NLP backend of the last solve: config.solver, '+compiled' once compiled."""
        nlp = self._last_nlp
        if nlp is None:
            return self._config.solver
        return nlp.backend + ('+compiled' if nlp.compiled else '')

    def _speed_bound(self) -> float:
        return float(np.max(np.abs(self._model.u_max[:1])))

    def _reachable(self, x0: np.ndarray) -> ObstacleSet:
        """Return the inflated obstacles the horizon can reach, nearest first."""
        c = self._config
        reach = self._speed_bound() * c.step * c.horizon + 1e-3
        chosen, _ = self._obstacle_set.near(x0[None, :2], reach)
        return self._obstacle_set.subset(chosen)

    def _activation_distance(self) -> float:
        c = self._config
        if c.activation_distance is not None:
            return c.activation_distance
        # half a step: measured, re-solves on < 1 % of steps (BARN at 1 m/s, the paper's
        # scenario with 20 obstacles) with at most 4 obstacles in the NLP; 2 v_max h held
        # up to 22 and built 4x as many NLP shapes
        return 0.5 * self._speed_bound() * c.step

    def _near_trajectory(self, x: np.ndarray, reachable: ObstacleSet,
                         distance: float) -> list[ConvexPolygon]:
        """Return the reachable obstacles within distance of the positions x, nearest first."""
        chosen, _ = reachable.near(x[:, :2], distance)
        return [reachable.obstacles[i] for i in chosen]

    def _obstacle_params(self, selected: list[ConvexPolygon], nlp: _Nlp) -> np.ndarray:
        faces, slots = nlp.faces, nlp.slots
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

    def _multipliers(self, x: np.ndarray, selected: list[ConvexPolygon],
                     nlp: _Nlp) -> np.ndarray:
        """Put each multiplier on the most separating face: a feasible mu for clear points."""
        n, faces, slots = x.shape[0] - 1, nlp.faces, nlp.slots
        mu = np.zeros((n, slots, faces))
        for j in range(slots):
            if j < len(selected):
                # the padded rows repeat the last face (see _obstacle_params)
                faces_j = min(selected[j].num_faces, faces)
                face = np.argmax(x[1:, :2] @ selected[j].A[:faces_j].T - selected[j].b[:faces_j],
                                 axis=1)
            else:
                face = np.zeros(n, dtype=int)
            mu[np.arange(n), j, face] = 1.0
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
        """Simulate the model from x0 under u, in one call of a mapaccum'ed step."""
        key = (self._config.step, len(u))
        rollout = self._rollouts.get(key)
        if rollout is None:
            step = self._model.discrete(self._config.step)
            rollout = self._rollouts[key] = step.mapaccum('rollout', len(u))
        xs = np.asarray(rollout(x0, np.asarray(u, dtype=float).T)).T
        return np.vstack([x0, xs])

    def _candidate(self, x0: np.ndarray) -> _Plan:
        """The proof's candidate: shift the last plan and append the terminal steady state.

        Its multipliers depend on the NLP (obstacles held): see _multipliers.
        """
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
        return plan

    def _terminal_state(self, s: float, x0: np.ndarray) -> np.ndarray | None:
        raise NotImplementedError

    def _violation(self, w: np.ndarray, params: np.ndarray, obstacles: ObstacleSet,
                   nlp: _Nlp) -> float:
        """Return the largest constraint violation, collisions checked geometrically.

        The geometric check does not trust the multipliers: whatever the solver did with
        them, every predicted position l = 1..N must clear every given obstacle (those of the
        NLP, or every reachable one).
        """
        g = np.asarray(nlp.g_fn(w, params)).reshape(-1)
        viol = np.maximum(nlp.lbg - g, 0) + np.maximum(g - nlp.ubg, 0)
        viol_w = np.maximum(nlp.lbw - w, 0) + np.maximum(w - nlp.ubw, 0)
        worst = max(np.max(viol, initial=0.0), np.max(viol_w, initial=0.0))
        return max(float(worst), self._penetration(w[nlp.ix[1:, :2]], obstacles))

    def _penetration(self, positions: np.ndarray, obstacles: ObstacleSet) -> float:
        """Return how far the positions fall short of the Farkas margin (0 when all clear)."""
        depth = self._config.farkas_margin - obstacles.signed_distance_lower_bound(positions)
        return float(np.max(depth, initial=0.0))

    def _run_solver(
        self, nlp: _Nlp, w0: np.ndarray, params: np.ndarray, active: ObstacleSet,
        solver: ca.Function | None = None,
    ) -> tuple[bool, np.ndarray, float, str, int, float]:
        """Solve from w0; return (verified, w, value, status, iterations, seconds)."""
        solver = nlp.solver if solver is None else solver
        start = time.perf_counter()
        result = solver(x0=w0, p=params, lbx=nlp.lbw, ubx=nlp.ubw, lbg=nlp.lbg, ubg=nlp.ubg)
        seconds = time.perf_counter() - start
        stats = solver.stats()
        status = str(stats.get('return_status', 'unknown'))
        iterations = int(stats.get('iter_count', 0))
        w_opt = np.asarray(result['x']).reshape(-1)
        solved = bool(stats.get('success', False)) and bool(np.all(np.isfinite(w_opt)))
        solved = solved and self._violation(w_opt, params, active, nlp) <= FEASIBILITY_TOLERANCE
        value = float(result['f']) if solved else math.inf
        return solved, w_opt, value, status, iterations, seconds

    def _optimise(self, nlp: _Nlp, w_candidate: np.ndarray, params: np.ndarray,
                  x0: np.ndarray, active: list[ConvexPolygon]
                  ) -> tuple[bool, np.ndarray, float, str, int, float]:
        """Solve from the candidate; on failure retry from other starts and with IPOPT."""
        active_set = ObstacleSet(active)
        solved, w_opt, value, status, iterations, solve_time = self._run_solver(
            nlp, w_candidate, params, active_set)
        guess = None
        if not solved and self._plan is None:
            # "stay put" zeroes every derivative of the quartic cost, and IPOPT may stall
            # there; a second start rolled out along the path usually converges
            guess = self._pack(self._guided_guess(x0, active, nlp), nlp)
            retry = self._run_solver(nlp, guess, params, active_set)
            solved, w_opt, value, status = retry[:4]
            iterations += retry[4]
            solve_time += retry[5]
        fallback = None if solved else nlp.fallback_solver()
        if fallback is not None:
            starts = [w_candidate] if guess is None else [w_candidate, guess]
            for w_start in starts:
                retry = self._run_solver(nlp, w_start, params, active_set, fallback)
                iterations += retry[4]
                solve_time += retry[5]
                if retry[0]:
                    solved, w_opt, value, status = retry[:4]
                    status = f'{status} (IPOPT fallback)'
                    break
        return solved, w_opt, value, status, iterations, solve_time

    def _collision_free(self, x: np.ndarray, obstacles: ObstacleSet) -> bool:
        """Say whether the positions x[1:] clear every given (inflated) obstacle."""
        return self._penetration(x[1:, :2], obstacles) <= 0.0

    def _guided_guess(self, x0: np.ndarray, active: list[ConvexPolygon], nlp: _Nlp) -> _Plan:
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
        return _Plan(x=x, u=u, s=s, mu=self._multipliers(x, active, nlp), value=math.inf)

    def _check_ready(self) -> None:
        if self.uses_path and self._path is None:
            msg = 'no reference path: call set_path() first'
            raise RuntimeError(msg)
        if not self.uses_path and self._target is None:
            msg = 'no target: call set_target() first'
            raise RuntimeError(msg)

    def _prepare_nlp(self, active: list[ConvexPolygon], x0: np.ndarray
                     ) -> tuple[_Nlp, np.ndarray]:
        """Return the NLP holding the active obstacles and its parameter vector."""
        if not self._config.adaptive_slots and len(active) > self._slots:
            self._slots = len(active)  # grow: rebuilt below, between two control steps
        cached = len(self._nlps)
        nlp = self._nlp_for(*self._slot_shape(active))
        _finish_compilation(nlp)
        if len(self._nlps) != cached:
            self._last_build_time += nlp.build_time_s
        self._last_nlp = nlp
        params = np.concatenate([x0, self._weights(), self._obstacle_params(active, nlp),
                                 self._path_params()])
        return nlp, params

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
        reachable = self._reachable(x0)
        candidate = self._candidate(x0)
        activation = self._activation_distance()
        active = self._near_trajectory(candidate.x, reachable, activation)
        self._last_build_time = 0.0
        solve_time, iterations = 0.0, 0
        for round_ in range(MAX_ACTIVATION_ROUNDS + 1):
            nlp, params = self._prepare_nlp(active, x0)
            candidate.mu = self._multipliers(candidate.x, active, nlp)
            w_candidate = self._pack(candidate, nlp)
            # the candidate must clear every reachable obstacle, not only the active ones
            candidate_ok = (self._violation(w_candidate, params, reachable, nlp)
                            <= FEASIBILITY_TOLERANCE)
            candidate_value = (float(nlp.cost_fn(w_candidate, params)) if candidate_ok
                               else math.inf)
            solved, w_opt, value, status, its, seconds = self._optimise(
                nlp, w_candidate, params, x0, active)
            solve_time += seconds
            iterations += its
            if not solved:
                break
            # constraint generation: obstacles the solution came near join the NLP
            missed = [o for o in self._near_trajectory(w_opt[nlp.ix], reachable, activation / 2)
                      if not any(o is a for a in active)]
            if not missed:
                break
            if round_ == MAX_ACTIVATION_ROUNDS:
                if self._penetration(w_opt[nlp.ix[1:, :2]], reachable) > FEASIBILITY_TOLERANCE:
                    solved, status = False, f'{status} (hits an obstacle left out of the NLP)'
                break
            active = active + missed

        if solved and value <= candidate_value + LYAPUNOV_TOLERANCE * (1 + abs(candidate_value)):
            x_p, u_p, s_p, mu_p = self._unpack(w_opt, nlp)
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
        elif self._plan is not None and self._collision_free(candidate.x, reachable):
            # measured state off the prediction (timing jitter, model mismatch): the shifted
            # inputs no longer end exactly on the path, but they were verified one step ago
            # and their rollout from the measured state is still clear; the shift runs out
            # after N steps (all u_s), which stops the robot
            self._failures += 1
            candidate.value = float(nlp.cost_fn(w_candidate, params))
            plan, source = candidate, 'candidate'
            status = f'{status} (applied the shifted candidate; off the prediction)'
        else:
            self._failures += 1
            return self._stop(x0, status, solve_time, iterations, len(reachable), len(active))

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
            failures=self._failures, obstacles_in_reach=len(reachable),
            obstacles_active=len(active), rounds=round_ + 1, solver_verified=solved,
        )

    def _stop(self, x0: np.ndarray, status: str, solve_time: float, iterations: int,
              in_reach: int = 0, active: int = 0) -> MpcSolution:
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
            obstacles_in_reach=in_reach, obstacles_active=active,
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

    def _reference_dim(self) -> int:
        return 1

    def _reference_state(self, r: ca.SX, p_path: ca.SX) -> ca.SX:
        assert self._path is not None
        x_s, _ = self._model.steady_state(self._path.symbolic(r[0], p_path))
        return x_s

    def _reference_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(1), np.ones(1)

    def _reference_value(self, plan: _Plan) -> np.ndarray:
        return np.array([plan.s])

    def _terminal(
        self, x_n: ca.SX, r: ca.SX, p_path: ca.SX, weights: ca.SX
    ) -> tuple[ca.SX, ca.SX]:
        return x_n - self._reference_state(r, p_path), (1 - r[0]) ** 2

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

    def _reference_dim(self) -> int:
        return self._model.nx

    def _reference_state(self, r: ca.SX, p_path: ca.SX) -> ca.SX:
        return r

    def _reference_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self._model.x_min, self._model.x_max

    def _reference_value(self, plan: _Plan) -> np.ndarray:
        return plan.x[-1]

    def _terminal(
        self, x_n: ca.SX, r: ca.SX, p_path: ca.SX, weights: ca.SX
    ) -> tuple[ca.SX, ca.SX]:
        x_s, _ = self._model.steady_state(r[:3])
        err = r[:3] - p_path
        return (ca.vertcat(x_n - r, r - x_s),
                err[0] ** 2 + err[1] ** 2 + weights[1] * err[2] ** 2)

    def _initial_s(self, x0: np.ndarray) -> float:
        return 0.0

    def _terminal_state(self, s: float, x0: np.ndarray) -> np.ndarray | None:
        return None
