# SPDX-License-Identifier: Apache-2.0
"""The paper's MPC and the baseline on the paper's scenario (no ROS)."""

import numpy as np
import pytest

from mpc_local_planner.core.baselines import TrackingMPC
from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import PathReferenceMPC, PlanSource
from mpc_local_planner.core.mpc.backends import SolverRun
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import paper_sinusoid, WaypointPath
from mpc_local_planner.evaluation.experiments import run_closed_loop

BOX = ConvexPolygon.from_box(1.0, -1.0, 1.5, 1.0)
# Time enough for any solve: these closed loops test the MPC's behaviour, which must not
# depend on how loaded the machine is (the solve time budget: test_mpc_budget.py).
CONFIG = MpcConfig(solving=SolverSettings(max_solve_time=3600.0))


@pytest.fixture(scope='module')
def proposed_run():
    path = paper_sinusoid()
    model = Unicycle()
    controller = PathReferenceMPC(model, CONFIG, obstacles=[BOX], path=path)
    return run_closed_loop(controller, model, path.start, goal=path.goal, obstacles=[BOX],
                           label='proposed', max_time=40.0)


@pytest.fixture(scope='module')
def baseline_run():
    path = paper_sinusoid()
    model = Unicycle()
    controller = TrackingMPC(model, CONFIG, obstacles=[BOX], target=path.goal)
    return run_closed_loop(controller, model, path.start, goal=path.goal, obstacles=[BOX],
                           label='baseline', max_time=40.0)


def test_proposed_mpc_reaches_the_target_around_the_box(proposed_run) -> None:
    metrics = proposed_run.metrics
    assert metrics['reached']
    assert metrics['final_position_error'] <= 0.05
    assert metrics['final_heading_error'] <= 0.1
    assert np.max(proposed_run.rows[:, 1]) > 2.4


def test_proposed_mpc_never_samples_a_position_inside_the_box(proposed_run) -> None:
    assert not np.any(BOX.contains(proposed_run.rows[:, 1:3]))
    assert proposed_run.metrics['min_clearance'] > 0.0


def test_proposed_mpc_value_function_never_increases(proposed_run) -> None:
    values = proposed_run.rows[:, 7]
    assert np.all(np.diff(values) <= 1e-6 * (1 + np.abs(values[:-1])))
    assert proposed_run.metrics['lyapunov_checks'] == len(values) - 1
    assert proposed_run.metrics['lyapunov_violations'] == 0


def test_proposed_mpc_path_progress_reaches_one(proposed_run) -> None:
    assert proposed_run.rows[-1, 6] == pytest.approx(1.0, abs=1e-3)


def test_every_applied_input_is_within_the_bounds(proposed_run, baseline_run) -> None:
    for run in (proposed_run, baseline_run):
        assert np.all(np.abs(run.rows[:, 4]) <= 0.31 + 1e-12)
        assert np.all(np.abs(run.rows[:, 5]) <= 1.9 + 1e-12)


def test_tracking_baseline_stops_in_front_of_the_box(baseline_run) -> None:
    assert not baseline_run.metrics['reached']
    assert np.max(baseline_run.rows[:, 1]) < 1.0
    assert not np.any(BOX.contains(baseline_run.rows[:, 1:3]))
    last_5_s = baseline_run.rows[baseline_run.rows[:, 0] >= baseline_run.rows[-1, 0] - 5.0]
    assert baseline_run.rows[-1, 0] >= 10.0  # it had time, and stood still at the end
    assert np.ptp(last_5_s[:, 1]) < 0.02 and np.ptp(last_5_s[:, 2]) < 0.02


def test_solve_refuses_a_non_finite_state() -> None:
    controller = PathReferenceMPC(Unicycle(), MpcConfig(), path=paper_sinusoid())
    with pytest.raises(ValueError, match='finite'):
        controller.solve(np.array([0.0, np.nan, 0.0]))


def test_solve_without_a_path_says_so() -> None:
    controller = PathReferenceMPC(Unicycle(), MpcConfig())
    with pytest.raises(RuntimeError, match='path'):
        controller.solve(np.zeros(3))


def test_measured_heading_is_unwrapped_to_the_prediction() -> None:
    path = WaypointPath(np.array([[0.0, 0.0], [2.0, 0.0]]), start_heading=np.pi - 0.05)
    controller = PathReferenceMPC(Unicycle(), CONFIG, path=path)
    first = controller.solve(np.array([0.0, 0.0, np.pi - 0.05]))
    # the same pose reported on the other branch (-pi + ...) must give the same command
    second_a = controller.solve(first.x_pred[1])
    controller_b = PathReferenceMPC(Unicycle(), CONFIG, path=path)
    controller_b.solve(np.array([0.0, 0.0, np.pi - 0.05]))
    wrapped = first.x_pred[1].copy()
    wrapped[2] -= 2 * np.pi
    second_b = controller_b.solve(wrapped)
    np.testing.assert_allclose(second_a.u0, second_b.u0, atol=1e-6)


