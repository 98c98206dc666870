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

"""The solve time budget of a control step (MpcConfig.max_solve_time): behaviour, not speed.

Where a test needs the budget spent at a given point, the MPC gets a fake clock that the test
moves (MpcBase.clock); a 1 us budget is spent before any solver is reached. Nothing here
asserts how fast anything is.
"""

from __future__ import annotations

import math
from typing import Any

import casadi as ca
import numpy as np
import pytest

from mpc_local_planner.core.config import MpcConfig, STRUCTURAL_FIELDS
from mpc_local_planner.core.controller import MpcController, Reason
from mpc_local_planner.core.diagnostics import ControllerDiagnostics
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import Decision, PathReferenceMPC, PlanSource
from mpc_local_planner.core.mpc import step as step_module
from mpc_local_planner.core.mpc.backends import iteration_levels, run_solver, stage_size
from mpc_local_planner.core.mpc.step import SolveAttempt
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import paper_sinusoid
from mpc_local_planner.evaluation.experiments import run_closed_loop
from mpc_local_planner.evaluation.trajectory import TRAJECTORY_COLUMNS, TRAJECTORY_INDEX

H = 0.2
BOX = ConvexPolygon.from_box(1.0, -1.0, 1.5, 1.0)
# Time enough for any solve, on any machine.
NO_TIME_LIMIT = 3600.0
# Spent before the first solver call: a step does far more than 1 us of work before it.
TINY = 1e-6


class FakeClock:
    """A clock that only the test moves (seconds)."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def paper_mpc(**changes: Any) -> PathReferenceMPC:
    """The paper's MPC around its box, interpreted functions (deterministic, no gcc)."""
    config = MpcConfig(compile=False, max_solve_time=NO_TIME_LIMIT).with_changes(**changes)
    return PathReferenceMPC(Unicycle(), config, obstacles=[BOX], path=paper_sinusoid())


def drive(mpc: PathReferenceMPC, steps: int) -> tuple[np.ndarray, Any]:
    """Solve and apply u0 for H, steps times; return the state reached and the last solution."""
    x = mpc.path.start.copy()
    solution = None
    for _ in range(steps):
        solution = mpc.solve(x)
        x = mpc.model.step(x, solution.u0, H)
    return x, solution


def failing_solver(calls: list[str], clock: FakeClock | None = None, spend: float = 0.0,
                   starts: list[np.ndarray] | None = None):
    """A _run_solver that fails, records which solver (and start) it got, and takes spend s."""

    def run(nlp, w0, params, active, solver=None):  # the signature of _run_solver
        calls.append('primary' if solver is None else 'fallback')
        if starts is not None:
            starts.append(np.array(w0, dtype=float))
        if clock is not None:
            clock.now += spend
        return SolveAttempt(verified=False, w=np.asarray(w0, dtype=float), value=math.inf,
                            status='injected failure', iterations=0, seconds=0.0)

    return run


# ----------------------------------------------------------------------------- the setting
def test_the_budget_is_half_the_period_unless_given_and_must_be_positive() -> None:
    assert MpcConfig().max_solve_time is None
    assert MpcConfig().solve_budget() == pytest.approx(0.1)
    assert MpcConfig(step=0.1).solve_budget() == pytest.approx(0.05)
    assert MpcConfig(max_solve_time=0.03).solve_budget() == pytest.approx(0.03)
    assert MpcConfig(max_solve_time=2).solve_budget() == 2.0
    for bad in (0.0, -0.1, 'fast', True):
        with pytest.raises(ValueError, match='max_solve_time must be None or a number > 0'):
            MpcConfig(max_solve_time=bad)
    with pytest.raises(ValueError, match='max_solve_time must be finite'):
        MpcConfig(max_solve_time=math.inf)


def test_a_new_budget_rebuilds_nothing_and_keeps_the_warm_start() -> None:
    assert 'max_solve_time' not in STRUCTURAL_FIELDS
    mpc = paper_mpc()
    x, _ = drive(mpc, 2)
    nlps = dict(mpc._nlps)
    mpc.update_config(mpc.config.with_changes(max_solve_time=0.05))
    assert mpc._nlps == nlps and mpc._plan is not None
    assert mpc.solve(x).lyapunov_ok is not None  # the history was kept


