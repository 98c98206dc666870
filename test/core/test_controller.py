# SPDX-License-Identifier: Apache-2.0
"""MpcController: the node's decisions without ROS (no plan, stale input, goal, blockage)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.controller import MpcController, ROTATE_STEPS
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.input_freshness import InputFreshness
from mpc_local_planner.core.local_controller import LocalController
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc.backends import run_solver, SolverRun
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import analytic_path, WaypointPath
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import load_world, paper_world

WORLD = paper_world()
# Time enough for any solve: these tests are about the controller's decisions, not about the
# solve time budget (test_mpc_budget.py), and must not depend on how loaded the machine is.
CONFIG = MpcConfig(solving=SolverSettings(max_solve_time=3600.0))
# A plan around the paper's box (above it), headings as the planner sends them.
PLAN = np.array([[0.0, 0.0, WORLD.start[2]], [0.8, 1.3, 0.0], [1.7, 1.3, -0.96],
                 [2.5, 0.0, WORLD.goal[2]]])


def _control(controller: MpcController, pose: np.ndarray, now: float,
             **inputs: object) -> ControlOutput:
    """Step as the controller node does: the inputs' ages are checked before compute."""
    refused = InputFreshness.of(controller.settings).check(now, **inputs)
    if refused is None:
        return controller.compute(pose, None, now)
    return controller.refuse_inputs(refused, now)


@pytest.fixture(scope='module')
def controller() -> MpcController:
    return MpcController(Unicycle(), CONFIG, obstacles=WORLD.obstacles)


def test_without_a_plan_the_command_is_zero_with_a_reason(controller: MpcController) -> None:
    fresh = MpcController(config=CONFIG, obstacles=WORLD.obstacles)
    out = fresh.compute(WORLD.start, None, 0.0)
    assert out.reason is Reason.NO_PLAN
    assert out.solution is None
    np.testing.assert_array_equal(out.u, [0.0, 0.0])


def test_without_odometry_the_command_is_zero(controller: MpcController) -> None:
    controller.set_plan(PLAN)
    out = controller.compute(None, None, 10.0)
    assert out.reason is Reason.NO_ODOM
    np.testing.assert_array_equal(out.u, [0.0, 0.0])


def test_stale_odometry_gives_zero(controller: MpcController) -> None:
    controller.set_plan(PLAN)
    timeout = controller.settings.odom_timeout
    out = _control(controller, WORLD.start, 10.0, pose_time=10.0 - 2 * timeout)
    assert out.reason is Reason.STALE_ODOM
    np.testing.assert_array_equal(out.u, [0.0, 0.0])


def test_a_plan_gives_a_bounded_command_and_a_prediction(controller: MpcController) -> None:
    controller.set_plan(PLAN)
    out = _control(controller, WORLD.start, 1.0, pose_time=0.9)
    assert out.reason is Reason.TRACKING
    assert out.solution is not None
    model = controller.model
    assert np.all(out.u >= model.u_min - 1e-12) and np.all(out.u <= model.u_max + 1e-12)
    assert out.u[0] > 0.05  # it drives off
    assert out.solution.x_pred.shape == (controller.config.horizon + 1, 3)


def test_the_goal_reached_gives_zero(controller: MpcController) -> None:
    controller.set_plan(PLAN)
    near_goal = WORLD.goal + np.array([0.005, 0.0, 0.01])
    out = controller.compute(near_goal, None, 0.0)
    assert out.reason is Reason.GOAL_REACHED
    np.testing.assert_array_equal(out.u, [0.0, 0.0])
    position, heading = controller.goal_error(near_goal)
    assert position == pytest.approx(0.005) and heading == pytest.approx(0.01)


def test_a_non_finite_state_gives_zero_as_invalid_odometry_with_the_problem_as_detail(
        controller: MpcController) -> None:
    controller.set_plan(PLAN)
    out = controller.compute(np.array([0.0, np.nan, 0.0]), None, 0.0)
    assert out.reason is Reason.INVALID_ODOM
    assert 'three finite numbers' in out.detail
    assert out.message == f'invalid odometry: {out.detail}'
    np.testing.assert_array_equal(out.u, [0.0, 0.0])


