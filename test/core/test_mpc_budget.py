# SPDX-License-Identifier: Apache-2.0
"""The solve budget of a control step (SolverSettings.budget): behaviour, not speed.

Two kinds: wall time (max_solve_time, the robot's) and solver iterations
(max_solve_iterations, the evaluation's: the same on any machine). Where a test needs the
wall budget spent at a given point, the MPC gets a fake clock that the test moves (the public
MpcBase.clock); a 1 us budget is spent before any solver is reached. Where it needs the
solver to fail, the MPC is given a fake solver runner (FakeSolver, the public
MpcBase.runner), and the step says which tries it made (MpcSolution.tries). Which tries a
situation calls for is the table of test_mpc_tries.py. Nothing here asserts how fast anything is.
"""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np
import pytest

from mpc_local_planner.core.config import MpcConfig, SolverSettings, STRUCTURAL_SOLVER_FIELDS
from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.diagnostics import ControllerDiagnostics
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import (
    backends,
    built_nlps,
    continuation,
    Decision,
    PathReferenceMPC,
    PlanSource,
    Solver,
    Start,
    Try,
)
from mpc_local_planner.core.mpc.backends import (
    iteration_levels,
    Nlp,
    run_solver,
    SolverRun,
    stage_size,
)
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import paper_sinusoid, WaypointPath
from mpc_local_planner.evaluation.experiments import run_closed_loop
from mpc_local_planner.evaluation.trajectory import TRAJECTORY_COLUMNS, TRAJECTORY_INDEX

H = 0.2
BOX = ConvexPolygon.from_box(1.0, -1.0, 1.5, 1.0)
# Time enough for any solve, on any machine.
NO_TIME_LIMIT = 3600.0
# Spent before the first solver call: a step does far more than 1 us of work before it.
TINY = 1e-6
CANDIDATE_BACKEND = Try(Start.CANDIDATE, Solver.BACKEND)
CANDIDATE_FALLBACK = Try(Start.CANDIDATE, Solver.IPOPT_FALLBACK)