# ----------------------------------------------------------------------------- a spent budget
def test_a_tiny_budget_cuts_the_solver_and_applies_the_verified_shifted_candidate() -> None:
    mpc = paper_mpc()
    x, last = drive(mpc, 3)
    assert last.source is PlanSource.SOLVER and not last.timed_out
    mpc.update_config(mpc.config.with_changes(max_solve_time=TINY))
    for k in range(1, 4):
        solution = mpc.solve(x)
        assert solution.timed_out and not solution.solver_verified
        assert solution.source is PlanSource.CANDIDATE and not solution.success
        assert solution.status.endswith(f'({Decision.CANDIDATE_TIMEOUT.value})')
        assert solution.iterations == 0 and solution.failures == k
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


def test_the_retry_chain_is_left_out_once_the_budget_is_spent(
        monkeypatch: pytest.MonkeyPatch) -> None:
    mpc = paper_mpc()
    x, _ = drive(mpc, 3)
    clock = FakeClock()
    mpc.clock = clock
    mpc.update_config(mpc.config.with_changes(max_solve_time=100.0))
    # with time to spare a failed solve is retried with the IPOPT fallback
    calls: list[str] = []
    monkeypatch.setattr(mpc, '_run_solver', failing_solver(calls))
    spare = mpc.solve(x)
    assert calls == ['primary', 'fallback']
    assert not spare.timed_out and spare.status.endswith(
        f'({Decision.CANDIDATE_SOLVER_FAILED.value})')
    # a failed solve that spends the budget is the step's only try
    calls.clear()
    monkeypatch.setattr(mpc, '_run_solver', failing_solver(calls, clock, spend=200.0))
    spent = mpc.solve(mpc.model.step(x, spare.u0, H))
    assert calls == ['primary']
    assert spent.timed_out and spent.source is PlanSource.CANDIDATE
    assert spent.status.endswith(f'({Decision.CANDIDATE_TIMEOUT.value})')


def test_without_a_plan_the_second_start_is_left_out_once_the_budget_is_spent(
        monkeypatch: pytest.MonkeyPatch) -> None:
    clock = FakeClock()
    calls: list[str] = []
    mpc = paper_mpc(max_solve_time=100.0)
    mpc.clock = clock
    starts: list[np.ndarray] = []
    monkeypatch.setattr(mpc, '_run_solver', failing_solver(calls, starts=starts))
    mpc.solve(mpc.path.start)
    # the candidate (stay put), then the start along the path with IPOPT and the backend,
    # then the candidate with IPOPT
    assert calls == ['primary', 'fallback', 'primary', 'fallback']
    assert not np.array_equal(starts[1], starts[0])
    np.testing.assert_array_equal(starts[2], starts[1])
    np.testing.assert_array_equal(starts[3], starts[0])
    calls.clear()
    mpc.reset()
    monkeypatch.setattr(mpc, '_run_solver', failing_solver(calls, clock, spend=200.0))
    solution = mpc.solve(mpc.path.start)
    assert calls == ['primary']
    assert solution.timed_out


def test_a_fallback_is_built_mid_step_only_if_its_build_fits_in_what_is_left(
        monkeypatch: pytest.MonkeyPatch) -> None:
    mpc = paper_mpc()
    x, _ = drive(mpc, 3)
    clock = FakeClock()
    mpc.clock = clock
    mpc.update_config(mpc.config.with_changes(max_solve_time=0.1))
    nlp = mpc._last_nlp
    assert nlp.fallback is None  # every solve so far succeeded: never needed
    nlp.build_time_s = 0.5  # as if building this NLP had taken longer than the budget
    calls: list[str] = []
    monkeypatch.setattr(mpc, '_run_solver', failing_solver(calls))
    solution = mpc.solve(x)
    assert calls == ['primary'] and nlp.fallback is None
    assert solution.timed_out and solution.source is PlanSource.CANDIDATE