def test_an_exception_in_the_solve_gives_zero_with_the_error_reason_and_its_message() -> None:
    controller = MpcController(config=CONFIG, obstacles=WORLD.obstacles)
    controller.set_plan(PLAN)

    def broken(state: np.ndarray) -> None:
        raise RuntimeError('boom')

    controller.mpc.solve = broken  # type: ignore[method-assign]
    out = controller.compute(WORLD.start, None, 0.0)
    assert out.reason is Reason.ERROR and out.detail == 'RuntimeError: boom'
    assert controller.solver_failures == 1
    np.testing.assert_array_equal(out.u, [0.0, 0.0])


def test_only_the_mpc_the_turn_a_recovery_and_an_evasion_apply_an_input_and_every_reason_has_words(
        ) -> None:
    assert {r for r in Reason if r.applies_input} == {Reason.TRACKING, Reason.CANDIDATE,
                                                      Reason.ROTATE_TO_HEADING,
                                                      Reason.RECOVERY, Reason.EVADE}
    assert all(r.text and ': ' not in r.text for r in Reason)
    assert len({r.value for r in Reason}) == len(Reason)
    plain = ControlOutput(np.zeros(2), None, Reason.NO_PLAN)
    assert plain.detail == '' and plain.message == 'no plan yet'


@pytest.mark.parametrize(('poses', 'match'), [
    (np.zeros((3, 2)), 'shape'),
    (np.zeros((1, 3)), 'at least two'),
    (np.array([[0.0, 0.0, 0.0], [np.inf, 1.0, 0.0]]), 'NaN or inf'),
    (np.zeros((4, 3)), 'two distinct'),
])
def test_bad_plans_are_refused_and_the_old_one_kept(controller: MpcController,
                                                    poses: np.ndarray, match: str) -> None:
    controller.set_plan(PLAN)
    before = controller.path
    with pytest.raises(ValueError, match=match):
        controller.set_plan(poses)
    assert controller.path is before


def test_a_dense_plan_is_simplified_to_fit_the_capacity() -> None:
    controller = MpcController(config=CONFIG, settings=ControllerSettings(capacity=16))
    t = np.linspace(0.0, 1.0, 2000)
    poses = np.column_stack([2.5 * t, 1.1 * np.sin(np.pi * t), np.zeros_like(t)])
    path = controller.set_plan(poses)
    assert isinstance(path, WaypointPath)
    assert len(path.knots) - 1 <= 16
    np.testing.assert_allclose(path.start[:2], poses[0, :2], atol=1e-12)
    np.testing.assert_allclose(path.goal[:2], poses[-1, :2], atol=1e-12)
    # the simplified polyline stays near the dense one
    _, sampled = path.sample(200)
    gaps = np.min(np.linalg.norm(sampled[:, None, :2] - poses[None, :, :2], axis=2), axis=1)
    assert np.max(gaps) < 0.1


def test_a_new_horizon_takes_effect_at_the_next_solve(controller: MpcController) -> None:
    controller.set_path(analytic_path('paper_sinusoid'))
    controller.update_config(controller.config.with_changes(horizon=6))
    out = controller.compute(WORLD.start, None, 0.0)
    assert out.reason is Reason.TRACKING
    assert out.solution.x_pred.shape == (7, 3)
    controller.update_config(controller.config.with_changes(horizon=10))


def test_new_velocity_bounds_bound_the_command() -> None:
    controller = MpcController(config=CONFIG, obstacles=WORLD.obstacles)
    controller.set_path(analytic_path('paper_sinusoid'))
    controller.set_model(Unicycle(v_max=0.1, omega_max=0.5))
    out = controller.compute(WORLD.start, None, 0.0)
    assert out.reason is Reason.TRACKING
    assert abs(out.u[0]) <= 0.1 + 1e-12 and abs(out.u[1]) <= 0.5 + 1e-12
    assert out.u[0] > 0.05


@pytest.mark.parametrize('name', ['xy_goal_tolerance', 'yaw_goal_tolerance'])
@pytest.mark.parametrize('value', [0.0, -0.1, math.nan, math.inf])
def test_settings_refuse_goal_tolerances_that_are_not_positive_and_finite(
        name: str, value: float) -> None:
    with pytest.raises(ValueError, match=f'{name} must be > 0 and finite, got {value}'):
        ControllerSettings(**{name: value})


def test_settings_refuse_a_stateful_that_is_not_a_bool() -> None:
    with pytest.raises(ValueError, match="stateful must be true or false, got 'yes'"):
        ControllerSettings(stateful='yes')  # type: ignore[arg-type]


