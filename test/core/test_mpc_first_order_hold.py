# SPDX-License-Identifier: Apache-2.0
"""MpcConfig.input_hold 'first_order': ramps between knots, in the NLP and out of it.

The dynamics integrate the ramp; the shifted candidate of a solution keeps every constraint;
a rate-limited, lagging base commanded along the ramp (led by its latency and lag) ends
where the plan predicts; and the paper's zero hold builds the NLP it built before.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest

from mpc_local_planner.core.braking import Brake
from mpc_local_planner.core.config import CostWeights, MpcConfig, SolverSettings
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.moving_obstacles import MOTION_SIZE
from mpc_local_planner.core.mpc import PathReferenceMPC, PlanSource
from mpc_local_planner.core.mpc.formulation import formulate, path_terminal
from mpc_local_planner.core.mpc.tries import Start
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet
from mpc_local_planner.core.paths import paper_sinusoid, WaypointPath
from mpc_local_planner.sim.base import Base
from mpc_local_planner.sim.reality import Reality

JACKAL_VERTICES = tuple((float(x), float(y)) for x, y in JACKAL.vertices)
MODEL = Unicycle(v_max=2.0, omega_max=4.0, v_min=0.0)
RATE = (2.0, 6.0)  # the 'real' base's limits


def exact_ramp(x0: np.ndarray, q: np.ndarray, u: np.ndarray, h: float,
               samples: int = 20001) -> np.ndarray:
    """Return the unicycle's pose after h with (v, omega) linear from q to u (quadrature)."""
    t = np.linspace(0.0, h, samples)
    v = q[0] + (u[0] - q[0]) * t / h
    theta = x0[2] + q[1] * t + (u[1] - q[1]) * t ** 2 / (2 * h)  # exact
    dx, dy = v * np.cos(theta), v * np.sin(theta)
    return np.array([x0[0] + np.trapezoid(dx, t), x0[1] + np.trapezoid(dy, t), theta[-1]])


@pytest.mark.parametrize(('q', 'u'), [((0.0, 0.0), (0.4, 1.2)), ((2.0, -4.0), (1.6, -2.8)),
                                      ((1.0, 4.0), (1.4, 2.8)), ((1.5, 3.0), (1.5, 3.0))])
def test_a_ramp_integrates_to_the_arc_of_a_linearly_varying_twist(q: tuple, u: tuple) -> None:
    x0 = np.array([0.3, -0.2, 0.7])
    got = np.asarray(MODEL.discrete_ramp(0.2)(x0, q, u)).reshape(-1)
    expected = exact_ramp(x0, np.array(q), np.array(u), 0.2)
    assert np.max(np.abs(got - expected)) < 5e-5
    if q == u:  # a ramp of zero slope is the zero hold
        held = np.asarray(MODEL.discrete(0.2)(x0, u)).reshape(-1)
        assert np.max(np.abs(got - held)) < 5e-5


def test_first_order_needs_max_accel_and_unknown_holds_are_refused() -> None:
    with pytest.raises(ValueError, match='needs max_accel'):
        MpcConfig(input_hold='first_order')
    with pytest.raises(ValueError, match='input_hold must be one of'):
        MpcConfig(input_hold='linear', max_accel=RATE)
    assert 'input_hold' in dict(MpcConfig().structure_key())  # a change rebuilds the NLPs


def _mpc(hold: str, obstacles: list[ConvexPolygon]) -> PathReferenceMPC:
    config = MpcConfig(footprint=JACKAL_VERTICES, collision_margin=0.03, max_accel=RATE,
                       input_hold=hold, solving=SolverSettings(
                           budget='iterations', max_solve_iterations=200, compile=False))
    path = WaypointPath(np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 3.0]]), capacity=16)
    return PathReferenceMPC(MODEL, config, obstacles=obstacles, path=path)


