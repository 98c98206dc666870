# SPDX-License-Identifier: Apache-2.0
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

A step's solving is bounded (budget.py: wall time on the robot, solver iterations in the
evaluation). Which tries an NLP solve makes, in which order, is tries.py's table
(solver_tries); _optimise only makes them. Once the budget is spent, decide() applies the
verified shifted candidate (CANDIDATE_TIMEOUT), or stops if there is none. Nothing
unverified is ever applied: the budget only decides how hard the step tries to beat the
candidate.

The NLP itself is formulation.py (problem (6)); the solvers and their compilation are
backends.py; the footprint's clearance along a plan clearance.py; the candidate and the
guided start candidate.py; the budget budget.py; what a cut solve carries to the next step
continuation.py. PathReferenceMPC (path_mpc.py) and the tracking baseline say what the
terminal condition is.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import replace
import math
import time
from types import MappingProxyType
from typing import Callable, Mapping, NamedTuple, Sequence

import casadi as ca
import numpy as np

from mpc_local_planner.core.config import BudgetKind, MpcConfig
from mpc_local_planner.core.identity_memo import IdentityMemo
from mpc_local_planner.core.models import RobotModel
from mpc_local_planner.core.moving_obstacles import moving, stage_pad
from mpc_local_planner.core.mpc.backends import Nlp, run_solver, SolverRunner
from mpc_local_planner.core.mpc.budget import Budget, build_time, solver_of
from mpc_local_planner.core.mpc.built_nlps import shared_nlp
from mpc_local_planner.core.mpc.candidate import (
    guided_guess,
    Plan,
    plan_moves,
    rate_start,
    Rollout,
    shifted_candidate,
    STANDING_INPUT,
)
from mpc_local_planner.core.mpc.clearance import Clearance
from mpc_local_planner.core.mpc.continuation import resumed_round, same_polygons, SpotMemory
from mpc_local_planner.core.mpc.decision import (
    decide,
    Decision,
    LyapunovRecord,
    PlanSource,
)
from mpc_local_planner.core.mpc.formulation import stage_cost, TerminalCondition
from mpc_local_planner.core.mpc.nlp_shapes import NlpShapes, slot_shape
from mpc_local_planner.core.mpc.nlp_values import obstacle_parameters, parameter_vector
from mpc_local_planner.core.mpc.solution import MpcSolution, Rounds, SolveAttempt
from mpc_local_planner.core.mpc.tries import Situation, Solver, solver_tries, Start, Try
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet
from mpc_local_planner.core.paths import wrap_angle

__all__ = ['MpcBase', 'SolverProblem']

# Constraint-violation bound for accepting a solution or a candidate (metres, rad, m/s).
FEASIBILITY_TOLERANCE = 1e-5
# Re-solves with more obstacles when a solution came too close to one left out of the NLP.
MAX_ACTIVATION_ROUNDS = 3


class SolverProblem(NamedTuple):
    """What a solve hands the solver (see MpcBase.solver_problem)."""

    nlp: Nlp  # the NLP holding the obstacles
    params: np.ndarray  # its parameter vector: state, weights, obstacles, terminal condition
    w0: np.ndarray  # the start, packed as the NLP's decision vector