def test_the_default_goal_tolerances_are_for_noisy_odometry_and_stateful() -> None:
    settings = ControllerSettings()
    # looser than the paper's 2 cm / 0.05 rad (odometry noise 0.5-3 cm), tighter than Nav2's
    # 0.25 m / 0.25 rad
    assert (settings.xy_goal_tolerance, settings.yaw_goal_tolerance) == (0.1, 0.15)
    assert settings.stateful is True


# ----------------------------------------------------------------------------- arrival
# The goal of PLAN, and a pose at its position turned away from its heading.
GOAL = np.array([2.5, 0.0, WORLD.goal[2]])
TURNED = GOAL + np.array([0.05, 0.0, 0.5])


def arrival_controller(**settings: object) -> MpcController:
    controller = MpcController(Unicycle(), CONFIG, obstacles=WORLD.obstacles,
                               settings=ControllerSettings(**settings))
    controller.set_plan(PLAN)
    return controller


def test_at_the_goal_position_off_its_heading_the_robot_turns_in_place_then_arrives() -> None:
    controller = arrival_controller()
    model, step = controller.model, controller.config.step
    x = TURNED.copy()
    reasons = []
    for _ in range(20):
        out = controller.compute(x, None, 0.0)
        reasons.append(out.reason)
        if out.reason is Reason.GOAL_REACHED:
            break
        assert out.reason is Reason.ROTATE_TO_HEADING and out.solution is None
        assert out.u[0] == 0.0 and out.u[1] < 0.0  # towards the heading, no creeping
        assert abs(out.u[1]) <= model.omega_max
        x = model.step(x, out.u, step)
    # omega closes the error over ROTATE_STEPS periods: 0.5 rad -> 0.25 -> 0.125, arrived
    assert reasons == [Reason.ROTATE_TO_HEADING] * 2 + [Reason.GOAL_REACHED]
    np.testing.assert_allclose(x[:2], TURNED[:2], atol=1e-12)  # turned in place
    position, heading = controller.goal_error(x)
    assert position == pytest.approx(0.05) and heading <= 0.15
    assert ROTATE_STEPS == 2.0


def test_a_polygon_robot_beside_an_obstacle_lets_the_mpc_steer_to_the_heading() -> None:
    # a 0.6 x 0.4 m rectangle turning in place sweeps a disc of radius 0.36 m: with a box
    # 0.2 m beside the goal that turn could hit it, so the MPC is asked instead
    rectangle = ((0.3, 0.2), (-0.3, 0.2), (-0.3, -0.2), (0.3, -0.2))
    box = ConvexPolygon.from_box(2.75, -0.5, 3.0, 0.5)
    controller = MpcController(Unicycle(), MpcConfig(footprint=rectangle), obstacles=[box])
    controller.set_plan(PLAN)

    def steered(state: np.ndarray) -> None:
        raise RuntimeError('the MPC was asked')

    controller.mpc.solve = steered  # type: ignore[method-assign]
    out = controller.compute(TURNED, None, 0.0)
    assert out.reason is Reason.ERROR and 'the MPC was asked' in out.detail
    controller.set_obstacles([ConvexPolygon.from_box(3.5, -0.5, 4.0, 0.5)])  # 0.95 m away
    out = controller.compute(TURNED, None, 0.0)
    assert out.reason is Reason.ROTATE_TO_HEADING and out.u[0] == 0.0


def test_stateful_arrival_stays_through_drift_until_a_new_plan() -> None:
    controller = arrival_controller()
    assert controller.compute(GOAL + [0.08, 0.0, 0.1], None, 0.0).reason is Reason.GOAL_REACHED
    # odometry noise carries the measured pose out of both tolerances: still arrived
    for drifted in (GOAL + [0.3, 0.0, 0.0], GOAL + [0.0, 0.12, 1.0], WORLD.start):
        out = controller.compute(drifted, None, 0.0)
        assert out.reason is Reason.GOAL_REACHED and out.solution is None
        np.testing.assert_array_equal(out.u, [0.0, 0.0])
    assert controller.compute(None, None, 0.0).reason is Reason.GOAL_REACHED
    # a new plan (the same poses again: a new goal) is driven to from the drifted pose
    controller.set_plan(PLAN)
    out = controller.compute(GOAL + [0.3, 0.0, 0.0], None, 0.0)
    assert out.reason in (Reason.TRACKING, Reason.CANDIDATE) and out.solution is not None