def test_the_shifted_candidate_of_a_first_order_solution_is_feasible() -> None:
    obstacles = [ConvexPolygon.from_box(1.0, 0.5, 2.0, 1.5)]
    mpc = _mpc('first_order', obstacles)
    x = np.array([0.0, 0.0, 0.0])
    rate = np.array(RATE) * mpc.config.step
    before = np.zeros(2)
    for _ in range(6):
        solution = mpc.solve(x)
        assert solution.source is PlanSource.SOLVER, solution.status
        # the knots start from the velocity of the plan before, move within the rate bounds
        # and end at rest (u_{N-1} = 0)
        np.testing.assert_allclose(solution.u_before, before, atol=1e-12)
        knots = np.vstack([before, solution.u_pred])
        assert np.all(np.abs(np.diff(knots, axis=0)) <= rate + 1e-6)
        assert np.all(np.abs(solution.u_pred[-1]) <= 1e-6)
        # the robot carries out the first ramp exactly: the prediction
        x = np.asarray(MODEL.discrete_ramp(mpc.config.step)(
            x, solution.u_before, solution.u0)).reshape(-1)
        np.testing.assert_allclose(x, solution.x_pred[1], atol=1e-6)
        before = solution.u_pred[0]
        # the proof's candidate from there: every row of the NLP holds, obstacles cleared
        problem = mpc.solver_problem(x, mpc.inflated_obstacles, start=Start.CANDIDATE)
        layout = problem.nlp.formulation.layout
        np.testing.assert_allclose(problem.w0[layout.x][:-1], solution.x_pred[1:], atol=1e-6)
        np.testing.assert_allclose(problem.w0[layout.prev][0], before)  # its first ramp's start
        reachable = ObstacleSet(list(mpc.inflated_obstacles))
        assert mpc.clearance.violation(problem.nlp.formulation, problem.w0, problem.params,
                                       reachable) <= 1e-5


def test_the_tracking_baseline_builds_with_a_first_order_hold() -> None:
    from mpc_local_planner.core.baselines.tracking_mpc import TrackingMPC

    config = MpcConfig(robot_radius=0.2, max_accel=RATE, input_hold='first_order',
                       solving=SolverSettings(compile=False, budget='iterations'))
    mpc = TrackingMPC(MODEL, config, target=np.array([2.0, 0.0, 0.0]))
    solution = mpc.solve(np.zeros(3))
    assert solution.source is not PlanSource.STOP, solution.status
    assert np.all(np.abs(solution.u_pred[-1]) <= 1e-6)


def _prediction_errors(hold: str, factor: float, delay: float) -> np.ndarray:
    """Drive a rate-limited, lagging base with the controller at 20 Hz; one-step errors."""
    reality = Reality(lag=(0.1, 0.1), acceleration=RATE, latency=0.05)
    config = MpcConfig(footprint=JACKAL_VERTICES, collision_margin=0.03,
                       max_accel=tuple(factor * a for a in RATE), input_hold=hold,
                       solving=SolverSettings(budget='iterations', max_solve_iterations=100,
                                              compile=False))
    controller = MpcController(MODEL, config, settings=ControllerSettings(
        max_decel=RATE, actuation_delay=delay, xy_goal_tolerance=0.1,
        yaw_goal_tolerance=math.pi))
    controller.set_plan(np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.5, 1.5, 1.57],
                                  [1.0, 3.0, 3.14]]))
    base = Base(MODEL, reality, np.zeros(3), dt=0.01)
    period, h = 0.05, config.step
    pending: list[tuple[float, np.ndarray, np.ndarray]] = []
    errors = []
    for k in range(int(8.0 / period)):
        t = k * period
        for start, pose, predicted in list(pending):
            if abs(t - start - h) < 1e-9:
                pending.remove((start, pose, predicted))
                actual = _relative(pose, base.pose)
                errors.append((float(np.hypot(*(actual[:2] - predicted[:2]))),
                               abs(actual[2] - predicted[2])))
        output = controller.compute(base.pose.copy(), base.twist(), t)
        if output.fresh and output.reason.applies_input and output.solution is not None:
            pending.append((t, base.pose.copy(),
                            _relative(output.solution.x_pred[0], output.solution.x_pred[1])))
        base.command(output.u, t)
        base.advance(t + period)
    return np.array(errors)


def _relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    c, s = math.cos(a[2]), math.sin(a[2])
    d = np.asarray(b[:2]) - np.asarray(a[:2])
    return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1],
                     (b[2] - a[2] + math.pi) % (2 * math.pi) - math.pi])


def test_a_lagging_rate_limited_base_ends_where_a_first_order_plan_predicts() -> None:
    # the property: one step after each solve, the base (latency 0.05 s, lag 0.1 s,
    # the limits the plan's ramps keep) is within 4 cm and 0.04 rad of the predicted pose
    foh = _prediction_errors('first_order', 1.0, delay=0.15)
    assert len(foh) > 20
    assert np.max(foh[:, 0]) < 0.04 and np.max(foh[:, 1]) < 0.04, np.max(foh, axis=0)
    # the zero hold at twice the limits (the Jackal's before) jumps where the base cannot
    zoh = _prediction_errors('zero', 2.0, delay=0.0)
    assert np.max(zoh[:, 1]) > np.max(foh[:, 1])