class MpcBase(ABC):
    """The per-step logic shared by the paper's MPC and the tracking-MPC baseline.

    Subclasses say what the terminal condition is (_terminal_condition(), the formulation's
    part) and what it means for the numbers of a plan (the other methods of the section
    'the terminal condition' below).

    Args:
        model: the robot model.
        config: settings (MpcConfig()).
        obstacles: convex obstacles as described; inflated here by config.inflation().
        runner: what runs an NLP's solver (backends.run_solver); a test gives a failing or
            slow stand-in here, or sets the `runner` attribute of an instance.

    """

    # The clock of the solve budget (seconds); a test may give an instance a fake one.
    clock: Callable[[], float] = staticmethod(time.perf_counter)

    def __init__(self, model: RobotModel, config: MpcConfig | None = None, *,
                 obstacles: Sequence[ConvexPolygon] = (),
                 runner: SolverRunner = run_solver) -> None:
        self.runner = runner
        self._model = model
        self._budget = Budget(self.clock)  # solve() starts one per step
        self._tries: list[Try] = []  # the tries of the step in progress
        self._config = config or MpcConfig()
        self._use_footprint()
        self._raw_obstacles: list[ConvexPolygon] = []
        self._inflated: list[ConvexPolygon] = []
        # each obstacle grown once while it stays: the laser's pieces come again at every
        # step, and growing them all again took a twentieth of the controller node's time
        # on BARN (issue 34)
        self._grown: IdentityMemo[ConvexPolygon, ConvexPolygon] = IdentityMemo()
        self._shapes = NlpShapes(self._structure, self._build)
        self._last_nlp: Nlp | None = None
        self._last_active: tuple[ConvexPolygon, ...] = ()
        self._rollout = Rollout(model)
        self._stage_fn = stage_cost(model, self._config.cost_exponent)
        # the versions of the problem's obstacles and settings (LyapunovRecord.case)
        self._problem_version = (0, 0)
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

        config.solving.solver, or IPOPT for a shape beyond its fatrop_stage_limit.
        """
        nlp = self._last_nlp
        if nlp is None:
            return self._config.solving.solver
        return nlp.backend + ('+compiled' if nlp.compiled else '')

    @property
    def inflated_obstacles(self) -> tuple[ConvexPolygon, ...]:
        """The obstacles as the NLP sees them: grown by config.inflation()."""
        return tuple(self._inflated)

    @property
    def holds_moving_obstacles(self) -> bool:
        """Whether some obstacle in force moves (it is predicted over the horizon)."""
        return self._moving

    @property
    def last_active_obstacles(self) -> tuple[ConvexPolygon, ...]:
        """The inflated obstacles the last solve held as Farkas constraints (its NLP's)."""
        return self._last_active

    @property
    def last_nlp(self) -> Nlp | None:
        """The NLP of the last solve (or solver_problem), None before the first."""
        return self._last_nlp

    def update_config(self, config: MpcConfig) -> None:
        """Apply new settings at the next solve; shape changes rebuild the NLP there."""
        old = self._config
        self._config = config
        if old != config:
            self._problem_version = (self._problem_version[0], self._problem_version[1] + 1)
        if old.structure_key() != config.structure_key():
            self._use_footprint()
            self._shapes.clear()  # the new shapes are built as steps need them
            self._stage_fn = stage_cost(self._model, config.cost_exponent)
            self.reset()
        if old.inflation(self._model.u_max[0]) != config.inflation(self._model.u_max[0]):
            self.set_obstacles(self._raw_obstacles)

    def set_obstacles(self, obstacles: Sequence[ConvexPolygon]) -> None:
        """Replace the obstacles (as described, not inflated).

        Raises:
            ValueError: if an obstacle has more faces than config.solving.faces_per_obstacle.

        """
        faces = self._config.solving.faces_per_obstacle
        for obstacle in obstacles:
            if obstacle.num_faces > faces:
                msg = (f'an obstacle has {obstacle.num_faces} faces, more than '
                       f'faces_per_obstacle={faces}')
                raise ValueError(msg)
        self._raw_obstacles = list(obstacles)
        inflation = self._config.inflation(float(self._model.u_max[0]))
        inflated = self._grow(self._raw_obstacles, inflation)
        if not same_polygons(self._inflated, inflated):
            self._problem_version = (self._problem_version[0] + 1, self._problem_version[1])
        self._inflated = inflated
        self._obstacle_set = ObstacleSet(self._inflated)
        # some obstacle moves (core/moving_obstacles.py): it is predicted over the horizon
        self._moving = any(moving(o) for o in inflated)
        self._last_active = ()

    def _grow(self, obstacles: list[ConvexPolygon], inflation: float) -> list[ConvexPolygon]:
        """Return the obstacles grown by inflation, each grown once while it stays."""
        return self._grown.map(obstacles, inflation,
                               lambda obstacle: obstacle.inflate(inflation))

    @property
    def clearance(self) -> Clearance:
        """The footprint's clearance from obstacles along plans (this step's memos)."""
        return self._clearance

    def _use_footprint(self) -> None:
        """Set up the geometry of config.footprint (nothing for a round robot)."""
        self._clearance = Clearance(self._model, self._config)

    def reset(self) -> None:
        """Forget the previous solution (warm start, candidate, Lyapunov history)."""
        self._plan: Plan | None = None
        self._progress_gain = math.nan  # the gain in s of the plan in force over the one before
        self._lyapunov = LyapunovRecord()
        # a plan of the solver's has been applied since this reset: the candidate's value
        # bounds the next (decision.decide's candidate_binds)
        self._bound_started = False
        self._failures = 0
        self._spot = SpotMemory()  # a cut solve to go on with, the tries failed here
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
        """Return what the NLPs depend on (a change empties the cache).

        The settings' structure_key() and the terminal condition's family and parameter count.
        """
        terminal = self._terminal_condition()
        return (self._config.structure_key(), terminal.family, terminal.num_params)

    def _build(self, slots: int, faces: int) -> Nlp:
        """Return the NLP of an obstacle shape for the settings in force (own record).

        Built now, unless an MPC of this process built the same problem (built_nlps.py).
        """
        return shared_nlp(self._model, self._config, self._terminal_condition(), slots, faces)

    @property
    def nlps(self) -> Mapping[tuple[int, int], Nlp]:
        """The NLPs built for the settings in force, by shape (slots, faces); read-only."""
        return MappingProxyType(self._shapes.built())

    def nlp_for(self, slots: int, faces: int) -> Nlp:
        """Return the NLP for this obstacle shape, built (or fetched from the cache) now."""
        return self._shapes.get((slots, faces))

    def _nlp_holding(self, active: list[ConvexPolygon]
                     ) -> tuple[Nlp, list[ConvexPolygon]]:
        """Return an NLP for the active obstacles and the ones it holds (see NlpShapes.hold)."""
        return self._shapes.holding(active, self._config.solving.faces_per_obstacle)

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
            max_obstacles: the largest count to prepare (config.solving.obstacle_slots by
                default).

        """
        c = self._config.solving
        count = c.obstacle_slots if max_obstacles is None else max_obstacles
        faces = sorted({4, c.faces_per_obstacle}
                       | {slot_shape([o], c.faces_per_obstacle)[1] for o in self._inflated})
        self._shapes.prepare([(0, 0)] + [(k, f) for k in range(1, count + 1) for f in faces])

    def wait_compiled(self) -> None:
        """Block until the background compilations of the built NLPs are done (or failed)."""
        for nlp in self.nlps.values():
            nlp.finish_compilation(wait=True)

    def _prepare_nlp(self, active: list[ConvexPolygon], x0: np.ndarray, *,
                     nlp: Nlp | None = None) -> tuple[Nlp, np.ndarray, list[ConvexPolygon]]:
        """Return the NLP for the active obstacles, its parameters and the ones it holds.

        Args:
            active: the obstacles to hold, nearest first.
            x0: the measured state.
            nlp: the NLP to use, holding all of active in its slots (a resumed round's: the
                one its cut try ran in); None: the one _nlp_holding picks.

        """
        if nlp is None:
            nlp, held = self._nlp_holding(active)
        else:
            held = active
        # with an iteration budget, which functions run must not depend on timing either
        self._shapes.ready(nlp, wait=self._config.solving.budget is BudgetKind.ITERATIONS)
        self._last_nlp = nlp
        form = nlp.formulation
        params = parameter_vector(x0, self._config.cost_weights(),
                                  obstacle_parameters(held, form.slots, form.faces),
                                  self._terminal_parameters(), self._input_before)
        return nlp, params, held

    def solver_problem(self, x0: np.ndarray, obstacles: Sequence[ConvexPolygon] = (),
                       start: Start = Start.GUIDED) -> SolverProblem:
        """Return the NLP a solve from x0 holding these obstacles runs, its parameters, a start.

        To run a solver outside solve() (backends.run_solver), as a benchmark or a test does.
        The NLP is the one a step would pick (built now if need be; it becomes last_nlp), and
        the rate bounds start where a step's would (with max_accel: the plan in force's).

        Args:
            x0: the measured state.
            obstacles: the (inflated) obstacles to hold, nearest first.
            start: Start.GUIDED (the guided start) or Start.CANDIDATE (the proof's shifted
                candidate of the plan in force), with multipliers for the obstacles held.

        Raises:
            ValueError: for another start (those need a step in progress).

        """
        x0 = np.asarray(x0, dtype=float)
        self._input_before = self._before(None)
        self._clearance.clear(self._input_before)
        nlp, params, held = self._prepare_nlp(list(obstacles), x0)
        if start is Start.GUIDED:
            plan = self._guided_guess(x0, held, nlp)
        elif start is Start.CANDIDATE:
            plan = self._candidate(x0)
            plan = replace(plan, mu=self._multipliers(plan.x, held, nlp))
        else:
            msg = f'solver_problem gives the guided or the candidate start, not {start}'
            raise ValueError(msg)
        return SolverProblem(nlp, params, self._pack(plan, nlp))

    def _pack(self, plan: Plan, nlp: Nlp) -> np.ndarray:
        form = nlp.formulation
        steady = self._terminal_state(plan.s) if form.layout.xs.size else None
        return form.pack(plan.x, self._reference_value(plan), plan.u, plan.mu, steady,
                         self._input_before)

    def _multipliers(self, x: np.ndarray, selected: list[ConvexPolygon],
                     nlp: Nlp) -> np.ndarray:
        """Return multipliers that are feasible for the states x wherever x is clear."""
        return self._clearance.multipliers(x, selected, nlp.formulation)

    # ----------------------------------------------------------------- obstacles in reach
    def _speed_bound(self) -> float:
        return float(np.max(np.abs(self._model.u_max[:1])))

    def reachable_obstacles(self, x0: np.ndarray) -> list[ConvexPolygon]:
        """Return the inflated obstacles the horizon can reach from x0, nearest first."""
        return list(self._reachable(np.asarray(x0, dtype=float)).obstacles)

    def _reachable(self, x0: np.ndarray) -> ObstacleSet:
        """Return the inflated obstacles the horizon can reach, nearest first.

        A polygon's points stay within r_c of the robot's origin, so it reaches r_c further
        (between the samples too: no point can touch an obstacle beyond this).
        """
        c = self._config
        reach = self._speed_bound() * c.step * c.horizon + self._clearance.body_radius + 1e-3
        if self._moving:
            # a moving obstacle comes towards the robot too: as far as it can go in the
            # horizon (its speed and growth over N h, and the half step around the last
            # sample) further
            reach = reach + np.array([
                (o.speed + o.growth) * c.step * c.horizon + stage_pad(o, c.step)
                if moving(o) else 0.0 for o in self._inflated])
        chosen, _ = self._obstacle_set.near(x0[None, :2], reach)
        return self._obstacle_set.subset(chosen)

    # ----------------------------------------------------------------- the candidate
    def _unwrap(self, x: np.ndarray) -> np.ndarray:
        """Put the measured heading on the branch nearest the prediction (or the path)."""
        x = np.array(x, dtype=float)
        k = self._model.angle_index
        reference = self._plan.x[1, k] if self._plan is not None else self._heading_reference(x)
        x[k] = reference + float(wrap_angle(x[k] - reference))
        return x

    def _candidate(self, x0: np.ndarray) -> Plan:
        """Return the proof's candidate from x0 (candidate.shifted_candidate of the last plan).

        Its multipliers depend on the NLP (obstacles held): see _multipliers.
        """
        return shifted_candidate(self._model, self._plan, x0, horizon=self._config.horizon,
                                 step=self._config.step, rollout=self._rollout,
                                 progress=self._progress, terminal_state=self._terminal_state,
                                 first_order=self._first_order)

    def _guided_guess(self, x0: np.ndarray, active: list[ConvexPolygon], nlp: Nlp) -> Plan:
        """Return the guided start from x0 (candidate.guided_guess), with nlp's multipliers."""
        plan = self._guided_motion(x0)
        return replace(plan, mu=self._multipliers(plan.x, active, nlp))

    def _guided_motion(self, x0: np.ndarray) -> Plan:
        """Return the guided start's states and inputs, within max_accel's rate bounds."""
        rate = (None if self._input_before is None else
                (self._input_before, np.asarray(self._config.max_accel) * self._config.step))
        return guided_guess(self._model, x0, self._carried_inputs,
                            horizon=self._config.horizon, step=self._config.step,
                            rollout=self._rollout, progress=self._progress,
                            terminal_state=self._terminal_state, rate_bounds=rate,
                            first_order=self._first_order)

    # ----------------------------------------------------------------- verification
    def _run_solver(self, nlp: Nlp, w0: np.ndarray, params: np.ndarray,
                    active: ObstacleSet, solver: ca.Function | None = None) -> SolveAttempt:
        """Solve from w0 (with the NLP's solver, or the given one) and verify the answer.

        The solver gets what is left of the step's budget; a call cut by it (or not started)
        marks the step as timed out.
        """
        budget = self._budget
        run = self.runner(nlp, w0, params, solver, time_limit=budget.remaining(),
                          iteration_limit=budget.iterations)
        budget.spend(run.iterations)
        if run.cut:
            budget.timed_out = True
        verified = (run.success and self._clearance.violation(
            nlp.formulation, run.w, params, active) <= FEASIBILITY_TOLERANCE)
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
        continuation = self._spot.continuation(nlp, x0, active)
        situation = Situation(
            plan_moves=plan_moves(self._plan, self._progress_gain),
            obstacles_active=bool(active), previous_round=previous is not None,
            has_fallback=nlp.has_fallback,
            continuation=continuation.solver if continuation is not None else None,
            failed=self._spot.failed(nlp))
        starts: dict[Start, np.ndarray] = {Start.CANDIDATE: w_candidate}
        if continuation is not None:
            starts[Start.CONTINUATION] = continuation.w

        def start_of(start: Start) -> np.ndarray:
            if start not in starts:
                if start is Start.PREVIOUS_ROUND:
                    assert previous is not None
                    plan = replace(previous, mu=self._multipliers(previous.x, active, nlp))
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
            if not first_backend and not self._budget.allows(build_time(nlp, kind)):
                continue
            self._tries.append(attempt_try)
            attempt = self._run_solver(nlp, start_of(attempt_try.start), params, active_set,
                                       solver_of(nlp, kind))
            iterations += attempt.iterations
            seconds += attempt.seconds
            origin = (continuation.origin if attempt_try.start is Start.CONTINUATION
                      else attempt_try)
            spent = attempt.iterations + (continuation.spent if attempt_try.start
                                          is Start.CONTINUATION and continuation else 0)
            self._spot.record(nlp, x0, attempt_try, origin, spent, verified=attempt.verified,
                              cut=attempt.cut, iterations=attempt.iterations, w=attempt.w,
                              held=active)
            if attempt.verified:
                best = attempt._replace(status=attempt.status + kind.label, origin=origin)
                break
            if best is None or kind is Solver.BACKEND:
                best = attempt
        assert best is not None  # the first backend try always runs
        return best._replace(iterations=iterations, seconds=seconds)

    # ----------------------------------------------------------------- constraint generation
    def _generate_constraints(self, x0: np.ndarray, candidate: Plan,
                              reachable: ObstacleSet) -> Rounds:
        """Solve with the obstacles near the candidate; add those the solution came near.

        The NLP may hold fewer than asked for (_nlp_holding: no shape is built within a
        prepared step); the solution is then checked against every reachable obstacle.
        """
        activation = self._config.activation_distance(self._speed_bound())
        unfinished = self._spot.unfinished
        active = resumed_round(unfinished, x0, reachable)
        # a resumed round runs in the NLP its cut try ran in: the one picked for the obstacles
        # that round was given may hold them with more faces than those it held need
        resumed = unfinished.nlp if active is not None and unfinished else None
        if active is None:
            # the candidate stands still (a new path) but with max_accel the robot cannot:
            # the solution goes on with the motion in hand; with a first-order hold it leaves
            # the robot's spot along the path from rest too (path_following_inputs)
            before, guided = self._input_before, None
            if (before is not None
                    and (np.any(np.abs(before) > STANDING_INPUT) or self._first_order)
                    and not plan_moves(self._plan, self._progress_gain)):
                motion = self._guided_motion(x0)
                guided = (motion.x, motion.u)
            active = self._clearance.first_round(candidate.x, candidate.u, guided, reachable,
                                                 activation)
        iterations, seconds = 0, 0.0
        previous: Plan | None = None  # the last round's solution, a start for the next
        # the last round whose solution clears every reachable obstacle: feasible for the full
        # problem, so it stands if a later round (for a better optimum) is cut or fails
        feasible: Rounds | None = None
        for round_ in range(MAX_ACTIVATION_ROUNDS + 1):
            nlp, params, held = self._prepare_nlp(active, x0,
                                                  nlp=resumed if round_ == 0 else None)
            candidate = replace(candidate, mu=self._multipliers(candidate.x, held, nlp))
            w_candidate = self._pack(candidate, nlp)
            # the candidate must clear every reachable obstacle, not only the active ones
            candidate_ok = (self._clearance.violation(nlp.formulation, w_candidate, params,
                                                      reachable) <= FEASIBILITY_TOLERANCE)
            candidate_value = (float(nlp.formulation.cost_fn(w_candidate, params))
                               if candidate_ok else math.inf)
            attempt = self._optimise(nlp, w_candidate, params, x0, held, previous)
            iterations += attempt.iterations
            seconds += attempt.seconds
            if not attempt.verified:
                break
            layout = nlp.formulation.layout
            states, inputs = attempt.w[layout.x], attempt.w[layout.u]
            near = self._clearance.near_trajectory(states, inputs, reachable, activation / 2)
            missed = [o for o in near if not any(o is a for a in held)]
            if not missed:
                break
            clears_all = (self._clearance.penetration(states, inputs, reachable)
                          <= FEASIBILITY_TOLERANCE)
            # the next round holds first what this solution comes nearest: where the largest
            # NLP holds fewer than asked for, the obstacles it would hit stay in, and those it
            # passes far from are left out (checked against every one all the same)
            ranked = near + [o for o in active if not any(o is n for n in near)]
            # no further round at the limit, without time for it, or without an NLP with
            # room for one of the missed obstacles (it would hold the same ones again): the
            # solution stands if it clears every reachable obstacle (feasible for the full
            # problem, then)
            if (round_ == MAX_ACTIVATION_ROUNDS or not self._shapes.holds_more(
                    ranked, held, self._config.solving.faces_per_obstacle)
                    or not self._budget.allows()):
                if not clears_all:
                    if attempt.origin is not None:
                        # from where the robot stands that try gives the same solution
                        # again, which hits the same obstacle: the others go first
                        self._spot.reject(nlp, attempt.origin)
                    attempt = attempt._replace(
                        verified=False,
                        status=f'{attempt.status} (hits an obstacle left out of the NLP)')
                break
            if clears_all:
                feasible = Rounds(nlp=nlp, params=params, candidate=candidate,
                                  w_candidate=w_candidate, candidate_ok=candidate_ok,
                                  candidate_value=candidate_value, attempt=attempt,
                                  active=held, rounds=round_ + 1)
            active = ranked
            previous = Plan(x=states, u=inputs, s=self._progress_of(attempt.w[layout.r[-1]]),
                            mu=np.zeros(0), value=math.inf)
        result = Rounds(nlp=nlp, params=params, candidate=candidate, w_candidate=w_candidate,
                        candidate_ok=candidate_ok, candidate_value=candidate_value,
                        attempt=attempt, active=held, rounds=round_ + 1)
        if feasible is not None and not attempt.verified:
            result = feasible._replace(attempt=feasible.attempt._replace(
                status=f'{feasible.attempt.status} (round {feasible.rounds}: '
                       f'round {round_ + 1} {attempt.status})'))
        return result._replace(attempt=result.attempt._replace(iterations=iterations,
                                                                 seconds=seconds))

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
        self._budget = budget = Budget.of(self._config, self.clock)
        self._tries = []
        x = np.asarray(x, dtype=float).reshape(-1)
        if x.shape != (self._model.nx,) or not np.all(np.isfinite(x)):
            msg = f'state must be {self._model.nx} finite numbers, got {x}'
            raise ValueError(msg)
        self._terminal_parameters()  # RuntimeError without a path (or target)
        x0 = self._unwrap(x)
        self._input_before = self._before(previous_input)
        # the memos hold this step's plans only (a first-order hold's ramps start from u_prev)
        self._clearance.clear(self._input_before)
        reachable = self._reachable(x0)
        candidate = self._candidate(x0)
        result = self._generate_constraints(x0, candidate, reachable)
        self._last_active = tuple(result.active)
        attempt = result.attempt
        decision = decide(
            solver_verified=attempt.verified, solver_value=attempt.value,
            candidate_ok=result.candidate_ok, candidate_value=result.candidate_value,
            has_previous_plan=self._plan is not None,
            candidate_collision_free=self._clearance.penetration(
                candidate.x, candidate.u, reachable) <= 0.0,
            timed_out=budget.timed_out, candidate_binds=self._bound_started)
        if decision is Decision.SOLVER and not self._bound_started:
            # the first plan of the solver's since the reset: the proof's record starts here
            self._lyapunov = LyapunovRecord()
            self._bound_started = True
        if decision is Decision.CANDIDATE_CHEAPER and attempt.origin is not None:
            # from where the robot stands, that try gives the same losing solution again
            self._spot.reject(result.nlp, attempt.origin)
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
            plan = replace(result.candidate, value=(
                result.candidate_value if result.candidate_ok else float(
                    result.nlp.formulation.cost_fn(result.w_candidate, result.params))))

        lyapunov_case = self._lyapunov.case(x0, self._problem_version, self._model.angle_index)
        lyapunov_ok = self._lyapunov.check(plan.value)
        weights = np.array(self._config.cost_weights().as_vector())
        # where the input commanded takes the robot: the model's step (its ramp from
        # u_before with a first-order hold) of u0 as clipped, not the plan's x_1, which
        # meets the dynamics and the bounds only within the solver's tolerance
        u0 = np.clip(plan.u[:1], self._model.u_min, self._model.u_max)
        predicted = self._rollout(x0, u0, self._config.step,
                                  self._input_before if self._first_order else None)[1]
        self._lyapunov.keep(plan.value, self._stage_fn(plan.x[0], plan.u[0], plan.x[-1], weights),
                            predicted=predicted, problem=self._problem_version)
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
            u_before=(None if not self._first_order or self._input_before is None
                      else self._input_before.copy()),
            lyapunov_case=lyapunov_case if lyapunov_ok is not None else None,
        )

    def _before(self, previous_input: np.ndarray | None) -> np.ndarray | None:
        """Return the input the rate bounds start from (None without max_accel)."""
        if self._config.max_accel is None:
            return None
        if self._first_order and self._plan is not None:
            # a first-order hold: the velocity the plan in force gives for now (its first
            # knot), which the shifted candidate's first ramp starts from
            return np.asarray(self._plan.u[0], dtype=float).copy()
        return rate_start(self._model, previous_input, self._plan)

    @property
    def _first_order(self) -> bool:
        """The inputs are first-order-hold knots (MpcConfig.input_hold 'first_order')."""
        return self._config.first_order_hold

    def _stop(self, x0: np.ndarray, status: str, attempt: SolveAttempt, in_reach: int,
              active: int, *, timed_out: bool = False) -> MpcSolution:
        """No verified plan: command the steady-state input (stand still) and start over."""
        n = self._config.horizon
        _, u_s = self._model.steady_state(x0[:3])
        u_s = np.asarray(u_s, dtype=float).reshape(-1)
        kept = self._failures, self._spot
        self.reset()
        # the robot stands still: a solve the budget cut goes on at the next step, and the
        # tries that failed here go last
        self._failures, self._spot = kept
        return MpcSolution(
            u0=u_s, x_pred=np.tile(x0, (n + 1, 1)), u_pred=np.tile(u_s, (n, 1)),
            s=math.nan, value=math.nan, success=False, status=status,
            solve_time_s=attempt.seconds, iterations=attempt.iterations,
            source=PlanSource.STOP, lyapunov_ok=None, failures=self._failures,
            obstacles_in_reach=in_reach, obstacles_active=active, timed_out=timed_out,
            tries=tuple(self._tries),
        )