def test_stateful_the_goal_position_once_met_stays_met_while_turning() -> None:
    controller = arrival_controller()
    assert controller.compute(TURNED, None, 0.0).reason is Reason.ROTATE_TO_HEADING
    # noise moves the position 0.12 m off (outside 0.1 m): the robot still only turns
    out = controller.compute(GOAL + [0.12, 0.0, 0.5], None, 0.0)
    assert out.reason is Reason.ROTATE_TO_HEADING and out.u[0] == 0.0
    assert controller.compute(GOAL + [0.12, 0.0, 0.1], None, 0.0).reason is Reason.GOAL_REACHED


def test_not_stateful_a_pose_that_drifts_out_is_driven_back() -> None:
    controller = arrival_controller(stateful=False)
    assert controller.compute(GOAL + [0.08, 0.0, 0.1], None, 0.0).reason is Reason.GOAL_REACHED
    out = controller.compute(GOAL + [0.3, 0.0, 0.0], None, 0.0)
    assert out.reason in (Reason.TRACKING, Reason.CANDIDATE) and out.solution is not None
    controller.set_plan(PLAN)
    assert controller.compute(TURNED, None, 0.0).reason is Reason.ROTATE_TO_HEADING
    out = controller.compute(GOAL + [0.12, 0.0, 0.5], None, 0.0)  # out of xy: the MPC again
    assert out.reason in (Reason.TRACKING, Reason.CANDIDATE) and out.solution is not None


def test_world_files_resolve_by_name_and_missing_ones_raise() -> None:
    path = resolve_data_file('paper_obstacle.yaml')
    assert load_world(path).obstacles
    assert resolve_data_file('worlds/corridor_turn.yaml').is_file()
    with pytest.raises(FileNotFoundError, match='no_such_world.yaml: not found'):
        resolve_data_file('no_such_world.yaml')


def test_a_plan_through_an_obstacle_is_followed_and_reported_blocked_where_it_enters() -> None:
    controller = MpcController(config=CONFIG, obstacles=WORLD.obstacles)
    straight = np.array([WORLD.start, WORLD.goal])
    path = controller.set_plan(straight)  # no longer refused
    assert controller.path is path
    out = controller.compute(WORLD.start, None, 0.0)
    assert out.reason in (Reason.TRACKING, Reason.CANDIDATE, Reason.STOP)
    blockage = controller.path_blockage(WORLD.start)
    assert blockage.blocked
    # the first point of the straight line inside the grown box, found independently
    grown = controller.grown_obstacles[0]
    t = np.linspace(0.0, 1.0, 200_001)
    line = WORLD.start[:2] + t[:, None] * (WORLD.goal[:2] - WORLD.start[:2])
    first = line[np.argmax(grown.contains(line))]
    assert blockage.at == pytest.approx(np.hypot(*(first - WORLD.start[:2])), abs=1e-3)
    # the MPC keeps the robot's prediction out of the grown obstacle
    if out.solution is not None:
        assert not np.any(grown.contains(out.solution.x_pred[:, :2], margin=-1e-6))


def test_a_clear_plan_is_not_blocked_and_the_distance_counts_from_the_projection() -> None:
    controller = MpcController(config=CONFIG, obstacles=WORLD.obstacles)
    controller.set_plan(PLAN)
    blockage = controller.path_blockage(WORLD.start)
    assert not blockage.blocked and np.isnan(blockage.at)
    assert not controller.path_blockage(None).blocked
    controller.set_obstacles([ConvexPolygon.from_box(1.0, 1.2, 1.2, 1.4)])  # on the plan
    ahead = controller.path_blockage(np.array([0.8, 1.3, 0.0]))  # on the plan's second leg
    assert ahead.blocked
    inflation = controller.config.inflation(controller.model.v_max)
    assert ahead.at == pytest.approx(1.0 - inflation - 0.8, abs=1e-6)


def test_with_the_scan_a_source_no_scan_or_a_stale_one_gives_zero() -> None:
    controller = MpcController(config=CONFIG, obstacles=WORLD.obstacles,
                               settings=ControllerSettings(scan_timeout=0.5))
    controller.set_plan(PLAN)
    out = _control(controller, WORLD.start, 10.0, pose_time=10.0, scan_required=True)
    assert out.reason is Reason.NO_SCAN and not out.u.any()
    out = _control(controller, WORLD.start, 10.0, pose_time=10.0, scan_required=True,
                   scan_time=9.4)
    assert out.reason is Reason.STALE_SCAN and out.message == 'scan is stale'
    assert not out.u.any()
    out = _control(controller, WORLD.start, 10.0, pose_time=10.0, scan_required=True,
                   scan_time=9.6)
    assert out.reason is Reason.TRACKING
    with pytest.raises(ValueError, match='scan_timeout'):
        ControllerSettings(scan_timeout=0.0)