def test_the_plan_velocity_and_braking_follow_the_ramp() -> None:
    mpc = _mpc('first_order', [])
    solution = mpc.solve(np.zeros(3), previous_input=np.array([0.5, 0.0]))
    h = mpc.config.step
    np.testing.assert_allclose(solution.velocity_at(0.0, h), solution.u_before)
    np.testing.assert_allclose(solution.velocity_at(h, h), solution.u_pred[0])
    np.testing.assert_allclose(solution.velocity_at(1.5 * h, h),
                               (solution.u_pred[0] + solution.u_pred[1]) / 2)
    brake = Brake((math.inf, math.inf))  # infinite limits: stop at once
    brake.start(solution.u_pred, h, 0.0, solution.u_before)
    assert not brake.active
    brake = Brake((100.0, 100.0))  # nearly no braking over 1 ms: the ramp's value
    brake.start(solution.u_pred, h, 0.5 * h, solution.u_before)
    np.testing.assert_allclose(brake.command(1e-3),
                               solution.velocity_at(0.5 * h + 1e-3, h), atol=0.1)


# The zero-hold formulations as built before the first-order hold existed: per case, three
# probes (w, p uniform from default_rng(0)) of g(w, p) . r and of the cost J(w, p), and the
# sha256 of the bounds (lbg, ubg, lbw, ubw). Values, not serialized Functions: any CasADi
# version evaluates the same expressions to the same numbers (to rounding).
ZERO_HOLD_FINGERPRINTS = {
    'circle': ((0.97168295987261, 146.544880552297, 3.78583540243564, 91.4296240807782,
                -0.069901332509218, 45.6314234389458),
               '3c2276a8e837bf1e7efb0a2210c248a8482fe2c277770e89617fbbd94446823d'),
    'polygon_max_accel': ((-10.7575729295885, 18.4195666410779, 11.4222484394719,
                           14.5848985396832, -6.2737119846243, 14.7346230223165),
                          '26984ffe75c5fe950f7e8e09c41b7e92821b44616811a09da57f928cda09381a'),
    'circle_max_accel': ((2.75232738283271, 179.411771204651, -13.7656966103009,
                          309.813713027508, 4.32538652518701, 122.440020517352),
                         '61377818a44679aab7e7e3d71216c5a7682a5498250e6502b2ddf4d51c6468e8'),
}


def _with_static_motion(p: np.ndarray, nx: int, *, slots: int, faces: int) -> np.ndarray:
    """Insert a static motion (zeros) after each obstacle slot of a parameter vector."""
    start = nx + len(CostWeights._fields)
    parts = [p[:start]]
    for j in range(slots):
        parts += [p[start + 3 * faces * j:start + 3 * faces * (j + 1)], np.zeros(MOTION_SIZE)]
    parts.append(p[start + 3 * faces * slots:])
    return np.concatenate(parts)


def test_the_zero_hold_formulation_is_the_one_built_before() -> None:
    model = Unicycle(v_max=2.0, omega_max=4.0)
    footprint = ((0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215), (0.254, -0.215))
    waypoints = WaypointPath(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 1.0]]), capacity=8)
    cases = {
        'circle': (MpcConfig(robot_radius=0.2), paper_sinusoid()),
        'polygon_max_accel': (MpcConfig(footprint=footprint, max_accel=RATE), waypoints),
        'circle_max_accel': (MpcConfig(robot_radius=0.2, max_accel=RATE), paper_sinusoid()),
    }
    for name, (config, path) in cases.items():
        assert config.input_hold == 'zero'
        form = formulate(model, config, path_terminal(model, path), slots=2, faces=4)
        rng = np.random.default_rng(0)
        probes = []
        for _ in range(3):
            w = rng.uniform(-1.0, 1.0, form.problem['x'].shape[0])
            # the parameters as they were laid out before obstacles could move: each slot's
            # motion (zeros: static) is put in after its half-planes
            p = _with_static_motion(rng.uniform(
                0.1, 1.0, form.problem['p'].shape[0] - 2 * MOTION_SIZE), model.nx, slots=2,
                faces=4)
            g = np.asarray(form.g_fn(w, p)).ravel()
            probes += [float(g @ rng.uniform(-1.0, 1.0, g.size)), float(form.cost_fn(w, p))]
        values, bounds = ZERO_HOLD_FINGERPRINTS[name]
        np.testing.assert_allclose(probes, values, rtol=1e-9, err_msg=name)
        digest = hashlib.sha256()
        for bound in (form.lbg, form.ubg, form.lbw, form.ubw):
            digest.update(bound.tobytes())
        assert digest.hexdigest() == bounds, name