def test_invalid_settings_are_refused_with_reasons() -> None:
    with pytest.raises(ValueError, match='horizon must be an integer >= 1'):
        MpcConfig(horizon=0)
    with pytest.raises(ValueError, match='step must be > 0'):
        MpcConfig(step=-0.1)
    with pytest.raises(ValueError, match='weight_v must be >= 0'):
        MpcConfig(weight_v=-1.0)


@pytest.mark.parametrize('seed', [0, 1])
def test_default_backend_reaches_the_target_when_the_sampling_time_jitters(seed) -> None:
    # a real loop never applies the input for exactly h: the measured state leaves the
    # prediction, the shifted candidate no longer ends on the path, and the fast backend
    # must not be the only thing between the robot and a permanent stop
    path = paper_sinusoid()
    model = Unicycle()
    controller = PathReferenceMPC(model, CONFIG, obstacles=[BOX], path=path)
    rng = np.random.default_rng(seed)
    x = path.start.copy()
    stops = 0
    for _ in range(150):
        solution = controller.solve(x)
        stops += solution.source == PlanSource.STOP
        assert not BOX.contains(x[None, :2])[0]
        x = model.step(x, solution.u0, 0.2 * (1 + 0.1 * rng.uniform(-1, 1)))
    assert np.linalg.norm(x[:2] - path.goal[:2]) < 0.05
    assert stops == 0


def _paper_run(config: MpcConfig, label: str):
    path = paper_sinusoid()
    model = Unicycle()
    controller = PathReferenceMPC(model, config, obstacles=[BOX], path=path)
    return run_closed_loop(controller, model, path.start, goal=path.goal, obstacles=[BOX],
                           label=label, max_time=40.0)


def test_obstacles_left_out_of_the_nlp_are_added_when_the_solution_comes_near() -> None:
    """Constraint generation: with no obstacle active up front, the box still is avoided."""
    run = _paper_run(CONFIG.with_solving(activation_distance=0.0), 'lazy')
    assert run.metrics['reached']
    assert run.metrics['min_clearance'] > 0.0
    assert run.metrics['lyapunov_violations'] == 0


def test_lazy_obstacles_give_the_closed_loop_of_all_obstacles_in_the_nlp(proposed_run) -> None:
    run = _paper_run(CONFIG.with_solving(activation_distance=10.0), 'eager')
    assert run.metrics['reached']
    assert run.metrics['path_length'] == pytest.approx(
        proposed_run.metrics['path_length'], rel=1e-3)


def test_without_a_solver_the_shifted_candidate_is_applied_until_it_runs_out() -> None:
    path, model, horizon = paper_sinusoid(), Unicycle(), 6
    controller = PathReferenceMPC(model, CONFIG.with_changes(horizon=horizon), obstacles=[BOX],
                                  path=path)
    x = path.start.copy()
    for _ in range(3):
        verified = controller.solve(x)
        x = model.step(x, verified.u0, 0.2)
    assert verified.source == PlanSource.SOLVER

    def failing_solver(nlp, w0, params, solver=None, **limits):  # backends.run_solver's
        return SolverRun(w=np.asarray(w0, dtype=float), value=np.inf, success=False,
                         status='injected failure', iterations=0, seconds=0.0)

    controller.runner = failing_solver
    for k in range(1, horizon + 2):
        solution = controller.solve(x)
        assert solution.source == PlanSource.CANDIDATE and not solution.solver_verified
        assert solution.failures == k
        assert 'applied the shifted candidate' in solution.status
        expected = verified.u_pred[k] if k < horizon else np.zeros(2)
        np.testing.assert_allclose(solution.u0, expected, atol=1e-12)
        x = model.step(x, solution.u0, 0.2)


# A plan of BARN world 0 as the re-planning planner made it, and where the Jackal (1 m/s,
# 2 rad/s) stood when every solve failed with the polyline's kinked corners: the horizon's
# reach ends at a corner, so the optimal s sits on a knot where g_p has no derivative.
BARN_0_PLAN = np.array([
    [-2.758, 5.317], [-2.998, 5.701], [-3.1, 5.919], [-3.296, 6.379], [-3.438, 6.809],
    [-3.401, 7.182], [-3.154, 7.578], [-2.94, 7.966], [-2.669, 8.292], [-2.424, 8.728],
    [-2.436, 8.995], [-2.463, 9.384], [-2.644, 9.819], [-2.559, 10.243], [-2.548, 10.445],
    [-2.531, 10.915], [-2.487, 11.357], [-2.488, 11.639], [-2.464, 12.029], [-2.347, 12.412],
    [-2.346, 12.648], [-2.25, 13.0]])