def test_new_obstacles_keep_the_warm_start_and_the_lyapunov_history() -> None:
    controller = MpcController(config=CONFIG, obstacles=WORLD.obstacles)
    controller.set_path(analytic_path('paper_sinusoid'))
    first = controller.compute(WORLD.start, None, 0.0)
    state = first.solution.x_pred[1]
    far = ConvexPolygon.from_box(10.0, 10.0, 11.0, 11.0)
    controller.set_obstacles([*WORLD.obstacles, far])
    assert len(controller.obstacles) == 2
    second = controller.compute(state, None, 0.2)
    assert second.reason is Reason.TRACKING
    assert second.solution.lyapunov_ok is not None  # the history was kept, and checked
    same = controller.grown_obstacles
    controller.set_obstacles(list(controller.obstacles))  # the same objects: nothing to do
    assert controller.grown_obstacles == same


def test_the_mpc_controller_implements_the_local_controller_interface() -> None:
    assert isinstance(MpcController(config=CONFIG), LocalController)


def test_reset_forgets_the_run_as_a_new_controller_would_start_it() -> None:
    used = MpcController(config=CONFIG, obstacles=WORLD.obstacles)
    used.set_path(analytic_path('paper_sinusoid'))
    x = np.asarray(WORLD.start, dtype=float)
    for k in range(3):
        x = used.compute(x, None, 0.2 * k).solution.x_pred[1]
    used.reset()
    assert used.path is None
    out = used.compute(x, None, 0.6)
    assert out.reason is Reason.NO_PLAN and not out.u.any()  # nothing held, nothing braked
    new = MpcController(config=CONFIG, obstacles=WORLD.obstacles)
    for controller in (used, new):
        controller.set_path(analytic_path('paper_sinusoid'))
    # the same step as a new controller's first: no held input, no candidate, no history
    a, b = used.compute(x, None, 0.65), new.compute(x, None, 0.65)
    assert a.fresh and a.reason is b.reason is Reason.TRACKING
    assert a.solution.lyapunov_ok is None and b.solution.lyapunov_ok is None
    np.testing.assert_array_equal(a.u, b.u)
    np.testing.assert_array_equal(a.solution.x_pred, b.solution.x_pred)


def test_a_speed_limit_caps_every_command_until_it_is_lifted() -> None:
    controller = MpcController(config=CONFIG, obstacles=WORLD.obstacles)
    controller.set_plan(PLAN)
    cap = 0.12  # the paper's Turtlebot drives at up to 0.31 m/s here
    controller.set_speed_limit(cap)
    assert controller.speed_limit == cap and controller.model.v_max == Unicycle().v_max
    model = controller.model.discrete(0.2)
    x = np.asarray(WORLD.start, dtype=float)
    speeds = []
    for k in range(15):
        out = controller.compute(x, None, 0.2 * k)
        # the plans within the solver's tolerance, the command exactly
        assert out.solution is None or np.all(np.abs(out.solution.u_pred[:, 0]) <= cap + 1e-6)
        speeds.append(abs(out.u[0]))
        x = np.asarray(model(x, out.u)).reshape(-1)
    assert max(speeds) <= cap and max(speeds) > 0.9 * cap
    controller.set_speed_limit(None)
    out = controller.compute(x, None, 3.0)
    assert out.reason is Reason.TRACKING and abs(out.u[0]) > cap
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match='speed limit'):
            controller.set_speed_limit(bad)


def test_the_solver_runner_is_injected_and_kept_through_a_rebuild() -> None:
    calls: list[int] = []

    def counting(*args: object, **kwargs: object) -> SolverRun:
        calls.append(1)
        return run_solver(*args, **kwargs)

    controller = MpcController(config=CONFIG, obstacles=WORLD.obstacles, runner=counting)
    assert controller.runner is counting and controller.mpc.runner is counting
    controller.set_plan(PLAN)
    controller.set_speed_limit(0.2)  # a rebuild of the MPC
    assert controller.runner is counting
    assert controller.compute(WORLD.start, None, 0.0).reason is Reason.TRACKING and calls