class FakeClock:
    """A clock that only the test moves (seconds)."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def no_clock() -> float:
    """A clock that must not be read."""
    msg = 'the clock was read'
    raise AssertionError(msg)


class FakeSolver:
    """Stands in for backends.run_solver (an MPC's runner): fails, records, spends a budget.

    Args:
        clock: a fake clock it moves by `seconds` a call (none: no time passes).
        seconds: what each call takes of the clock.
        iterations: what each call reports (and so spends of an iteration budget).

    """

    def __init__(self, clock: FakeClock | None = None, seconds: float = 0.0,
                 iterations: int = 0) -> None:
        self.clock, self.seconds, self.iterations = clock, seconds, iterations
        self.nlps: list[Nlp] = []
        self.starts: list[np.ndarray] = []
        self.limits: list[float] = []

    def __call__(self, nlp: Nlp, w0: np.ndarray, params: np.ndarray, solver: Any = None, *,
                 time_limit: float = math.inf, iteration_limit: float = math.inf) -> SolverRun:
        self.nlps.append(nlp)
        self.starts.append(np.array(w0, dtype=float))
        self.limits.append(iteration_limit)
        if self.clock is not None:
            self.clock.now += self.seconds
        return SolverRun(w=np.asarray(w0, dtype=float).reshape(-1), value=math.inf,
                         success=False, status='injected failure',
                         iterations=self.iterations, seconds=0.0)


def paper_mpc(horizon: int = MpcConfig.horizon, **solving: Any) -> PathReferenceMPC:
    """The paper's MPC around its box, interpreted functions (deterministic, no gcc)."""
    config = MpcConfig(horizon=horizon, solving=SolverSettings(
        compile=False, max_solve_time=NO_TIME_LIMIT).with_changes(**solving))
    return PathReferenceMPC(Unicycle(), config, obstacles=[BOX], path=paper_sinusoid())


def drive(mpc: PathReferenceMPC, steps: int) -> tuple[np.ndarray, Any]:
    """Solve and apply u0 for H, steps times; return the state reached and the last solution."""
    x = mpc.path.start.copy()
    solution = None
    for _ in range(steps):
        solution = mpc.solve(x)
        x = mpc.model.step(x, solution.u0, H)
    return x, solution


# ----------------------------------------------------------------------------- the setting
def test_the_budget_is_half_the_period_unless_given_and_must_be_positive() -> None:
    assert MpcConfig().solving.max_solve_time is None
    assert MpcConfig().solve_budget() == pytest.approx(0.1)
    assert MpcConfig(step=0.1).solve_budget() == pytest.approx(0.05)
    assert MpcConfig(solving=SolverSettings(max_solve_time=0.03)).solve_budget() == \
        pytest.approx(0.03)
    assert MpcConfig(solving=SolverSettings(max_solve_time=2)).solve_budget() == 2.0
    for bad in (0.0, -0.1, 'fast', True):
        with pytest.raises(ValueError, match='max_solve_time must be None or a number > 0'):
            MpcConfig(solving=SolverSettings(max_solve_time=bad))
    with pytest.raises(ValueError, match='max_solve_time must be finite'):
        MpcConfig(solving=SolverSettings(max_solve_time=math.inf))


def test_the_budget_is_wall_time_unless_iterations_are_asked_for() -> None:
    assert MpcConfig().solving.budget == 'wall'
    # the wall budget's worth: 0.1 s at 1 ms an iteration
    assert MpcConfig(solving=SolverSettings(budget='iterations')).solve_iterations() == 100
    assert MpcConfig(step=0.1,
                     solving=SolverSettings(budget='iterations')).solve_iterations() == 50
    assert MpcConfig(solving=SolverSettings(budget='iterations',
                                            max_solve_iterations=7)).solve_iterations() == 7
    with pytest.raises(ValueError, match="budget must be one of \\('wall', 'iterations'\\)"):
        MpcConfig(solving=SolverSettings(budget='cpu'))
    for bad in (0, -3, 2.5, True, 'many'):
        with pytest.raises(ValueError, match='max_solve_iterations must be None or an integer'):
            MpcConfig(solving=SolverSettings(max_solve_iterations=bad))


def test_a_new_budget_rebuilds_nothing_and_keeps_the_warm_start(
        monkeypatch: pytest.MonkeyPatch) -> None:
    assert not {'max_solve_time', 'budget', 'max_solve_iterations'} & STRUCTURAL_SOLVER_FIELDS
    mpc = paper_mpc()
    x, _ = drive(mpc, 2)
    built = dict(mpc.nlps)
    formulated: list[tuple] = []
    monkeypatch.setattr(built_nlps, 'formulate', lambda *args: formulated.append(args))
    for changes in ({'max_solve_time': 0.05}, {'budget': 'iterations'},
                    {'max_solve_iterations': 500}):
        mpc.update_config(mpc.config.with_solving(**changes))
        solution = mpc.solve(x)
        assert solution.lyapunov_ok is not None  # the history was kept
        x = mpc.model.step(x, solution.u0, H)
    assert formulated == []  # nothing was built again
    assert all(mpc.nlps[shape] is nlp for shape, nlp in built.items())  # nor fetched again


# ----------------------------------------------------------------------------- a spent budget
def test_a_tiny_budget_cuts_the_solver_and_applies_the_verified_shifted_candidate() -> None:
    mpc = paper_mpc()
    x, last = drive(mpc, 3)
    assert last.source is PlanSource.SOLVER and not last.timed_out
    mpc.update_config(mpc.config.with_solving(max_solve_time=TINY))
    for k in range(1, 4):
        solution = mpc.solve(x)
        assert solution.timed_out and not solution.solver_verified
        assert solution.source is PlanSource.CANDIDATE and not solution.success
        assert solution.status.endswith(f'({Decision.CANDIDATE_TIMEOUT.value})')
        assert solution.iterations == 0 and solution.failures == k
        assert solution.tries == (CANDIDATE_BACKEND,)  # not started; nothing after it
        # the proof's candidate: the last solver plan, shifted k steps
        np.testing.assert_allclose(solution.u0, last.u_pred[k], atol=1e-12)
        assert solution.lyapunov_ok
        x = mpc.model.step(x, solution.u0, H)
    assert not np.any(BOX.contains(solution.x_pred[:, :2]))


def test_a_spent_budget_stops_the_robot_when_there_is_no_verified_candidate() -> None:
    # off the path, with no previous plan: the stand-still candidate does not end on the path
    mpc = paper_mpc(max_solve_time=TINY)
    solution = mpc.solve(np.array([0.3, 0.5, 0.0]))
    assert solution.timed_out
    assert solution.source is PlanSource.STOP
    np.testing.assert_array_equal(solution.u0, np.zeros(2))
    assert f'({Decision.STOP.value})' in solution.status


def test_the_retry_chain_is_left_out_once_the_budget_is_spent() -> None:
    mpc = paper_mpc()
    x, _ = drive(mpc, 3)
    clock = FakeClock()
    mpc.clock = clock
    mpc.update_config(mpc.config.with_solving(max_solve_time=100.0))
    # with time to spare a failed solve is retried with the IPOPT fallback
    mpc.runner = FakeSolver()
    spare = mpc.solve(x)
    assert spare.tries == (CANDIDATE_BACKEND, CANDIDATE_FALLBACK)
    assert not spare.timed_out and spare.status.endswith(
        f'({Decision.CANDIDATE_SOLVER_FAILED.value})')
    # a failed solve that spends the budget is the step's only try
    mpc.runner = FakeSolver(clock, seconds=200.0)
    spent = mpc.solve(mpc.model.step(x, spare.u0, H))
    assert spent.tries == (CANDIDATE_BACKEND,)
    assert spent.timed_out and spent.source is PlanSource.CANDIDATE
    assert spent.status.endswith(f'({Decision.CANDIDATE_TIMEOUT.value})')


def test_without_a_plan_the_second_start_is_left_out_once_the_budget_is_spent() -> None:
    clock = FakeClock()
    mpc = paper_mpc(max_solve_time=100.0)
    mpc.clock = clock
    solver = FakeSolver()
    mpc.runner = solver
    solution = mpc.solve(mpc.path.start)
    # the candidate (stay put) with IPOPT cold and the backend, then the start along the
    # path with IPOPT and the backend: solver_tries()'s order, each start packed once
    assert [t.start for t in solution.tries] == [
        Start.CANDIDATE, Start.CANDIDATE, Start.GUIDED, Start.GUIDED]
    starts = solver.starts
    np.testing.assert_array_equal(starts[1], starts[0])
    assert not np.array_equal(starts[2], starts[0])
    np.testing.assert_array_equal(starts[3], starts[2])
    mpc.reset()
    mpc.runner = FakeSolver(clock, seconds=200.0)
    solution = mpc.solve(mpc.path.start)
    assert solution.tries == (Try(Start.CANDIDATE, Solver.IPOPT_COLD),)
    assert solution.timed_out


def test_a_fallback_is_built_mid_step_only_if_its_build_fits_in_what_is_left() -> None:
    mpc = paper_mpc()
    x, _ = drive(mpc, 3)
    clock = FakeClock()
    mpc.clock = clock
    mpc.update_config(mpc.config.with_solving(max_solve_time=0.1))
    solver = FakeSolver()
    mpc.runner = solver
    mpc.solve(x)  # finds the NLP of this state (and builds its fallback: time was left)
    nlp = solver.nlps[0]
    nlp.fallback = None  # as if never built
    nlp.build_time_s = 0.5  # and building this NLP had taken longer than the budget
    solution = mpc.solve(x)
    assert solution.tries == (CANDIDATE_BACKEND,) and nlp.fallback is None
    assert solution.timed_out and solution.source is PlanSource.CANDIDATE
    # an iteration budget does not count builds: the fallback is built and tried
    mpc.update_config(mpc.config.with_solving(budget='iterations'))
    solution = mpc.solve(x)
    assert solution.tries == (CANDIDATE_BACKEND, CANDIDATE_FALLBACK)
    assert nlp.fallback is not None


def test_prepare_builds_the_fallbacks_ahead() -> None:
    mpc = paper_mpc()
    mpc.prepare(1)
    assert mpc.nlps and all(nlp.fallback is not None for nlp in mpc.nlps.values())
    assert all(nlp.fallback_build_time == 0.0 for nlp in mpc.nlps.values())


def test_a_constraint_generation_round_is_left_out_once_the_budget_is_spent() -> None:
    # nothing active up front: at step 15 the solution comes onto the box, which a second
    # round adds (found by running this scenario; the interpreted solver is deterministic)
    rounds_at = 15
    timely = paper_mpc(activation_distance=0.0)
    x, _ = drive(timely, rounds_at)
    solution = timely.solve(x)
    assert solution.rounds == 2 and solution.source is PlanSource.SOLVER

    hurried = paper_mpc(activation_distance=0.0)
    x, _ = drive(hurried, rounds_at)
    clock = FakeClock()
    hurried.clock = clock
    hurried.update_config(hurried.config.with_solving(max_solve_time=100.0))

    def slow_solver(*args: Any, **kwargs: Any) -> SolverRun:
        run = run_solver(*args, **kwargs)
        clock.now += 200.0  # it took longer than the budget
        return run

    hurried.runner = slow_solver
    solution = hurried.solve(x)
    assert solution.rounds == 1 and solution.timed_out
    # the one round's solution ran onto the box left out of its NLP: not applied
    assert solution.source is PlanSource.CANDIDATE
    assert not np.any(hurried.inflated_obstacles[0].contains(solution.x_pred[1:, :2]))


# ----------------------------------------------------------------------------- iterations
def test_an_iteration_budget_is_spent_by_the_iterations_made_and_never_reads_a_clock() -> None:
    mpc = paper_mpc()
    x, _ = drive(mpc, 3)
    mpc.clock = no_clock
    mpc.update_config(mpc.config.with_solving(budget='iterations', max_solve_iterations=10))
    # a failed try of 4 iterations leaves 6 for the fallback
    solver = FakeSolver(iterations=4)
    mpc.runner = solver
    solution = mpc.solve(x)
    assert solution.tries == (CANDIDATE_BACKEND, CANDIDATE_FALLBACK)
    assert solver.limits == [10, 6] and solution.iterations == 8 and not solution.timed_out
    # one of 10 leaves nothing: the step's only try
    solver = FakeSolver(iterations=10)
    mpc.runner = solver
    solution = mpc.solve(mpc.model.step(x, solution.u0, H))
    assert solution.tries == (CANDIDATE_BACKEND,) and solution.timed_out
    assert solution.source is PlanSource.CANDIDATE


def test_ipopt_and_fatrop_keep_to_an_iteration_budget() -> None:
    x0 = np.array([0.0, 0.0, 0.944])
    for solver, spent in (('ipopt', 3), ('fatrop', iteration_levels(200)[-1] + 1)):
        mpc = paper_mpc(solver=solver, horizon=3, budget='iterations',
                        max_solve_iterations=10**6)
        mpc.clock = no_clock
        first = mpc.solve(x0)  # from rest IPOPT cold goes first: this makes a plan that moves
        assert first.success and np.any(first.u_pred)
        mpc.update_config(mpc.config.with_solving(max_solve_iterations=3))
        # off the prediction: the backend from the shifted candidate needs more than 3
        solution = mpc.solve(first.x_pred[1] + np.array([0.05, -0.05, 0.2]))
        assert solution.timed_out and not solution.success
        assert solution.tries == (CANDIDATE_BACKEND,)
        # IPOPT to the iteration; fatrop at most to its smallest level, here an interpreted
        # copy (it reports one iteration more than its max_iter; from this start it gives
        # up a little earlier)
        if solver == 'ipopt':
            assert solution.iterations == spent
        else:
            assert 3 < solution.iterations <= spent


def test_with_a_generous_budget_the_paper_run_is_the_run_without_a_clock() -> None:
    """The same path, step for step, as when nothing reads the clock (iterations to spare)."""
    path, model = paper_sinusoid(), Unicycle()

    def run(config: MpcConfig, clock: Any = None) -> tuple[np.ndarray, list]:
        mpc = PathReferenceMPC(model, config, obstacles=[BOX], path=path)
        if clock is not None:
            mpc.clock = clock
        solutions = []
        solve = mpc.solve

        def recorded(x: np.ndarray) -> Any:
            solutions.append(solve(x))
            return solutions[-1]

        mpc.solve = recorded  # type: ignore[method-assign]
        result = run_closed_loop(mpc, model, path.start, goal=path.goal, obstacles=[BOX],
                                 label='paper', max_time=40.0)
        assert result.metrics['reached']
        return result.rows, solutions

    rows, solutions = run(MpcConfig(
        solving=SolverSettings(compile=False, max_solve_time=NO_TIME_LIMIT)))
    assert not any(s.timed_out for s in solutions)
    assert all(s.source is PlanSource.SOLVER for s in solutions)
    rows_without, _ = run(MpcConfig(solving=SolverSettings(
        compile=False, budget='iterations', max_solve_iterations=10**6)), clock=no_clock)
    applied = [TRAJECTORY_INDEX[name] for name in TRAJECTORY_COLUMNS if name != 'solve_ms']
    np.testing.assert_array_equal(rows[:, applied], rows_without[:, applied])


# ----------------------------------------------------------------------------- counted
def test_the_controller_counts_timeouts_and_the_diagnostics_publish_the_count() -> None:
    controller = MpcController(config=MpcConfig(solving=SolverSettings(
                                   compile=False, max_solve_time=NO_TIME_LIMIT)),
                               obstacles=[BOX])
    controller.set_path(paper_sinusoid())
    x = paper_sinusoid().start
    output = controller.compute(x, None, 0.0)
    assert output.reason is Reason.TRACKING and controller.timeouts == 0
    controller.update_config(controller.config.with_solving(max_solve_time=TINY))
    for k in range(1, 3):
        x = controller.model.step(x, output.u, H)
        output = controller.compute(x, None, k * H)
        assert output.reason is Reason.CANDIDATE and output.solution.timed_out
        assert controller.timeouts == k and controller.solver_failures == k
    record = ControllerDiagnostics.from_output(
        output, state=x, state_time=2 * H, failures_total=controller.solver_failures,
        timeouts_total=controller.timeouts)
    values = dict(record.to_values())
    assert values['timeouts_total'] == '2'
    assert ControllerDiagnostics.from_values(values).timeouts_total == 2


# ----------------------------------------------------------------------------- the solvers
def test_ipopt_is_stopped_at_its_time_limit() -> None:
    mpc = paper_mpc(solver='ipopt', horizon=3)
    nlp, params, w0 = mpc.solver_problem(mpc.path.start)
    untimed = run_solver(nlp, w0, params)
    assert untimed.success and not untimed.cut
    stopped = run_solver(nlp, w0, params, time_limit=1e-9)
    assert stopped.cut and not stopped.success and stopped.status == 'User_Requested_Stop'
    not_started = run_solver(nlp, w0, params, time_limit=0.0)
    assert not_started.cut and not_started.iterations == 0
    np.testing.assert_array_equal(not_started.w, w0)
    nlp.iteration_time = 1.0  # however slow its iterations: no copy with fewer of them
    assert nlp.solver_within(1e-3) == (nlp.solver, nlp.max_iterations)
    assert nlp.solver_within(math.inf, 2) == (nlp.solver, nlp.max_iterations)
    # an iteration limit: exactly that many (its iteration callback), whatever the time
    counted = run_solver(nlp, w0, params, iteration_limit=2)
    assert counted.cut and counted.iterations == 2 and counted.status == 'User_Requested_Stop'
    assert run_solver(nlp, w0, params, iteration_limit=0).status.startswith('not started')
    again = run_solver(nlp, w0, params)
    assert again.success and again.iterations == untimed.iterations  # the limit was cleared


def test_a_solver_call_that_never_returns_is_abandoned_and_the_solver_built_again(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Fatrop's inertia correction has no bound: a call was seen never to return.

    A stand-in that blocks until the test lets it go plays that call. The step must get an
    answer (a cut run: no success, the initial guess) and not wait for ever, and the NLP
    must not call that solver again: its next call is a fresh one's, and succeeds.
    """
    mpc = paper_mpc(horizon=3)  # fatrop
    nlp, params, w0 = mpc.solver_problem(mpc.path.start)
    entered, release = threading.Event(), threading.Event()

    def stuck(**_: Any) -> None:
        entered.set()
        release.wait()

    nlp.solver = stuck
    monkeypatch.setattr(backends, 'HANG_SECONDS', 0.05)  # the stand-in never returns anyway
    try:
        run = run_solver(nlp, w0, params)
    finally:
        release.set()
        monkeypatch.undo()  # the real solver's next call gets the shipped time
    assert entered.is_set()
    assert run.cut and not run.success and run.status.startswith('abandoned')
    np.testing.assert_array_equal(run.w, w0)
    assert nlp.solver is not stuck
    again = run_solver(nlp, w0, params)
    assert again.success and not again.cut


def test_the_ipopt_fallback_is_stopped_at_its_time_limit() -> None:
    mpc = paper_mpc(horizon=3)  # fatrop, with IPOPT as its fallback
    nlp, params, w0 = mpc.solver_problem(mpc.path.start)
    stopped = run_solver(nlp, w0, params, nlp.fallback_solver(), time_limit=1e-9)
    assert stopped.cut and stopped.status == 'User_Requested_Stop'
    assert nlp.deadline is not None and nlp.deadline.at == math.inf  # cleared after the call
    counted = run_solver(nlp, w0, params, nlp.cold_solver(), iteration_limit=1)
    assert counted.cut and counted.iterations == 1
    assert nlp.deadline.max_iterations == math.inf


def test_fatrop_gets_fewer_iterations_when_the_full_limit_would_not_fit(
        monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    """A start from which this horizon-3 NLP needs about 30 fatrop iterations (not 12)."""
    monkeypatch.setenv('MPC_LOCAL_PLANNER_CACHE', str(tmp_path))
    mpc = PathReferenceMPC(Unicycle(),
                           MpcConfig(horizon=3,
                                     solving=SolverSettings(max_solve_time=NO_TIME_LIMIT)),
                           path=paper_sinusoid())
    x0 = np.array([0.0, 0.0, 0.944])  # on the path's start, heading 0.5 mrad off
    mpc.prepare(0)
    mpc.wait_compiled()
    nlp, params, w0 = mpc.solver_problem(x0, start=Start.CANDIDATE)
    assert nlp.compiled and nlp.library is not None
    assert iteration_levels(200) == [200, 100, 50, 25, 12]
    # not measured yet, or time for all: the full solver
    assert nlp.solver_within(1e-3) == (nlp.solver, 200)
    full = run_solver(nlp, w0, params, time_limit=NO_TIME_LIMIT)
    assert full.success and full.iterations > 12 and not full.cut
    # 12.5 iterations' time at one second each: the copy with 12
    nlp.iteration_time = 1.0
    solver, limit = nlp.solver_within(12.5)
    assert limit == 12 and solver is nlp.limited[12] and solver is not nlp.solver
    assert nlp.solver_within(1e-3)[1] == 12  # the smallest level, when none fits
    assert nlp.solver_within(60.0)[1] == 50
    assert nlp.solver_within(200.0) == (nlp.solver, 200)
    cut = run_solver(nlp, w0, params, time_limit=12.5)
    assert cut.cut and not cut.success and cut.iterations >= 12
    assert nlp.iteration_time < 1.0  # measured again, on the call
    # an iteration limit picks the level within it, whatever the time per iteration
    nlp.iteration_time = 0.0
    assert nlp.solver_within(math.inf, 30)[1] == 25
    assert nlp.solver_within(math.inf, 5)[1] == 12
    assert nlp.solver_within(math.inf, 200) == (nlp.solver, 200)
    counted = run_solver(nlp, w0, params, iteration_limit=30)
    assert counted.cut and 25 <= counted.iterations <= 26  # fatrop reports max_iter + 1


def test_the_time_per_iteration_rises_at_once_and_falls_slowly() -> None:
    mpc = paper_mpc(horizon=3)
    nlp = mpc.solver_problem(mpc.path.start).nlp
    nlp.iteration_time = 0.0
    nlp.record_iterations(0.01, 10)
    assert nlp.iteration_time == pytest.approx(1e-3)
    nlp.record_iterations(0.1, 10)
    assert nlp.iteration_time == pytest.approx(1e-2)
    nlp.record_iterations(0.01, 10)
    assert 1e-3 < nlp.iteration_time < 1e-2
    before = nlp.iteration_time
    nlp.record_iterations(0.5, 0)  # no iterations: no sample
    assert nlp.iteration_time == before


# ----------------------------------------------------------------------------- NLP shapes
# within the horizon's reach of the start (0.62 m), beside and behind the paper's path
THREE_BOXES = [ConvexPolygon.from_box(0.4, -0.3, 0.6, 0.0),
               ConvexPolygon.from_box(-0.1, 0.4, 0.1, 0.6),
               ConvexPolygon.from_box(-0.6, -0.2, -0.4, 0.2)]


def test_a_prepared_step_never_builds_an_nlp_shape_and_holds_the_nearest_obstacles(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # every obstacle in reach is active: three, but only shapes for up to one are prepared
    config = MpcConfig(solving=SolverSettings(compile=False, max_solve_time=NO_TIME_LIMIT,
                                              activation_distance=5.0))
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES, path=paper_sinusoid())
    mpc.prepare(1)
    prepared = dict(mpc.nlps)
    formulated: list[tuple] = []
    monkeypatch.setattr(built_nlps, 'formulate', lambda *args: formulated.append(args))
    x = mpc.path.start.copy()
    for _ in range(3):  # nothing is built, step after step
        solution = mpc.solve(x)
        assert mpc.nlps.keys() == prepared.keys()  # the same shapes, the same NLPs
        assert all(mpc.nlps[shape] is nlp for shape, nlp in prepared.items())
        assert len(mpc.last_active_obstacles) == 1  # the nearest one held
        assert solution.source is not PlanSource.STOP
        plan = np.asarray(solution.x_pred)
        for box in mpc.inflated_obstacles:  # and the plan checked against all three
            assert not np.any(box.contains(plan[1:, :2]))
        x = mpc.model.step(x, solution.u0, H)
    assert formulated == []


def test_before_prepare_a_step_builds_the_shape_it_needs() -> None:
    config = MpcConfig(solving=SolverSettings(compile=False, max_solve_time=NO_TIME_LIMIT,
                                              activation_distance=5.0))
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES, path=paper_sinusoid())
    mpc.solve(mpc.path.start)
    assert (3, 4) in mpc.nlps
    assert len(mpc.last_active_obstacles) == 3


def test_a_shape_never_solved_is_bounded_by_its_siblings_time_per_iteration() -> None:
    config = MpcConfig(solving=SolverSettings(compile=False, max_solve_time=NO_TIME_LIMIT,
                                              activation_distance=5.0))
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES, path=paper_sinusoid())
    mpc.prepare(3)
    one, three = mpc.nlps[(1, 4)], mpc.nlps[(3, 4)]
    one.iteration_time = 0.002
    assert three.iteration_time == 0.0
    assert mpc.solver_problem(mpc.path.start, THREE_BOXES).nlp is three
    size = three.formulation.lbw.shape[0] / one.formulation.lbw.shape[0]
    assert size > 1.0
    assert three.iteration_time == pytest.approx(0.002 * size)


# ----------------------------------------------------------------------------- big stages
def test_shapes_with_stages_beyond_the_fatrop_limit_are_solved_by_ipopt() -> None:
    # the paper's MPC: a stage of 6 variables, 4 more per box (its faces' multipliers)
    config = MpcConfig(solving=SolverSettings(compile=False, max_solve_time=NO_TIME_LIMIT,
                                              activation_distance=5.0, fatrop_stage_limit=10))
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES, path=paper_sinusoid())
    small, big = mpc.nlp_for(1, 4), mpc.nlp_for(2, 4)
    assert stage_size(small.formulation.structure) == 10
    assert (small.plugin, small.has_fallback) == ('fatrop', True)
    assert stage_size(big.formulation.structure) == 14
    assert (big.plugin, big.has_fallback) == ('ipopt', False)  # IPOPT is its own fallback
    solution = mpc.solve(mpc.path.start)  # three boxes held: a stage of 18
    assert solution.success and mpc.backend == 'ipopt'
    assert solution.obstacles_active == 3


# ----------------------------------------------------------------------------- continuing
def test_a_solve_the_budget_cut_goes_on_at_the_next_step_while_the_robot_stands_still(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # from rest among three boxes the solve takes more iterations (9) than a step's budget
    # allows (here 7): the step applies the candidate (stand still), and the next one goes
    # on from where the cut try stopped and finishes (in 5); started over, it never does
    # (the continuation is primal only: with 5 neither finishes)
    def steps_to_move(continuing: bool) -> int | None:
        config = MpcConfig(solving=SolverSettings(compile=False, activation_distance=5.0,
                                                  budget='iterations', max_solve_iterations=7))
        mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES,
                               path=paper_sinusoid())
        if not continuing:
            monkeypatch.setattr(continuation, 'CONTINUE_TOLERANCE', -1.0)
        x = mpc.path.start.copy()
        for step in range(12):
            solution = mpc.solve(x)  # x stays: the candidate at rest is standing still
            if solution.success:
                assert solution.tries[0] == Try(Start.CONTINUATION, Solver.IPOPT_COLD)
                return step
            assert solution.timed_out and not np.any(solution.u0)
            assert solution.tries == (Try(Start.GUIDED, Solver.IPOPT_COLD),)
        return None

    assert steps_to_move(continuing=True) == 1  # cut at first, then finished
    assert steps_to_move(continuing=False) is None  # starting over never finishes


# a route past the three boxes, as a planner's plan
WAYPOINTS = [[0.0, 0.0], [1.25, 0.9], [2.5, 0.0]]


def test_the_same_path_again_keeps_the_cut_solve_and_a_new_one_starts_over() -> None:
    # a re-plan that finds the same path again (the planner's no-progress re-plans do, at a
    # standing robot) poses the same problem: the cut solve goes on (BARN 273 stood 20 s,
    # its cut solves dropped at every re-plan); a different path is a new problem
    def tries_after(new_path: bool) -> Try:
        config = MpcConfig(solving=SolverSettings(compile=False, activation_distance=5.0,
                                                  budget='iterations', max_solve_iterations=7))
        mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES,
                               path=WaypointPath(np.array(WAYPOINTS)))
        x = mpc.path.start.copy()
        assert mpc.solve(x).timed_out  # cut: the robot stands on the candidate
        waypoints = np.array(WAYPOINTS) + ([[0.0, 0.0], [0.0, 0.0], [0.0, 0.1]] if new_path
                                           else 0.0)
        mpc.set_path(WaypointPath(waypoints))
        return mpc.solve(x).tries[0]

    assert tries_after(new_path=False).start is Start.CONTINUATION
    assert tries_after(new_path=True).start is not Start.CONTINUATION


def test_after_a_stand_still_plan_the_next_step_starts_as_from_rest() -> None:
    # a step from rest that does not solve applies the stand-still candidate; the step after
    # it must try IPOPT's cold start first, as from rest, not the warm tries from that
    # candidate (fatrop failed from it at every step after a re-plan at 2 m/s on BARN)
    config = MpcConfig(solving=SolverSettings(compile=False, max_solve_time=NO_TIME_LIMIT,
                                              activation_distance=5.0))
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES, path=paper_sinusoid(),
                           runner=FakeSolver(iterations=1))
    x = mpc.path.start.copy()
    first = mpc.solve(x)
    assert not first.success and not np.any(first.u_pred)  # the stand-still candidate
    assert first.tries[0].solver is Solver.IPOPT_COLD
    assert mpc.solve(x).tries[0].solver is Solver.IPOPT_COLD


def test_a_cut_solve_goes_on_after_a_step_that_stopped_the_robot() -> None:
    # off the path no stand-still candidate is feasible: a step that does not solve stops
    # (and starts over); the robot stands still, so the cut solve still goes on next step
    # (world 43 at 2 m/s on BARN stood still for good without it)
    config = MpcConfig(solving=SolverSettings(compile=False, activation_distance=5.0,
                                              budget='iterations', max_solve_iterations=10))
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES, path=paper_sinusoid())
    x = mpc.path.start + np.array([0.0, 0.05, 0.0])
    stopped = mpc.solve(x)
    assert stopped.source is PlanSource.STOP and stopped.timed_out
    assert mpc.solve(x).tries[0] == Try(Start.CONTINUATION, stopped.tries[-1].solver)


def test_a_cut_solve_goes_on_when_the_laser_fits_the_same_obstacles_again() -> None:
    # a laser's pieces are fitted again at every scan: a standing robot sees the same
    # obstacles a few micrometres apart. The cut solve must go on (on the physics plant, BARN
    # 23 through the nodes stood still for good, every step's solve started over and cut);
    # an obstacle that moved is a new problem
    def first_try_after(shift: float) -> Try:
        config = MpcConfig(solving=SolverSettings(compile=False, activation_distance=5.0,
                                                  budget='iterations', max_solve_iterations=7))
        mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES,
                               path=paper_sinusoid())
        x = mpc.path.start.copy()
        assert mpc.solve(x).timed_out  # cut: the robot stands on the candidate
        mpc.set_obstacles([ConvexPolygon.from_vertices(box.vertices + shift)
                           for box in THREE_BOXES])
        return mpc.solve(x).tries[0]

    assert first_try_after(3e-6).start is Start.CONTINUATION
    assert first_try_after(0.01).start is not Start.CONTINUATION
