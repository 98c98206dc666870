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

"""One control step of the paper's MPC: candidate, verification, constraint generation, decision.

The closed-loop guarantee rests on V_N not increasing. The proof compares the optimum at
k+1 with a candidate: the previous solution shifted by one step, with the terminal steady
state appended. A local NLP solver may return something worse than that candidate, or fail;
this module therefore always builds the candidate, verifies both (constraint violation and a
geometric collision check that does not trust the multipliers), and decide() applies whichever
is verified and cheaper. So V_N is non-increasing by construction, not by luck.

Obstacles enter the NLP lazily (constraint generation): every obstacle the horizon can reach
is checked geometrically, but only those near the candidate trajectory get Farkas
multipliers. If the solution comes too close to one left out, it is added and the NLP solved
again. A solution of the smaller problem that clears every reachable obstacle is optimal
for the full one too (the full feasible set is a subset), so nothing is given up but
variables that could not have been active.

A round robot is a point among obstacles inflated by its radius (and the collision margin).
A polygonal footprint (config.footprint) is checked exactly instead: the signed distance
between the polygon at each predicted pose and each obstacle (obstacles.polygon_separation)
must be at least the clearance the motion needs, farkas_margin + h/2 (|v| + r_c |omega|) for
both steps next to the pose (exact |.| here; the NLP's smooth one is never smaller).

A step's solving is bounded: in wall time by default (config.budget 'wall', the robot's:
config.solve_budget(), max_solve_time, half the period by default, counted from the start of
solve()), or in solver iterations (config.budget 'iterations', the evaluation's:
config.solve_iterations(), spent by the iterations each try makes; no clock is read, builds
are free and a step waits for its NLP's compilation, so a step does the same on any machine
under any load). The first NLP solve gets what is left of it when it starts (an NLP built
mid-step has spent its share of wall time: prepare() builds them ahead); the retries (a
second start, the IPOPT fallback, further constraint-generation rounds) run only while some
is left. Which tries an NLP solve makes, in which order, is tries.py's
table (solver_tries); _optimise only makes them. Once the budget is spent, decide() applies
the verified shifted candidate (CANDIDATE_TIMEOUT), or stops if there is none, and the
solution says so (MpcSolution.timed_out). Nothing unverified is ever applied: the budget
only decides how hard the step tries to beat the candidate. How closely a solver keeps to its
share is backends.py's (run_solver): IPOPT to an iteration, fatrop to its measured time per
iteration (wall) or to an iteration level (iterations).

The NLP itself is formulation.py (problem (6)); the solvers and their compilation are
backends.py.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
import math
import time
from typing import Callable, NamedTuple, Sequence

import casadi as ca
import numpy as np

from mpc_local_planner.core.config import MpcConfig, STRUCTURAL_FIELDS
from mpc_local_planner.core.models import RobotModel
from mpc_local_planner.core.mpc.backends import build_nlp, Nlp, run_solver
from mpc_local_planner.core.mpc.decision import (
    decide,
    Decision,
    LYAPUNOV_TOLERANCE,
    PlanSource,
)
from mpc_local_planner.core.mpc.formulation import (
    dual_multipliers,
    feasible_multipliers,
    formulate,
    obstacle_parameters,
    parameter_vector,
    path_terminal,
    rate_limited_inputs,
    stage_cost,
    sweep_rate,
    TerminalCondition,
)
from mpc_local_planner.core.mpc.nlp_shapes import NlpShapes
from mpc_local_planner.core.mpc.tries import Situation, Solver, solver_tries, Start, Try
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet, polygon_separation
from mpc_local_planner.core.paths import ReferencePath, wrap_angle

__all__ = ['Decision', 'MpcBase', 'MpcSolution', 'PathReferenceMPC', 'Plan', 'PlanSource',
           'SolveAttempt', 'decide']

# Constraint-violation bound for accepting a solution or a candidate (metres, rad, m/s).
FEASIBILITY_TOLERANCE = 1e-5
# Re-solves with more obstacles when a solution came too close to one left out of the NLP.
MAX_ACTIVATION_ROUNDS = 3
# Plans whose polygon clearances are memoised within a step (the candidate, the solutions).
MAX_CACHED_PLANS = 8
# A solve the budget cut goes on at the next step from where it stopped if the state moved
# less than this (each component): the robot stood still on the candidate meanwhile.
CONTINUE_TOLERANCE = 1e-3
# A cut solve goes on for at most this many steps after its first before it counts as failed
# here: enough for a solve of up to about three steps' budget to finish, few enough that a
# hopeless try does not hold back the others (see docs/design/mpc.md, section
# MAX_CONTINUED_STEPS).
MAX_CONTINUED_STEPS = 2
# Inputs below this (m/s, rad/s) stand still: a solver that converged to "wait" leaves
# 1e-9, not zeros; and a gain of path progress s below PROGRESS_TOLERANCE is none (see
# _plan_moves).
STANDING_INPUT = 1e-3
PROGRESS_TOLERANCE = 1e-6


class MpcSolution(NamedTuple):
    """Result of one control step.

    Attributes:
        u0: the input to apply now (always within the model's bounds).
        x_pred: (N+1, nx) predicted states.
        u_pred: (N, nu) predicted inputs.
        s: path progress s_k of the artificial steady state (nan for TrackingMPC).
        value: V_N, the cost of what is applied (the Lyapunov function).
        success: the applied plan is the solver's (source is PlanSource.SOLVER).
        status: the solver's return status, and why the candidate was used or the robot stops.
        solve_time_s: wall time of the NLP solves (the solver calls; solve() as a whole, with
            its verification and any NLP built mid-step, is bounded by the budget: timed_out).
        iterations: solver iterations.
        source: the solver's plan, the proof's shifted candidate, or a stop.
        lyapunov_ok: V_N(x_k) <= V_N(x_{k-1}) - l(x_{k-1}, u_{k-1}) + tolerance, or None at
            the first step after a reset.
        failures: consecutive steps on which the solver gave no verified solution (a verified
            one that the candidate beat is not a failure: see solver_verified).
        obstacles_in_reach: obstacles the horizon can reach (all checked geometrically).
        obstacles_active: those the NLP held as Farkas constraints (see MpcBase.solve()).
        rounds: NLP solves this step (more than one when obstacles had to be added).
        solver_verified: the solver returned a verified solution, applied or not.
        timed_out: the step's budget (config.solve_budget()) ran out before its solving was
            done: a solve was cut or not started, or a retry or a constraint-generation round
            was left out. What is applied is verified all the same (the solver's plan only if
            it cleared every reachable obstacle), else the robot stops.
        tries: the solver tries the step made, in order, over all its rounds (see tries.py:
            solver_tries() gives them; the budget may leave some out).

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
    source: PlanSource
    lyapunov_ok: bool | None
    failures: int
    obstacles_in_reach: int = 0
    obstacles_active: int = 0
    rounds: int = 1
    solver_verified: bool = False
    timed_out: bool = False
    tries: tuple[Try, ...] = ()


class SolveAttempt(NamedTuple):
    """The solver's answer after verification."""

    verified: bool  # converged, finite, and within FEASIBILITY_TOLERANCE of every constraint
    w: np.ndarray  # the decision vector it returned
    value: float  # its cost (inf unless verified)
    status: str  # the solver's return status
    iterations: int
    seconds: float
    cut: bool = False  # the budget stopped the solver before it converged


class _Unfinished(NamedTuple):
    """A solve the step's budget cut: where it got to, to go on from at the next step."""

    nlp: Nlp
    x0: np.ndarray
    w: np.ndarray
    solver: Solver  # the solver of the try that was cut
    held: tuple[ConvexPolygon, ...]  # the obstacles its NLP held, in their slots' order
    origin: Try  # the try that began it (a continuation's origin is the first one's)
    steps: int = 1  # the steps it has run in (the first one's and each continuation's)


def _stood_still(before: np.ndarray | None, x0: np.ndarray) -> bool:
    """Say whether the state is where it was (within CONTINUE_TOLERANCE); None: unknown."""
    return before is not None and float(np.max(np.abs(before - x0))) <= CONTINUE_TOLERANCE


def _plan_moves(plan: Plan | None, progress: float) -> bool:
    """Say whether the plan in force moves the robot on: it drives now, or it advances s.

    A plan that neither drives now (|v_0| <= STANDING_INPUT) nor advanced the path progress
    beyond the plan before it (progress, the gain in s; a turn in place along the path
    advances it) waits, and counts as standing: warm starts from it can hold the solver at
    "wait" for good. At rest the unicycle's linearisation cannot move sideways, so where the
    path's steady state g_p(s) leaves the robot's heading (a rounded turn-in-place knot) the
    solver reports success with s frozen, the robot turning to and fro on the spot or not at
    all, the motion put off to the horizon's end; each step's shifted candidate puts it off
    again, V_N constant, and the robot stands in open space (see docs/design/mpc.md, section
    "A waiting plan counts as standing (_plan_moves)"). Counted as standing, the plan gets the
    cold tries of tries.py, which leave that point. Without a path (progress NaN, the
    tracking baseline) any input above STANDING_INPUT moves.
    """
    if plan is None or not len(plan.u):
        return False
    first = np.abs(plan.u[0])
    if math.isnan(progress):
        return bool(np.any(first > STANDING_INPUT))
    return bool(first[0] > STANDING_INPUT or (progress > PROGRESS_TOLERANCE
                                              and np.any(first > STANDING_INPUT)))


def _same_polygons(a: Sequence[ConvexPolygon], b: Sequence[ConvexPolygon]) -> bool:
    """Say whether two obstacle lists are the same polygons in the same order."""
    return len(a) == len(b) and all(
        p.vertices.shape == q.vertices.shape and np.array_equal(p.vertices, q.vertices)
        for p, q in zip(a, b, strict=True))


class _Rounds(NamedTuple):
    """The outcome of constraint generation: the last NLP, its candidate and its solution."""

    nlp: Nlp
    params: np.ndarray
    w_candidate: np.ndarray
    candidate_ok: bool
    candidate_value: float
    attempt: SolveAttempt  # the last round's, with the iterations and time of all rounds
    active: list[ConvexPolygon]
    rounds: int


class _Budget:
    """What is left of one control step's solving, and whether the step ran out of it.

    Seconds of a clock (MpcConfig.budget 'wall'), or solver iterations ('iterations': the
    clock is never read, so the step does the same on any machine). The other is unbounded.
    """

    def __init__(self, clock: Callable[[], float], *, seconds: float = math.inf,
                 iterations: float = math.inf) -> None:
        self._clock = clock
        self._deadline = clock() + seconds if math.isfinite(seconds) else math.inf
        self.iterations = iterations  # left
        self.timed_out = False  # some solving was cut or left out for lack of budget

    @classmethod
    def of(cls, config: MpcConfig, clock: Callable[[], float]) -> _Budget:
        """Return the budget of one step under config."""
        if config.budget == 'iterations':
            return cls(clock, iterations=config.solve_iterations())
        return cls(clock, seconds=config.solve_budget())

    def remaining(self) -> float:
        """Return the seconds left (<= 0 when spent; inf without a time bound)."""
        if math.isinf(self._deadline):
            return math.inf
        return self._deadline - self._clock()

    def spend(self, iterations: int) -> None:
        """Count a solver call's iterations."""
        self.iterations -= iterations

    def allows(self, seconds: float = 0.0) -> bool:
        """Say whether there is budget for more solving; if not, the step has timed out.

        Args:
            seconds: what the work takes before it can be cut (a build), if known; it does
                not count against iterations.

        Ask only where work would otherwise run: a no means it is left out.
        """
        if self.remaining() > seconds and self.iterations >= 1:
            return True
        self.timed_out = True
        return False


def _solver_of(nlp: Nlp, solver: Solver) -> ca.Function | None:
    """Return the solver function a try runs (None: the NLP's own), building it if need be."""
    if solver is Solver.IPOPT_FALLBACK:
        return nlp.fallback_solver()
    if solver is Solver.IPOPT_COLD:
        return nlp.cold_solver()
    return None


def _build_time(nlp: Nlp, solver: Solver) -> float:
    """Return the seconds getting the solver of a try takes before it can run (0: built)."""
    if solver is Solver.IPOPT_FALLBACK:
        return nlp.fallback_build_time
    if solver is Solver.IPOPT_COLD:
        return nlp.cold_build_time
    return 0.0


@dataclass
class Plan:
    """A predicted trajectory with everything needed to shift it (s is nan without a path)."""

    x: np.ndarray  # (N+1, nx)
    u: np.ndarray  # (N, nu)
    s: float
    mu: np.ndarray  # flat multipliers
    value: float


class MpcBase(ABC):
    """The per-step logic shared by the paper's MPC and the tracking-MPC baseline.

    Subclasses say what the terminal condition is (_terminal_condition(), the formulation's
    part) and what it means for the numbers of a plan (the other methods of the section
    'the terminal condition' below).

    Args:
        model: the robot model.
        config: settings (MpcConfig()).
        obstacles: convex obstacles as described; inflated here by config.inflation().

    """

    # The clock of the solve budget (seconds); a test may give an instance a fake one.
    clock: Callable[[], float] = staticmethod(time.perf_counter)

    def __init__(self, model: RobotModel, config: MpcConfig | None = None, *,
                 obstacles: Sequence[ConvexPolygon] = ()) -> None:
        self._model = model
        self._budget = _Budget(self.clock)  # solve() starts one per step
        self._tries: list[Try] = []  # the tries of the step in progress
        self._config = config or MpcConfig()
        self._use_footprint()
        self._raw_obstacles: list[ConvexPolygon] = []
        self._inflated: list[ConvexPolygon] = []
        self._shapes = NlpShapes(self._structure, self._build)
        self._last_nlp: Nlp | None = None
        self._last_active: tuple[ConvexPolygon, ...] = ()
        self._rollouts: dict[tuple[float, int], ca.Function] = {}
        self._stage_fn = stage_cost(model, self._config.cost_exponent)
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
    def backend(self) -> str:
        """The NLP backend of the last solve, '+compiled' once compiled.

        config.solver, or IPOPT for a shape beyond config.fatrop_stage_limit.
        """
        nlp = self._last_nlp
        if nlp is None:
            return self._config.solver
        return nlp.backend + ('+compiled' if nlp.compiled else '')

    @property
    def inflated_obstacles(self) -> tuple[ConvexPolygon, ...]:
        """The obstacles as the NLP sees them: grown by config.inflation()."""
        return tuple(self._inflated)

    @property
    def last_active_obstacles(self) -> tuple[ConvexPolygon, ...]:
        """The inflated obstacles the last solve held as Farkas constraints (its NLP's)."""
        return self._last_active

    def update_config(self, config: MpcConfig) -> None:
        """Apply new settings at the next solve; shape changes rebuild the NLP there."""
        old = self._config
        self._config = config
        if any(getattr(old, name) != getattr(config, name) for name in STRUCTURAL_FIELDS):
            self._use_footprint()
            self._shapes.clear()  # the new shapes are built as steps need them
            self._stage_fn = stage_cost(self._model, config.cost_exponent)
            self.reset()
        if old.inflation(self._model.u_max[0]) != config.inflation(self._model.u_max[0]):
            self.set_obstacles(self._raw_obstacles)

    def set_obstacles(self, obstacles: Sequence[ConvexPolygon]) -> None:
        """Replace the obstacles (as described, not inflated).

        Raises:
            ValueError: if an obstacle has more faces than config.faces_per_obstacle.

        """
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
        self._last_active = ()

    def _use_footprint(self) -> None:
        """Set up the geometry of config.footprint (nothing for a round robot)."""
        footprint = self._config.robot_footprint
        self._body: ConvexPolygon | None = None if footprint.is_circle else footprint.body
        # r_c: no point of the body is further from the robot's origin
        self._body_radius = 0.0 if footprint.is_circle else footprint.radius
        self._sweep_exact = sweep_rate(self._model, self._body_radius)
        self._sweep_maps: dict[int, ca.Function] = {}
        self._geometry: dict[bytes, dict[int, tuple[ConvexPolygon, np.ndarray, np.ndarray]]] = {}
        self._clearance_memo: dict[bytes, np.ndarray] = {}

    def reset(self) -> None:
        """Forget the previous solution (warm start, candidate, Lyapunov history)."""
        self._plan: Plan | None = None
        self._progress_gain = math.nan  # the gain in s of the plan in force over the one before
        self._previous_value: float | None = None
        self._previous_stage: float = 0.0
        self._failures = 0
        self._unfinished: _Unfinished | None = None
        # tries that failed from the state _failed_x0, with their NLP's id (see tries.py;
        # the NLPs live as long as the controller's settings)
        self._failed_here: set[tuple[int, Try]] = set()
        self._failed_x0: np.ndarray | None = None
        # the inputs of the last plan on the previous path (set_path keeps them): the guided
        # start drives them from the robot's state, see _guided_guess
        self._carried_inputs: np.ndarray | None = None
        # with max_accel: the input commanded over the step before this one (solve())
        self._input_before: np.ndarray | None = None

    # ----------------------------------------------------------------- the terminal condition
    @abstractmethod
    def _terminal_condition(self) -> TerminalCondition:
        """Return the terminal condition and offset cost of the formulation."""

    @abstractmethod
    def _terminal_parameters(self) -> np.ndarray:
        """Return the values of the terminal condition's parameters (path, or target).

        Raises:
            RuntimeError: if there is no path (or target) yet.

        """

    @abstractmethod
    def _progress(self, x: np.ndarray, s_min: float = 0.0) -> float:
        """Return the path progress s nearest the pose of x, at least s_min (nan: no path)."""

    @abstractmethod
    def _terminal_state(self, s: float) -> np.ndarray | None:
        """Return the terminal steady state g_p(s) (None when it is free)."""

    @abstractmethod
    def _reference_value(self, plan: Plan) -> np.ndarray:
        """Return the value of the NLP's reference variable r for a plan."""

    @abstractmethod
    def _progress_of(self, r: np.ndarray) -> float:
        """Return the path progress s a value of r stands for (nan: no path)."""

    @abstractmethod
    def _heading_reference(self, x: np.ndarray) -> float:
        """Return the heading to unwrap a measured one towards when there is no plan."""

    # ----------------------------------------------------------------- the NLPs
    def _structure(self) -> tuple:
        """Return what the NLP's shape depends on: a change empties the cache."""
        c = self._config
        terminal = self._terminal_condition()
        return (c.horizon, c.step, c.cost_exponent, c.farkas_margin, c.faces_per_obstacle,
                c.solver, c.max_iterations, c.tolerance, c.compile, c.footprint,
                tuple(sorted((k, repr(v)) for k, v in c.solver_options.items())),
                terminal.family, terminal.num_params, c.max_accel)

    def _slot_shape(self, selected: list[ConvexPolygon]) -> tuple[int, int]:
        """Return (slots, faces) of the NLP that holds the selected obstacles."""
        c = self._config
        if not selected:
            return 0, 0
        # faces rounded up to a multiple of 4 so that boxes and octagons share few builds
        faces = max(o.num_faces for o in selected)
        faces = min(c.faces_per_obstacle, 4 * math.ceil(faces / 4)) if faces > 4 else faces
        return len(selected), max(faces, 3)

    def _build(self, slots: int, faces: int) -> Nlp:
        """Build the NLP of an obstacle shape for the settings in force."""
        terminal = self._terminal_condition()
        return build_nlp(formulate(self._model, self._config, terminal, slots, faces),
                         self._config)

    @property
    def _nlps(self) -> dict[tuple[int, int], Nlp]:
        """The NLPs built for the settings in force, by shape (slots, faces)."""
        return self._shapes.built()

    def _nlp_for(self, slots: int, faces: int) -> Nlp:
        """Return the NLP for this obstacle shape, built (or fetched from the cache) now."""
        return self._shapes.get((slots, faces))

    def _nlp_holding(self, active: list[ConvexPolygon]
                     ) -> tuple[Nlp, list[ConvexPolygon]]:
        """Return an NLP for the active obstacles and the ones it holds (see NlpShapes.hold)."""
        nlp, count = self._shapes.hold(self._slot_shape(active))
        return nlp, active[:count]

    def prepare(self, max_obstacles: int | None = None) -> None:
        """Build the NLPs for 0..max_obstacles obstacles in reach, so no control step waits.

        For boxes (4 faces), for polygons of faces_per_obstacle (what sensed obstacles
        become) and for the face counts of the obstacles set now: an NLP holds obstacles with
        fewer faces too. Their IPOPTs too (fallback, cold start): with a
        wall budget a step builds one only if the build fits in what is left of it, so one
        not built ahead may never be there when it is needed. From then on a control step builds no
        NLP, in any thread (see NlpShapes): with more obstacles active than max_obstacles,
        the NLP holds the nearest ones and the solution is checked against all of them.

        Args:
            max_obstacles: the largest count to prepare (config.obstacle_slots by default).

        """
        c = self._config
        count = c.obstacle_slots if max_obstacles is None else max_obstacles
        faces = sorted({4, c.faces_per_obstacle}
                       | {self._slot_shape([o])[1] for o in self._inflated})
        shapes = [(0, 0)] + [(k, f) for k in range(1, count + 1) for f in faces]
        for shape in shapes:
            nlp = self._nlp_for(*shape)
            nlp.fallback_solver()
            if shape[0]:
                nlp.cold_solver()
        self._shapes.prepared = True

    def wait_compiled(self) -> None:
        """Block until the background compilations of the built NLPs are done (or failed)."""
        for nlp in self._nlps.values():
            nlp.finish_compilation(wait=True)

    def _prepare_nlp(self, active: list[ConvexPolygon], x0: np.ndarray
                     ) -> tuple[Nlp, np.ndarray, list[ConvexPolygon]]:
        """Return the NLP for the active obstacles, its parameters and the ones it holds."""
        nlp, held = self._nlp_holding(active)
        # with an iteration budget, which functions run must not depend on timing either
        nlp.finish_compilation(wait=self._config.budget == 'iterations')
        if nlp.iteration_time <= 0.0:
            # never solved: its fatrop is bounded by its siblings' time per iteration
            nlp.iteration_time = self._shapes.iteration_time_estimate(nlp)
        self._last_nlp = nlp
        form = nlp.formulation
        params = parameter_vector(x0, self._config.cost_weights(),
                                  obstacle_parameters(held, form.slots, form.faces),
                                  self._terminal_parameters(), self._input_before)
        return nlp, params, held

    def _pack(self, plan: Plan, nlp: Nlp) -> np.ndarray:
        form = nlp.formulation
        steady = self._terminal_state(plan.s) if form.layout.xs.size else None
        return form.pack(plan.x, self._reference_value(plan), plan.u, plan.mu, steady,
                         self._input_before)

    def _multipliers(self, x: np.ndarray, selected: list[ConvexPolygon],
                     nlp: Nlp) -> np.ndarray:
        """Return multipliers that are feasible for the states x wherever x is clear."""
        form = nlp.formulation
        if self._body is not None:
            _, directions = self._separation(x, selected[:form.slots])
            return dual_multipliers(x, self._body, selected, form.slots, form.faces,
                                    self._model.angle_index, directions[1:])
        return feasible_multipliers(x, selected, form.slots, form.faces)

    # ----------------------------------------------------------------- obstacles in reach
    def _speed_bound(self) -> float:
        return float(np.max(np.abs(self._model.u_max[:1])))

    def _reachable(self, x0: np.ndarray) -> ObstacleSet:
        """Return the inflated obstacles the horizon can reach, nearest first.

        A polygon's points stay within r_c of the robot's origin, so it reaches r_c further
        (between the samples too: no point can touch an obstacle beyond this).
        """
        c = self._config
        reach = self._speed_bound() * c.step * c.horizon + self._body_radius + 1e-3
        chosen, _ = self._obstacle_set.near(x0[None, :2], reach)
        return self._obstacle_set.subset(chosen)

    def _activation_distance(self) -> float:
        c = self._config
        if c.activation_distance is not None:
            return c.activation_distance
        # half a step (v_max h / 2): few re-solves with few obstacles in the NLP, where a
        # wider band holds many more and builds many more NLP shapes (see
        # docs/design/mpc.md, section "Default activation distance")
        return 0.5 * self._speed_bound() * c.step

    def _near_trajectory(self, x: np.ndarray, u: np.ndarray, reachable: ObstacleSet,
                         distance: float) -> list[ConvexPolygon]:
        """Return the reachable obstacles within distance of the plan (x, u), nearest first.

        A circle: of the positions x. A polygon: whose clearance from the polygon at some
        pose x_l exceeds what the motion needs there by at most distance (exact distances,
        after a cheap bound has left out those further than r_c + distance + that).
        """
        if self._body is None:
            chosen, _ = reachable.near(x[:, :2], distance)
            return [reachable.obstacles[i] for i in chosen]
        if not len(reachable):
            return []
        # x_0 is not constrained: only its Farkas margin, as for a circle
        required = np.concatenate([[self._config.farkas_margin], self._required_clearance(x, u)])
        bound = (reachable.signed_distance_lower_bound(x[:, :2]) - self._body_radius
                 - required[:, None])
        near = [reachable.obstacles[i]
                for i in np.flatnonzero(np.min(bound, axis=0) <= distance)]
        signed, _ = self._separation(x, near)
        slack = np.min(signed - required[:, None], axis=0, initial=np.inf)
        chosen = np.flatnonzero(slack <= distance)
        order = np.argsort(slack[chosen], kind='stable')
        return [near[i] for i in chosen[order]]

    # ----------------------------------------------------------------- the polygon footprint
    def _separation(self, x: np.ndarray, obstacles: Sequence[ConvexPolygon]
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Return polygon_separation of the polygon at every pose of x, (N+1, K) and (N+1, K, 2).

        Memoised per plan and obstacle (a step asks about the same candidate and the same
        solution several times: for the obstacles near it, its verification, its
        multipliers), so each pair is computed once; emptied at every solve(). An entry holds
        its obstacle, so that no other object can take over its id() meanwhile.
        """
        body = self._body
        assert body is not None  # only called for a polygonal footprint
        x = np.asarray(x, dtype=float)
        key = x.tobytes()
        if key not in self._geometry and len(self._geometry) >= MAX_CACHED_PLANS:
            self._geometry.pop(next(iter(self._geometry)))  # the oldest
        entry = self._geometry.setdefault(key, {})
        missing = list({id(o): o for o in obstacles if id(o) not in entry}.values())
        if missing:
            angle = x[:, self._model.angle_index]
            cos, sin = np.cos(angle)[:, None], np.sin(angle)[:, None]
            local = body.vertices
            corners = np.stack([cos * local[:, 0] - sin * local[:, 1] + x[:, :1],
                                sin * local[:, 0] + cos * local[:, 1] + x[:, 1:2]], axis=-1)
            signed, direction = polygon_separation(corners, ObstacleSet(missing))
            for j, o in enumerate(missing):
                entry[id(o)] = (o, signed[:, j], direction[:, j])
        if not obstacles:
            return np.zeros((len(x), 0)), np.zeros((len(x), 0, 2))
        columns = [entry[id(o)] for o in obstacles]
        return (np.stack([c[1] for c in columns], axis=1),
                np.stack([c[2] for c in columns], axis=1))

    def _required_clearance(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Return the clearance x_1..x_N need: farkas_margin + h/2 of the faster adjacent step.

        Over a step every point of the body moves at most h sweep_rate(x_l, u_l) (exact |.|
        here); a pose at least half of that from an obstacle on both of its steps keeps the
        continuous motion between the samples clear. After x_N, u_N = 0: no motion.
        """
        x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
        key = x.tobytes() + u.tobytes()
        required = self._clearance_memo.get(key)
        if required is not None:
            return required
        n = len(u)
        rate_map = self._sweep_maps.get(n)
        if rate_map is None:
            rate_map = self._sweep_maps[n] = self._sweep_exact.map(n)
        rates = np.asarray(rate_map(x[:-1].T, u.T)).reshape(-1)
        after = np.append(rates[1:], 0.0)
        c = self._config
        required = c.farkas_margin + c.step / 2 * np.maximum(rates, after)
        if len(self._clearance_memo) >= MAX_CACHED_PLANS:
            self._clearance_memo.pop(next(iter(self._clearance_memo)))  # the oldest
        self._clearance_memo[key] = required
        return required

    # ----------------------------------------------------------------- the candidate
    def _unwrap(self, x: np.ndarray) -> np.ndarray:
        """Put the measured heading on the branch nearest the prediction (or the path)."""
        x = np.array(x, dtype=float)
        k = self._model.angle_index
        reference = self._plan.x[1, k] if self._plan is not None else self._heading_reference(x)
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

    def _candidate(self, x0: np.ndarray) -> Plan:
        """The proof's candidate: shift the last plan and append the terminal steady state.

        Without a last plan: stand still, and end in the steady state of the initial s.
        Its multipliers depend on the NLP (obstacles held): see _multipliers.
        """
        n = self._config.horizon
        if self._plan is None:
            s0 = self._progress(x0)
            u = np.zeros((n, self._model.nu))
            x = np.tile(x0, (n + 1, 1))
            x_s = self._terminal_state(s0)
            x[-1] = x_s if x_s is not None else x0
            return Plan(x=x, u=u, s=s0, mu=np.zeros(0), value=math.inf)
        prev = self._plan
        _, u_s = self._model.steady_state(prev.x[-1, :3])
        u = np.vstack([prev.u[1:], np.asarray(u_s, dtype=float).reshape(1, -1)])
        return Plan(x=self._rollout(x0, u), u=u, s=prev.s, mu=np.zeros(0), value=math.inf)

    def _guided_guess(self, x0: np.ndarray, active: list[ConvexPolygon], nlp: Nlp) -> Plan:
        """An infeasible but informative start: the motion in hand, ended on the path."""
        plan = self._guided_motion(x0)
        plan.mu = self._multipliers(plan.x, active, nlp)
        return plan

    def _guided_motion(self, x0: np.ndarray) -> Plan:
        """The guided start's states and inputs (its multipliers depend on the NLP).

        After a new path, the inputs of the last plan on the old one shifted by a step (the
        robot was carrying them out, and they avoid what the old plan avoided); else drive
        forward at half speed. With max_accel, moved into the rate bounds from the input
        before (rate_limited_inputs: a base at rest does not jump to half speed, and the
        plan must end at rest). Either is rolled out from x0, and its last state replaced by
        the steady state on the path nearest it.
        """
        n = self._config.horizon
        u = np.zeros((n, self._model.nu))
        carried = self._carried_inputs
        if carried is not None and len(carried) == n:
            u[:-1] = carried[1:]
        else:
            u[:, 0] = 0.5 * self._model.u_max[0]
        if self._input_before is not None:
            u = rate_limited_inputs(u, self._input_before,
                                    np.asarray(self._config.max_accel) * self._config.step)
        x = self._rollout(x0, u)
        s = self._progress(x[-1], s_min=self._progress(x0))
        terminal = self._terminal_state(s)
        if terminal is not None:
            x[-1] = terminal
        return Plan(x=x, u=u, s=s, mu=np.zeros(0), value=math.inf)

    # ----------------------------------------------------------------- verification
    def _violation(self, w: np.ndarray, params: np.ndarray, obstacles: ObstacleSet,
                   nlp: Nlp) -> float:
        """Return the largest constraint violation, collisions checked geometrically.

        The geometric check does not trust the multipliers: whatever the solver did with
        them, every predicted position l = 1..N must clear every given obstacle (those of the
        NLP, or every reachable one).
        """
        form = nlp.formulation
        g = np.asarray(form.g_fn(w, params)).reshape(-1)
        viol = np.maximum(form.lbg - g, 0) + np.maximum(g - form.ubg, 0)
        viol_w = np.maximum(form.lbw - w, 0) + np.maximum(w - form.ubw, 0)
        worst = max(np.max(viol, initial=0.0), np.max(viol_w, initial=0.0))
        return max(float(worst),
                   self._penetration(w[form.layout.x], w[form.layout.u], obstacles))

    def _penetration(self, x: np.ndarray, u: np.ndarray, obstacles: ObstacleSet) -> float:
        """Return how far the plan's poses x_1..x_N fall short of their clearance (0: clear).

        A circle: the positions against the inflated obstacles, by the Farkas margin. A
        polygon: the exact distance of the polygon at each pose against the clearance its
        motion needs (_required_clearance); the exact distances are computed only for the
        obstacles a cheap bound (r_c around the positions) cannot clear.
        """
        if self._body is None:
            depth = (self._config.farkas_margin
                     - obstacles.signed_distance_lower_bound(x[1:, :2]))
            return float(np.max(depth, initial=0.0))
        if not len(obstacles):
            return 0.0
        required = self._required_clearance(x, u)[:, None]
        bound = obstacles.signed_distance_lower_bound(x[1:, :2]) - self._body_radius
        unclear = [obstacles.obstacles[i]
                   for i in np.flatnonzero(np.any(bound < required, axis=0))]
        if not unclear:
            return 0.0
        depth = required - self._separation(x, unclear)[0][1:]
        return float(np.max(depth, initial=0.0))

    def _collision_free(self, plan: Plan, obstacles: ObstacleSet) -> bool:
        """Say whether the plan's poses x[1:] clear every given (inflated) obstacle."""
        return self._penetration(plan.x, plan.u, obstacles) <= 0.0

    def _run_solver(self, nlp: Nlp, w0: np.ndarray, params: np.ndarray,
                    active: ObstacleSet, solver: ca.Function | None = None) -> SolveAttempt:
        """Solve from w0 (with the NLP's solver, or the given one) and verify the answer.

        The solver gets what is left of the step's budget; a call cut by it (or not started)
        marks the step as timed out.
        """
        budget = self._budget
        run = run_solver(nlp, w0, params, solver, time_limit=budget.remaining(),
                         iteration_limit=budget.iterations)
        budget.spend(run.iterations)
        if run.cut:
            budget.timed_out = True
        verified = (run.success
                    and self._violation(run.w, params, active, nlp) <= FEASIBILITY_TOLERANCE)
        return SolveAttempt(verified=verified, w=run.w, value=run.value if verified else math.inf,
                            status=run.status, iterations=run.iterations, seconds=run.seconds,
                            cut=run.cut)

    def _optimise(self, nlp: Nlp, w_candidate: np.ndarray, params: np.ndarray,
                  x0: np.ndarray, active: list[ConvexPolygon],
                  previous: Plan | None = None) -> SolveAttempt:
        """Make the tries solver_tries() gives for this situation; keep the best.

        The tries run in order while the step's budget lasts, and stop at the first verified
        solution. The first backend try always runs (with what is left, maybe nothing: then
        it is a cut run that returns its start); any other only if the budget allows it, the
        build of an IPOPT not built yet included (a build cannot be cut: prepare() builds
        them ahead). The returned attempt counts the iterations and time of every try, and
        is the verified one, else the last backend try's (else the first try's).

        A try the budget cut is kept (_Unfinished) for the next step to go on with, if the
        same NLP comes up there and the state has not moved (see tries.py).
        """
        unfinished = self._unfinished
        continuation: _Unfinished | None = None
        if unfinished is not None and unfinished.nlp is nlp:
            self._unfinished = None  # continued once, or moved away from
            if _stood_still(unfinished.x0, x0) and _same_polygons(unfinished.held, active):
                continuation = unfinished
        if not _stood_still(self._failed_x0, x0):
            self._failed_here = set()  # the robot moved: every try is worth making again
            self._failed_x0 = x0.copy()
        situation = Situation(
            plan_moves=_plan_moves(self._plan, self._progress_gain),
            obstacles_active=bool(active), previous_round=previous is not None,
            has_fallback=nlp.has_fallback,
            continuation=continuation.solver if continuation is not None else None,
            failed=frozenset(t for n, t in self._failed_here if n == id(nlp)))
        starts: dict[Start, np.ndarray] = {Start.CANDIDATE: w_candidate}
        if continuation is not None:
            starts[Start.CONTINUATION] = continuation.w

        def start_of(start: Start) -> np.ndarray:
            if start not in starts:
                if start is Start.PREVIOUS_ROUND:
                    assert previous is not None
                    previous.mu = self._multipliers(previous.x, active, nlp)
                    plan = previous
                else:
                    plan = self._guided_guess(x0, active, nlp)
                starts[start] = self._pack(plan, nlp)
            return starts[start]

        active_set = ObstacleSet(active)
        best: SolveAttempt | None = None
        iterations, seconds = 0, 0.0
        for attempt_try in solver_tries(situation):
            kind = attempt_try.solver
            first_backend = best is None and kind is Solver.BACKEND
            if not first_backend and not self._budget.allows(_build_time(nlp, kind)):
                continue
            self._tries.append(attempt_try)
            attempt = self._run_solver(nlp, start_of(attempt_try.start), params, active_set,
                                       _solver_of(nlp, kind))
            iterations += attempt.iterations
            seconds += attempt.seconds
            origin = (continuation.origin if attempt_try.start is Start.CONTINUATION
                      else attempt_try)
            steps = (continuation.steps + 1 if attempt_try.start is Start.CONTINUATION
                     and continuation is not None else 1)
            if not attempt.verified and (not attempt.cut or steps > MAX_CONTINUED_STEPS):
                # failed outright, or cut in every step it was given: not first again while
                # the robot stands here
                self._failed_here.update({(id(nlp), attempt_try), (id(nlp), origin)})
            if (attempt.cut and not attempt.verified and attempt.iterations > 0
                    and steps <= MAX_CONTINUED_STEPS and np.all(np.isfinite(attempt.w))):
                self._unfinished = _Unfinished(nlp, x0.copy(), attempt.w, kind, tuple(active),
                                               origin, steps)
            if attempt.verified:
                best = attempt._replace(status=attempt.status + kind.label)
                break
            if best is None or kind is Solver.BACKEND:
                best = attempt
        assert best is not None  # the first backend try always runs
        return best._replace(iterations=iterations, seconds=seconds)

    # ----------------------------------------------------------------- constraint generation
    def _generate_constraints(self, x0: np.ndarray, candidate: Plan,
                              reachable: ObstacleSet) -> _Rounds:
        """Solve with the obstacles near the candidate; add those the solution came near.

        The NLP may hold fewer than asked for (_nlp_holding: no shape is built within a
        prepared step); the solution is then checked against every reachable obstacle.
        """
        activation = self._activation_distance()
        active = self._resumed_round(x0, reachable)
        if active is None:
            active = self._near_trajectory(candidate.x, candidate.u, reachable, activation)
            before = self._input_before
            if (before is not None and np.any(np.abs(before) > STANDING_INPUT)
                    and not _plan_moves(self._plan, self._progress_gain)):
                # the candidate stands still (a new path) but with max_accel the robot
                # cannot: the solution goes on with the motion in hand, among the obstacles
                # near it (a re-plan at speed held none near the candidate, and its rounds
                # overran the step, docs/real_robot.md)
                guided = self._guided_motion(x0)
                active = active + [o for o in self._near_trajectory(
                    guided.x, guided.u, reachable, activation) if not any(o is a for a in active)]
        iterations, seconds = 0, 0.0
        previous: Plan | None = None  # the last round's solution, a start for the next
        for round_ in range(MAX_ACTIVATION_ROUNDS + 1):
            nlp, params, held = self._prepare_nlp(active, x0)
            candidate.mu = self._multipliers(candidate.x, held, nlp)
            w_candidate = self._pack(candidate, nlp)
            # the candidate must clear every reachable obstacle, not only the active ones
            candidate_ok = (self._violation(w_candidate, params, reachable, nlp)
                            <= FEASIBILITY_TOLERANCE)
            candidate_value = (float(nlp.formulation.cost_fn(w_candidate, params))
                               if candidate_ok else math.inf)
            attempt = self._optimise(nlp, w_candidate, params, x0, held, previous)
            iterations += attempt.iterations
            seconds += attempt.seconds
            if not attempt.verified:
                break
            layout = nlp.formulation.layout
            states, inputs = attempt.w[layout.x], attempt.w[layout.u]
            missed = [o for o in self._near_trajectory(states, inputs, reachable, activation / 2)
                      if not any(o is a for a in held)]
            if not missed:
                break
            # no further round at the limit, without time for it, or without an NLP with
            # room for more: the solution stands if it clears every reachable obstacle
            # (feasible for the full problem, then)
            if (round_ == MAX_ACTIVATION_ROUNDS or len(held) < len(active)
                    or not self._budget.allows()):
                if self._penetration(states, inputs, reachable) > FEASIBILITY_TOLERANCE:
                    attempt = attempt._replace(
                        verified=False,
                        status=f'{attempt.status} (hits an obstacle left out of the NLP)')
                break
            active = active + missed
            previous = Plan(x=states, u=inputs, s=self._progress_of(attempt.w[layout.r[-1]]),
                            mu=np.zeros(0), value=math.inf)
        return _Rounds(nlp=nlp, params=params, w_candidate=w_candidate,
                       candidate_ok=candidate_ok, candidate_value=candidate_value,
                       attempt=attempt._replace(iterations=iterations, seconds=seconds),
                       active=held, rounds=round_ + 1)

    def _resumed_round(self, x0: np.ndarray, reachable: ObstacleSet
                       ) -> list[ConvexPolygon] | None:
        """Return the obstacles of the round the budget cut last step, to take it up again.

        Only when the robot has not moved since (the state within CONTINUE_TOLERANCE) and
        every obstacle that round held is still there, unchanged: then this step starts with
        that round, and its cut try goes on first (see _optimise), rather than solving the
        rounds before it again. Without this a step whose rounds need more iterations
        together than one step has would spend its budget on the same first round at every
        step, and the cut round would never get further (see docs/design/mpc.md, section
        "Resuming a cut round (_resumed_round)").

        Returns:
            The reachable obstacles that round held, in its order, or None.

        """
        unfinished = self._unfinished
        if unfinished is None or not _stood_still(unfinished.x0, x0):
            return None
        resumed = []
        for old in unfinished.held:
            match = next((o for o in reachable.obstacles if _same_polygons((o,), (old,))), None)
            if match is None:
                return None
            resumed.append(match)
        return resumed

    # ----------------------------------------------------------------- the step
    def solve(self, x: np.ndarray, previous_input: np.ndarray | None = None) -> MpcSolution:
        """Compute the input for the measured state x.

        Takes at most about config.solve_budget() seconds of solving (see the module's note):
        past it the verified shifted candidate is applied, and the solution is timed_out.

        With config.max_accel the first input is bounded around previous_input, the input
        commanded over the step before (the caller knows what it sent; after a stop, the
        measured twist); None: the last plan's first input (it was applied), or rest.

        Raises:
            ValueError: if x is not a finite state of the model's size.
            RuntimeError: if no path (or target) has been set.

        """
        self._budget = budget = _Budget.of(self._config, self.clock)
        self._tries = []
        x = np.asarray(x, dtype=float).reshape(-1)
        if x.shape != (self._model.nx,) or not np.all(np.isfinite(x)):
            msg = f'state must be {self._model.nx} finite numbers, got {x}'
            raise ValueError(msg)
        self._terminal_parameters()  # RuntimeError without a path (or target)
        self._geometry.clear()  # the memos hold this step's plans only
        self._clearance_memo.clear()
        x0 = self._unwrap(x)
        self._input_before = self._before(previous_input)
        reachable = self._reachable(x0)
        candidate = self._candidate(x0)
        result = self._generate_constraints(x0, candidate, reachable)
        self._last_active = tuple(result.active)
        attempt = result.attempt
        decision = decide(
            solver_verified=attempt.verified, solver_value=attempt.value,
            candidate_ok=result.candidate_ok, candidate_value=result.candidate_value,
            has_previous_plan=self._plan is not None,
            candidate_collision_free=self._collision_free(candidate, reachable),
            timed_out=budget.timed_out)
        if decision is Decision.SOLVER:
            self._failures = 0
        elif decision.is_failure:
            self._failures += 1
        status = f'{attempt.status} ({decision.value})' if decision.value else attempt.status
        if decision is Decision.STOP:
            return self._stop(x0, status, attempt, len(reachable), len(result.active),
                              timed_out=budget.timed_out)
        if decision is Decision.SOLVER:
            w, layout = attempt.w, result.nlp.formulation.layout
            plan = Plan(x=w[layout.x], u=w[layout.u], s=self._progress_of(w[layout.r[-1]]),
                         mu=w[layout.mu].reshape(-1), value=attempt.value)
        else:
            # the candidate; off the prediction it was not verified, so its cost is computed
            # here (the proof's bound does not hold for it)
            candidate.value = (result.candidate_value if result.candidate_ok else float(
                result.nlp.formulation.cost_fn(result.w_candidate, result.params)))
            plan = candidate

        lyapunov_ok = None
        if self._previous_value is not None:
            bound = self._previous_value - self._previous_stage
            lyapunov_ok = plan.value <= bound + LYAPUNOV_TOLERANCE * (1 + abs(bound))
        weights = np.array(self._config.cost_weights().as_vector())
        self._previous_stage = float(self._stage_fn(plan.x[0], plan.u[0], plan.x[-1], weights))
        self._previous_value = plan.value
        self._progress_gain = (plan.s - self._plan.s) if self._plan is not None else math.nan
        self._plan = plan
        return MpcSolution(
            u0=np.clip(plan.u[0], self._model.u_min, self._model.u_max),
            x_pred=plan.x.copy(), u_pred=plan.u.copy(), s=plan.s,
            value=plan.value, success=decision is Decision.SOLVER, status=status,
            solve_time_s=attempt.seconds, iterations=attempt.iterations,
            source=decision.source, lyapunov_ok=lyapunov_ok, failures=self._failures,
            obstacles_in_reach=len(reachable), obstacles_active=len(result.active),
            rounds=result.rounds, solver_verified=attempt.verified,
            timed_out=budget.timed_out, tries=tuple(self._tries),
        )

    def _before(self, previous_input: np.ndarray | None) -> np.ndarray | None:
        """Return the input the rate bounds start from (None without max_accel)."""
        if self._config.max_accel is None:
            return None
        if previous_input is not None:
            u = np.asarray(previous_input, dtype=float).reshape(-1)
            if u.shape == (self._model.nu,) and np.all(np.isfinite(u)):
                return np.clip(u, self._model.u_min, self._model.u_max)
        if self._plan is not None:
            return np.asarray(self._plan.u[0], dtype=float).copy()
        return np.zeros(self._model.nu)

    def _stop(self, x0: np.ndarray, status: str, attempt: SolveAttempt, in_reach: int,
              active: int, *, timed_out: bool = False) -> MpcSolution:
        """No verified plan: command the steady-state input (stand still) and start over."""
        n = self._config.horizon
        _, u_s = self._model.steady_state(x0[:3])
        u_s = np.asarray(u_s, dtype=float).reshape(-1)
        kept = self._failures, self._unfinished, self._failed_here, self._failed_x0
        self.reset()
        # the robot stands still: a solve the budget cut goes on at the next step, and the
        # tries that failed here go last
        self._failures, self._unfinished, self._failed_here, self._failed_x0 = kept
        return MpcSolution(
            u0=u_s, x_pred=np.tile(x0, (n + 1, 1)), u_pred=np.tile(u_s, (n, 1)),
            s=math.nan, value=math.nan, success=False, status=status,
            solve_time_s=attempt.seconds, iterations=attempt.iterations,
            source=PlanSource.STOP, lyapunov_ok=None, failures=self._failures,
            obstacles_in_reach=in_reach, obstacles_active=active, timed_out=timed_out,
            tries=tuple(self._tries),
        )


class PathReferenceMPC(MpcBase):
    """The paper's MPC: the prediction ends in a steady state on the path, x_N = g_p(s_k).

    Args:
        model: the robot model.
        config: settings (MpcConfig()).
        obstacles: convex obstacles as described; inflated here by config.inflation().
        path: the reference path p(s); p(0) should be the robot's start pose.

    """

    def __init__(self, model: RobotModel, config: MpcConfig | None = None, *,
                 obstacles: Sequence[ConvexPolygon] = (),
                 path: ReferencePath | None = None) -> None:
        self._path = path
        super().__init__(model, config, obstacles=obstacles)

    @property
    def path(self) -> ReferencePath | None:
        """The reference path in force (None before one is set)."""
        return self._path

    def set_path(self, path: ReferencePath) -> None:
        """Use a new reference path; s restarts at the robot's projection onto it.

        The proof's candidate does not carry over (the old plan does not end on the new
        path), but the old plan's inputs do, as the guided start (_guided_guess): a robot
        re-planned at speed is carrying them out.
        """
        previous = self._plan
        self._path = path
        self.reset()
        if previous is not None and _plan_moves(previous, math.inf):
            self._carried_inputs = previous.u.copy()

    def _require_path(self) -> ReferencePath:
        if self._path is None:
            msg = 'no reference path: call set_path() first'
            raise RuntimeError(msg)
        return self._path

    def _terminal_condition(self) -> TerminalCondition:
        return path_terminal(self._model, self._require_path())

    def _terminal_parameters(self) -> np.ndarray:
        return self._require_path().parameters()

    def _progress(self, x: np.ndarray, s_min: float = 0.0) -> float:
        return self._require_path().project(x[:3], s_min=s_min)

    def _terminal_state(self, s: float) -> np.ndarray | None:
        x_s, _ = self._model.steady_state(self._require_path().pose(s))
        return np.asarray(x_s, dtype=float).reshape(-1)

    def _reference_value(self, plan: Plan) -> np.ndarray:
        return np.array([plan.s])

    def _progress_of(self, r: np.ndarray) -> float:
        return float(r[0])

    def _heading_reference(self, x: np.ndarray) -> float:
        path = self._require_path()
        return float(path.pose(path.project(x[:3]))[2])