BARN_0_STALL = np.array([-2.87439976, 7.96106054, 1.25414747])


@pytest.mark.parametrize('solver', ['fatrop', 'ipopt'])
def test_a_cold_start_whose_reach_ends_at_a_plan_corner_is_solved(solver: str) -> None:
    path = WaypointPath(BARN_0_PLAN, start_heading=1.931, goal_heading=1.571)
    config = MpcConfig(footprint=((0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215),
                                  (0.254, -0.215)),
                       solving=SolverSettings(solver=solver, compile=False, max_solve_time=3600.0))
    mpc = PathReferenceMPC(Unicycle(v_max=1.0, omega_max=2.0), config, path=path)
    solution = mpc.solve(BARN_0_STALL)
    assert solution.source is PlanSource.SOLVER, solution.status
    assert solution.u0[0] > 0.5  # on its way, not creeping
    assert solution.s > path.project(BARN_0_STALL) + 0.1


# BARN world 2 at 1 m/s: the Jackal at rest beside five sensed boxes, its plan the first one
# (the start-goal line, before any scan). fatrop failed there from every start, and its failing
# first try spent every step's budget: the robot stood still for good.
BARN_2_STALL = np.array([-2.31264, 5.19817, 1.61895])
BARN_2_BOXES = [ConvexPolygon.from_vertices(np.array(v)) for v in (
    [[-1.976, 5.592], [-1.725, 5.465], [-1.671, 5.573], [-1.921, 5.7]],
    [[-2.577, 7.559], [-2.574, 7.236], [-2.534, 7.236], [-2.537, 7.559]],
    [[-2.573, 6.512], [-2.588, 6.169], [-2.548, 6.168], [-2.533, 6.511]],
    [[-2.547, 7.274], [-2.69, 7.231], [-2.675, 7.182], [-2.532, 7.225]],
    [[-2.562, 6.218], [-2.83, 6.206], [-2.827, 6.141], [-2.559, 6.153]])]


def test_a_cold_start_among_obstacles_tries_the_cold_ipopt_first_and_is_solved() -> None:
    path = WaypointPath(np.array([[-2.25, 3.0], [-2.25, 13.0]]), start_heading=1.57,
                        goal_heading=np.pi / 2, capacity=128)
    config = MpcConfig(footprint=((0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215),
                                  (0.254, -0.215)),
                       solving=SolverSettings(compile=False, max_solve_time=3600.0))
    mpc = PathReferenceMPC(Unicycle(v_max=1.0, omega_max=2.0), config, obstacles=BARN_2_BOXES,
                           path=path)
    solution = mpc.solve(BARN_2_STALL)
    assert solution.source is PlanSource.SOLVER, solution.status
    assert '(IPOPT cold start)' in solution.status
    assert solution.u0[0] > 0.5
    # no failing fatrop run of 200 iterations came first
    assert solution.iterations < config.solving.max_iterations


def test_an_obstacle_set_again_is_not_grown_again(monkeypatch) -> None:
    """The laser's pieces come at every control step: each is grown once, while it stays."""
    grown: list[ConvexPolygon] = []
    inflate = ConvexPolygon.inflate

    def counting(self: ConvexPolygon, distance: float) -> ConvexPolygon:
        grown.append(self)
        return inflate(self, distance)

    monkeypatch.setattr(ConvexPolygon, 'inflate', counting)
    mpc = PathReferenceMPC(Unicycle(), MpcConfig(), path=paper_sinusoid())
    first, second = ConvexPolygon.from_box(1.0, 0.0, 1.5, 0.5), ConvexPolygon.from_box(
        3.0, 0.0, 3.5, 0.5)
    mpc.set_obstacles([first])
    before = mpc.inflated_obstacles
    mpc.set_obstacles([first, second])  # a new piece comes; the first stays
    assert [id(p) for p in grown] == [id(first), id(second)]
    assert mpc.inflated_obstacles[0] is before[0]
    # another inflation (the settings changed) grows every obstacle again
    mpc.update_config(MpcConfig(collision_margin=0.3))
    assert [id(p) for p in grown[2:]] == [id(first), id(second)]
    assert np.all(mpc.inflated_obstacles[0].b > before[0].b)