def test_prepare_builds_the_fallbacks_ahead() -> None:
    mpc = paper_mpc()
    mpc.prepare(1)
    assert mpc._nlps and all(nlp.fallback is not None for nlp in mpc._nlps.values())
    assert all(nlp.fallback_build_time == 0.0 for nlp in mpc._nlps.values())


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
    hurried.update_config(hurried.config.with_changes(max_solve_time=100.0))
    solve_once = hurried._run_solver

    def slow_solver(*args: Any, **kwargs: Any) -> SolveAttempt:
        attempt = solve_once(*args, **kwargs)
        clock.now += 200.0  # it took longer than the budget
        return attempt

    hurried._run_solver = slow_solver  # type: ignore[method-assign]
    solution = hurried.solve(x)
    assert solution.rounds == 1 and solution.timed_out
    # the one round's solution ran onto the box left out of its NLP: not applied
    assert solution.source is PlanSource.CANDIDATE
    assert not np.any(hurried.inflated_obstacles[0].contains(solution.x_pred[1:, :2]))


# ----------------------------------------------------------------------------- a generous budget
def test_with_a_generous_budget_the_paper_run_is_the_run_without_one(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The same path, step for step, as when nothing reads the clock (the code before it)."""
    path, model = paper_sinusoid(), Unicycle()

    def run(config: MpcConfig) -> tuple[np.ndarray, list]:
        mpc = PathReferenceMPC(model, config, obstacles=[BOX], path=path)
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

    rows, solutions = run(MpcConfig(compile=False, max_solve_time=NO_TIME_LIMIT))
    assert not any(s.timed_out for s in solutions)
    assert all(s.source is PlanSource.SOLVER for s in solutions)

    class NoBudget(step_module._Budget):
        def remaining(self) -> float:
            return math.inf

    monkeypatch.setattr(step_module, '_Budget', NoBudget)
    rows_without, _ = run(MpcConfig(compile=False))
    applied = [TRAJECTORY_INDEX[name] for name in TRAJECTORY_COLUMNS if name != 'solve_ms']
    np.testing.assert_array_equal(rows[:, applied], rows_without[:, applied])


# ----------------------------------------------------------------------------- counted
def test_the_controller_counts_timeouts_and_the_diagnostics_publish_the_count() -> None:
    controller = MpcController(config=MpcConfig(compile=False, max_solve_time=NO_TIME_LIMIT),
                               obstacles=[BOX])
    controller.set_path(paper_sinusoid())
    x = paper_sinusoid().start
    output = controller.compute(x, 0.0)
    assert output.reason is Reason.TRACKING and controller.timeouts == 0
    controller.update_config(controller.config.with_changes(max_solve_time=TINY))
    for k in range(1, 3):
        x = controller.model.step(x, output.u, H)
        output = controller.compute(x, k * H)
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
    x0 = mpc.path.start
    nlp, params, _ = mpc._prepare_nlp([], x0)
    w0 = mpc._pack(mpc._guided_guess(x0, [], nlp), nlp)
    untimed = run_solver(nlp, w0, params)
    assert untimed.success and not untimed.cut
    stopped = run_solver(nlp, w0, params, time_limit=1e-9)
    assert stopped.cut and not stopped.success and stopped.status == 'User_Requested_Stop'
    not_started = run_solver(nlp, w0, params, time_limit=0.0)
    assert not_started.cut and not_started.iterations == 0
    np.testing.assert_array_equal(not_started.w, w0)
    nlp.iteration_time = 1.0  # however slow its iterations: no copy with fewer of them
    assert nlp.solver_within(1e-3) == (nlp.solver, nlp.max_iterations)


def test_the_ipopt_fallback_is_stopped_at_its_time_limit() -> None:
    mpc = paper_mpc(horizon=3)  # fatrop, with IPOPT as its fallback
    x0 = mpc.path.start
    nlp, params, _ = mpc._prepare_nlp([], x0)
    w0 = mpc._pack(mpc._guided_guess(x0, [], nlp), nlp)
    stopped = run_solver(nlp, w0, params, nlp.fallback_solver(), time_limit=1e-9)
    assert stopped.cut and stopped.status == 'User_Requested_Stop'
    assert nlp.deadline is not None and nlp.deadline.at == math.inf  # cleared after the call


def test_fatrop_gets_fewer_iterations_when_the_full_limit_would_not_fit(
        monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    """A start from which this horizon-3 NLP needs about 30 fatrop iterations (not 12)."""
    monkeypatch.setenv('MPC_LOCAL_PLANNER_CACHE', str(tmp_path))
    mpc = PathReferenceMPC(Unicycle(), MpcConfig(horizon=3, max_solve_time=NO_TIME_LIMIT),
                           path=paper_sinusoid())
    x0 = np.array([0.0, 0.0, 0.944])  # on the path's start, heading 0.5 mrad off
    mpc.prepare(0)
    mpc.wait_compiled()
    nlp, params, _ = mpc._prepare_nlp([], x0)
    assert nlp.compiled and nlp.library is not None
    candidate = mpc._candidate(x0)
    candidate.mu = mpc._multipliers(candidate.x, [], nlp)
    w0 = mpc._pack(candidate, nlp)
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


def test_the_time_per_iteration_rises_at_once_and_falls_slowly() -> None:
    mpc = paper_mpc(horizon=3)
    nlp, _, _ = mpc._prepare_nlp([], mpc.path.start)
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
    config = MpcConfig(compile=False, max_solve_time=NO_TIME_LIMIT, activation_distance=5.0)
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES, path=paper_sinusoid())
    mpc.prepare(1)
    prepared = set(mpc._nlps)
    formulated: list[tuple] = []
    monkeypatch.setattr(step_module, 'formulate', lambda *args: formulated.append(args))
    x = mpc.path.start.copy()
    for _ in range(3):  # nothing is built, step after step
        solution = mpc.solve(x)
        assert set(mpc._nlps) == prepared
        assert len(mpc.last_active_obstacles) == 1  # the nearest one held
        assert solution.source is not PlanSource.STOP
        plan = np.asarray(solution.x_pred)
        for box in mpc.inflated_obstacles:  # and the plan checked against all three
            assert not np.any(box.contains(plan[1:, :2]))
        x = mpc.model.step(x, solution.u0, H)
    assert formulated == []


def test_before_prepare_a_step_builds_the_shape_it_needs() -> None:
    config = MpcConfig(compile=False, max_solve_time=NO_TIME_LIMIT, activation_distance=5.0)
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES, path=paper_sinusoid())
    mpc.solve(mpc.path.start)
    assert (3, 4) in mpc._nlps
    assert len(mpc.last_active_obstacles) == 3


def test_a_shape_never_solved_is_bounded_by_its_siblings_time_per_iteration() -> None:
    config = MpcConfig(compile=False, max_solve_time=NO_TIME_LIMIT, activation_distance=5.0)
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES, path=paper_sinusoid())
    mpc.prepare(3)
    one, three = mpc._nlps[(1, 4)], mpc._nlps[(3, 4)]
    one.iteration_time = 0.002
    assert three.iteration_time == 0.0
    mpc._prepare_nlp(THREE_BOXES, mpc.path.start)
    size = three.formulation.lbw.shape[0] / one.formulation.lbw.shape[0]
    assert size > 1.0
    assert three.iteration_time == pytest.approx(0.002 * size)


# ----------------------------------------------------------------------------- big stages
def test_shapes_with_stages_beyond_the_fatrop_limit_are_solved_by_ipopt() -> None:
    # the paper's MPC: a stage of 6 variables, 4 more per box (its faces' multipliers)
    config = MpcConfig(compile=False, max_solve_time=NO_TIME_LIMIT, activation_distance=5.0,
                       fatrop_stage_limit=10)
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES, path=paper_sinusoid())
    small, big = mpc._nlp_for(1, 4), mpc._nlp_for(2, 4)
    assert stage_size(small.formulation.structure) == 10
    assert (small.plugin, small.has_fallback) == ('fatrop', True)
    assert stage_size(big.formulation.structure) == 14
    assert (big.plugin, big.has_fallback) == ('ipopt', False)  # IPOPT is its own fallback
    solution = mpc.solve(mpc.path.start)  # three boxes held: a stage of 18
    assert solution.success and mpc.backend == 'ipopt'
    assert solution.obstacles_active == 3


# ----------------------------------------------------------------------------- continuing
real_run_solver = run_solver


def solver_cut_after(iterations: int):
    """A run_solver whose budget stops every call after so many IPOPT iterations."""

    def run(nlp, w0, params, solver=None, time_limit=math.inf):
        limited = ca.nlpsol('cut', 'ipopt', nlp.formulation.problem, {
            'ipopt.print_level': 0, 'print_time': False, 'ipopt.sb': 'yes',
            'ipopt.max_iter': iterations, 'error_on_fail': False})
        result = real_run_solver(nlp, w0, params, limited)
        return result._replace(cut=not result.success)

    return run


def test_a_solve_the_budget_cut_goes_on_at_the_next_step_while_the_robot_stands_still(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # from rest among three boxes the solve takes more iterations than a step's budget
    # allows (here 10 a try): the step applies the candidate (stand still), and the next one
    # goes on from where the cut try stopped and finishes; started over, it never does (the
    # continuation is primal only: with 9 or fewer a try neither finishes)
    def steps_to_move(continuing: bool) -> int | None:
        config = MpcConfig(compile=False, max_solve_time=NO_TIME_LIMIT,
                           activation_distance=5.0)
        mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES,
                               path=paper_sinusoid())
        monkeypatch.setattr(step_module, 'run_solver', solver_cut_after(10))
        if not continuing:
            monkeypatch.setattr(step_module, 'CONTINUE_TOLERANCE', -1.0)
        x = mpc.path.start.copy()
        for step in range(12):
            solution = mpc.solve(x)  # x stays: the candidate at rest is standing still
            if solution.success:
                return step
            assert solution.timed_out and not np.any(solution.u0)
        return None

    assert steps_to_move(continuing=True) == 1  # cut at first, then finished
    assert steps_to_move(continuing=False) is None  # starting over never finishes


def test_after_a_stand_still_plan_the_next_step_starts_as_from_rest(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # a step from rest that does not solve applies the stand-still candidate; the step after
    # it must try IPOPT's cold start first, as from rest, not the warm tries from that
    # candidate (fatrop failed from it at every step after a re-plan at 2 m/s on BARN)
    config = MpcConfig(compile=False, max_solve_time=NO_TIME_LIMIT, activation_distance=5.0)
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES, path=paper_sinusoid())
    kinds: list[str] = []

    def failing(nlp, w0, params, active, solver=None):
        kinds.append('backend' if solver is None else 'cold' if solver is nlp.cold
                     else 'fallback')
        return SolveAttempt(verified=False, w=np.asarray(w0, dtype=float), value=math.inf,
                            status='injected failure', iterations=1, seconds=0.0)

    monkeypatch.setattr(mpc, '_run_solver', failing)
    x = mpc.path.start.copy()
    first = mpc.solve(x)
    assert not first.success and not np.any(first.u_pred)  # the stand-still candidate
    assert kinds[0] == 'cold'
    kinds.clear()
    mpc.solve(x)
    assert kinds[0] == 'cold'


def test_a_cut_solve_goes_on_after_a_step_that_stopped_the_robot(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # off the path no stand-still candidate is feasible: a step that does not solve stops
    # (and starts over); the robot stands still, so the cut solve still goes on next step
    # (world 43 at 2 m/s on BARN stood still for good without it)
    config = MpcConfig(compile=False, max_solve_time=NO_TIME_LIMIT, activation_distance=5.0)
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=THREE_BOXES, path=paper_sinusoid())
    cut = solver_cut_after(10)
    starts: list[np.ndarray] = []

    def recording(nlp, w0, params, solver=None, time_limit=math.inf):
        starts.append(np.array(w0, dtype=float))
        return cut(nlp, w0, params, solver, time_limit)

    monkeypatch.setattr(step_module, 'run_solver', recording)
    x = mpc.path.start + np.array([0.0, 0.05, 0.0])
    assert mpc.solve(x).source is PlanSource.STOP
    unfinished = mpc._unfinished
    assert unfinished is not None
    starts.clear()
    mpc.solve(x)
    assert any(np.array_equal(start, unfinished.w) for start in starts)
