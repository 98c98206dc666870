# SPDX-License-Identifier: Apache-2.0
"""The exact polygonal footprint in the MPC, and closed loops of the Jackal (no ROS).

The dual separation rows and their multipliers, the motion-dependent clearance, the exact
verification, constraint generation and the shifted candidate with a polygon.
"""

from __future__ import annotations

from typing import NamedTuple

import casadi as ca
import numpy as np
import pytest

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import Decision, PathReferenceMPC, PlanSource
from mpc_local_planner.core.mpc.backends import SolverRun
from mpc_local_planner.core.mpc.formulation import (
    formulate,
    Formulation,
    path_terminal,
    sweep_rate,
    SWEEP_SMOOTHING,
)
from mpc_local_planner.core.mpc.nlp_values import (
    dual_multipliers,
    obstacle_parameters,
    parameter_vector,
)
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet, polygon_separation
from mpc_local_planner.core.paths import AnalyticPath, paper_sinusoid, ReferencePath, WaypointPath

JACKAL_VERTICES = tuple((float(x), float(y)) for x, y in JACKAL.vertices)
H = 0.2
PAPER_BOX = ConvexPolygon.from_box(1.0, -1.0, 1.5, 1.0)
# a gap 0.60 m wide (the Jackal is 0.43 m wide) between two boxes 0.5 m long
GAP_BOXES = [ConvexPolygon.from_box(1.0, 0.30, 1.5, 1.0),
             ConvexPolygon.from_box(1.0, -1.0, 1.5, -0.30)]


# Time enough for any solve: interpreted functions on a loaded machine may need more than the
# default budget (half the period), and these tests are about the footprint, not about it.
NO_TIME_LIMIT = 3600.0


def jackal_config(**changes: object) -> MpcConfig:
    """The Jackal's footprint, interpreted functions (gcc would take longer than the test)."""
    return MpcConfig(footprint=JACKAL_VERTICES, solving=SolverSettings(
        compile=False, max_solve_time=NO_TIME_LIMIT)).with_changes(**changes)


def clearance(poses: np.ndarray, obstacles: list[ConvexPolygon]) -> np.ndarray:
    """The exact signed distance of the Jackal at each pose to the nearest obstacle."""
    signed, _ = polygon_separation(JACKAL.at_poses(np.atleast_2d(poses)), ObstacleSet(obstacles))
    return np.min(signed, axis=1)


def sinusoid(amplitude: float) -> AnalyticPath:
    """The paper's path shape p(s) = [2.5 s, a sin(pi s), heading] (a = 1.1 in the paper)."""
    return AnalyticPath('sinusoid', lambda s: ca.vertcat(
        2.5 * s, amplitude * ca.sin(ca.pi * s),
        ca.atan(amplitude * ca.pi * ca.cos(ca.pi * s) / 2.5)))


# ----------------------------------------------------------------------------- formulation
def stage_rows(form: Formulation, stage: int) -> int:
    """Index of the first of a stage's own constraint rows (after its gap-closing rows)."""
    nx, ng = form.structure['nx'], form.structure['ng']
    offset = 0
    for k in range(stage + 1):
        if k > 0:
            offset += ng[k - 1]
        if k < form.structure['N']:
            offset += nx[k + 1]  # the gap-closing rows of stage k come first
    return offset


def test_the_polygon_nlp_has_the_stage_sizes_fatrop_is_given() -> None:
    model, path, config = Unicycle(), paper_sinusoid(), jackal_config(horizon=4)
    form = formulate(model, config, path_terminal(model, path), slots=2, faces=5)
    structure, layout = form.structure, form.layout
    assert form.robot_faces == 4 and form.block == 9
    assert structure['nx'] == [4] + [5] * 4  # (x, s) and, from stage 1 on, the carried rate
    nw = sum(structure['nx']) + sum(structure['nu'])
    assert nw == form.lbw.shape[0] == (layout.x.size + layout.r.size + layout.u.size
                                       + layout.mu.size + layout.c.size)
    assert layout.c.shape == (4, 1) and layout.mu.shape == (4, 18)
    dynamics_rows = config.horizon * (model.nx + 1 + 1)
    assert sum(structure['ng']) + dynamics_rows == form.lbg.shape[0]
    # per slot: two clearance rows (steps before and after), G^T mu + R^T A^T lambda = 0,
    # |A^T lambda|^2 <= 1; the last stage has no step after it
    assert structure['ng'][1:] == [2 * 5] * 3 + [2 * 4 + 3]


def test_the_dual_bound_at_the_warm_start_multipliers_is_the_exact_distance() -> None:
    rng = np.random.default_rng(21)
    model, path = Unicycle(), paper_sinusoid()
    config = jackal_config(horizon=2)
    slots, faces = 3, 8  # two obstacles (padded to 8 faces) and an empty slot
    form = formulate(model, config, path_terminal(model, path), slots=slots, faces=faces)
    rate = sweep_rate(model, JACKAL.radius, SWEEP_SMOOTHING)
    disjoint = overlapping = 0
    for _ in range(40):
        obstacles = [ConvexPolygon.from_circle(*rng.uniform(-1.0, 1.0, 2), rng.uniform(0.1, 0.4),
                                               sides=int(rng.integers(3, 9)))
                     for _ in range(2)]
        x = np.column_stack([rng.uniform(-1.5, 1.5, (3, 2)), rng.uniform(-np.pi, np.pi, 3)])
        u = rng.uniform(-1.0, 1.0, (2, 2))
        mu = dual_multipliers(x, JACKAL.body, obstacles, slots, faces)
        w = form.pack(x, np.array([0.5]), u, mu)
        params = parameter_vector(x[0], config.cost_weights(),
                                  obstacle_parameters(obstacles, slots, faces), path.parameters())
        g = np.asarray(form.g_fn(w, params)).reshape(-1)
        exact = polygon_separation(JACKAL.at_poses(x[1:]), ObstacleSet(obstacles))[0]
        blocks = mu.reshape(2, slots, faces + 4)
        for stage in (1, 2):
            before = H / 2 * float(rate(x[stage - 1], u[stage - 1]))
            row = stage_rows(form, stage)
            for j in range(slots):
                width = 5 if stage == 1 else 4
                rows = g[row + j * width:row + (j + 1) * width]
                bound = rows[0] + before  # the clearance row holds bound - h/2 rate
                if j < 2:
                    assert bound == pytest.approx(exact[stage - 1, j], abs=1e-12)
                    np.testing.assert_allclose(rows[-3:-1], 0.0, atol=1e-12)  # G^T mu + ...
                    assert rows[-1] == pytest.approx(1.0, abs=1e-12)  # |A^T lambda| = 1
                    # the padded faces repeat the last one and get no multiplier
                    n = obstacles[j].num_faces
                    assert np.all(blocks[stage - 1, j, n:faces] == 0.0)
                    disjoint += exact[stage - 1, j] > 0
                    overlapping += exact[stage - 1, j] < 0
                else:  # the empty slot is trivially feasible
                    assert rows[0] >= config.farkas_margin
                    np.testing.assert_allclose(rows[-3:-1], 0.0, atol=1e-12)
                    assert rows[-1] <= 1.0
                if stage == 1:  # the step after x_1 (x_2 has none: u_N = 0)
                    after = H / 2 * float(rate(x[1], u[1]))
                    assert rows[1] + after == pytest.approx(bound, abs=1e-12)
    assert disjoint > 20 and overlapping > 5


def test_the_dual_optimum_over_the_multipliers_is_the_exact_distance() -> None:
    """Maximise the NLP's own bound over lambda and mu (IPOPT): weak duality is tight."""
    rng = np.random.default_rng(22)
    model, path = Unicycle(), paper_sinusoid()
    config = jackal_config(horizon=1)
    faces = 6
    form = formulate(model, config, path_terminal(model, path), slots=1, faces=faces)
    index = form.layout.mu[0]
    select = ca.DM.zeros(form.lbw.shape[0], len(index))
    for column, i in enumerate(index):
        select[int(i), column] = 1.0
    multipliers = ca.MX.sym('m', len(index))
    row = stage_rows(form, 1)
    solved = 0
    while solved < 8:
        obstacle = ConvexPolygon.from_circle(*rng.uniform(-1.0, 1.0, 2), rng.uniform(0.1, 0.4),
                                             sides=int(rng.integers(3, 7)))
        x = np.array([[0.0, 0.0, 0.0], [*rng.uniform(-1.5, 1.5, 2), rng.uniform(-np.pi, np.pi)]])
        distance = polygon_separation(JACKAL.at_poses(x[1:]), ObstacleSet([obstacle]))[0][0, 0]
        if distance <= 0.05:  # overlapping: the dual's best is lambda = mu = 0, value 0
            continue
        w = form.pack(x, np.array([0.5]), np.zeros((1, 2)),
                      np.zeros(len(index)))
        params = parameter_vector(x[0], config.cost_weights(),
                                  obstacle_parameters([obstacle], 1, faces), path.parameters())
        g = form.g_fn(ca.DM(w) + ca.mtimes(select, multipliers), params)
        solver = ca.nlpsol('dual', 'ipopt', {'x': multipliers, 'f': -g[row],
                                             'g': g[row + 1:row + 4]},
                           {'ipopt.print_level': 0, 'print_time': False, 'ipopt.tol': 1e-10})
        result = solver(x0=np.full(len(index), 0.1), lbx=0.0, ubx=np.inf,
                        lbg=[0.0, 0.0, -np.inf], ubg=[0.0, 0.0, 1.0])
        assert solver.stats()['success']
        rate = H / 2 * float(sweep_rate(model, JACKAL.radius, SWEEP_SMOOTHING)(x[0], [0, 0]))
        assert -float(result['f']) + rate == pytest.approx(distance, abs=1e-6)
        solved += 1


# ----------------------------------------------------------------------------- verification
def standing(pose: list[float], horizon: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """A plan that stays at pose: (N+1, 3) states, (N, 2) zero inputs."""
    return np.tile(pose, (horizon + 1, 1)), np.zeros((horizon, 2))


def test_verification_rejects_a_corner_overlap_that_the_inscribed_circle_misses() -> None:
    mpc = PathReferenceMPC(Unicycle(), jackal_config(), path=paper_sinusoid())
    # the front-left corner (0.254, 0.215) reaches into this box
    box = ConvexPolygon.from_box(0.23, 0.10, 0.50, 0.50)
    assert box.distance(np.zeros((1, 2)))[0] > 0.215  # the inscribed circle is clear of it
    x, u = standing([0.0, 0.0, 0.0])
    assert mpc.clearance.penetration(x, u, ObstacleSet([box])) == pytest.approx(
        0.024 + mpc.config.farkas_margin)  # the corner is 0.024 deep along x
    # turned by 90 degrees the polygon is 0.015 clear of it, the circle of r_c would not be
    x, u = standing([0.0, 0.0, np.pi / 2])
    assert box.distance(np.zeros((1, 2)))[0] < JACKAL.radius
    assert mpc.clearance.penetration(x, u, ObstacleSet([box])) == 0.0


def test_the_verified_clearance_follows_the_motion_of_both_adjacent_steps() -> None:
    mpc = PathReferenceMPC(Unicycle(), jackal_config(), path=paper_sinusoid())
    box = ConvexPolygon.from_box(0.28, -0.1, 0.5, 0.1)  # 0.026 ahead of the front face
    x, u = standing([0.0, 0.0, 0.0])
    assert mpc.clearance.penetration(x, u, ObstacleSet([box])) == 0.0  # standing still: clear
    # the poses as given, but the last step drives at 0.31 m/s: x_N needs h/2 0.31 = 0.031
    u[-1] = [0.31, 0.0]
    assert mpc.clearance.penetration(x, u, ObstacleSet([box])) == pytest.approx(
        0.031 + mpc.config.farkas_margin - 0.026)
    # turning on the spot sweeps the corners: h/2 r_c |omega|
    u[-1] = [0.0, -1.5]
    assert mpc.clearance.penetration(x, u, ObstacleSet([box])) == pytest.approx(
        H / 2 * JACKAL.radius * 1.5 + mpc.config.farkas_margin - 0.026)
    # the step before x_l counts too: at x_{N-1}, the step N-2 -> N-1
    u[:] = 0.0
    u[-2] = [0.31, 0.0]
    assert mpc.clearance.penetration(x, u, ObstacleSet([box])) > 0.0


def test_the_reach_counts_the_bodys_farthest_corner() -> None:
    reach = 0.31 * H * 10  # the robot's origin moves this far within the horizon
    inside = ConvexPolygon.from_box(reach + JACKAL.radius - 0.01, -0.1, 3.0, 0.1)
    beyond = ConvexPolygon.from_box(reach + JACKAL.radius + 0.01, 0.5, 3.0, 0.7)
    polygon = PathReferenceMPC(Unicycle(), jackal_config(), obstacles=[inside, beyond],
                               path=paper_sinusoid())
    assert polygon.reachable_obstacles(np.zeros(3)) == [inside]
    point = PathReferenceMPC(Unicycle(),
                             MpcConfig(collision_margin=0.0,
                                       solving=SolverSettings(compile=False)),
                             obstacles=[inside, beyond], path=paper_sinusoid())
    assert polygon.inflated_obstacles == (inside, beyond)  # no radius, no default margin
    assert point.reachable_obstacles(np.zeros(3)) == []


def test_an_explicit_collision_margin_inflates_the_obstacles_of_a_polygon() -> None:
    mpc = PathReferenceMPC(Unicycle(), jackal_config(collision_margin=0.05),
                           obstacles=[PAPER_BOX], path=paper_sinusoid())
    (inflated,) = mpc.inflated_obstacles
    np.testing.assert_allclose(inflated.b, PAPER_BOX.b + 0.05)


# ----------------------------------------------------------------------------- closed loops
class Run(NamedTuple):
    """What a closed loop did, for the assertions."""

    x: np.ndarray  # the final state
    states: np.ndarray  # (K+1, 3) the sampled states
    inputs: np.ndarray  # (K, 2) the applied inputs
    predicted: float  # the least clearance of any predicted pose
    true: float  # the least clearance of the true motion, sub-sampled at h/20
    sources: list[PlanSource]
    statuses: list[str]
    lyapunov: list[bool | None]
    values: np.ndarray
    progress: np.ndarray


def drive(mpc: PathReferenceMPC, x: np.ndarray, steps: int, obstacles: list[ConvexPolygon],
          goal: np.ndarray | None = None) -> Run:
    """Solve, apply u0 for h with the model's discrete step; stop at the goal if given."""
    model = mpc.model
    states, inputs, sources, statuses, lyapunov, values, progress = [x], [], [], [], [], [], []
    predicted = true = np.inf
    for _ in range(steps):
        sol = mpc.solve(x)
        predicted = min(predicted, float(np.min(clearance(sol.x_pred, obstacles))))
        between = np.array([model.step(x, sol.u0, H * i / 20) for i in range(1, 21)])
        true = min(true, float(np.min(clearance(between, obstacles))))
        x = between[-1]
        states.append(x)
        inputs.append(sol.u0)
        sources.append(sol.source)
        statuses.append(sol.status)
        lyapunov.append(sol.lyapunov_ok)
        values.append(sol.value)
        progress.append(sol.s)
        if goal is not None and np.hypot(*(x[:2] - goal[:2])) < 0.01:
            break
    return Run(x=x, states=np.array(states), inputs=np.array(inputs), predicted=predicted,
               true=true, sources=sources, statuses=statuses, lyapunov=lyapunov,
               values=np.array(values), progress=np.array(progress))


def gap_path(offset: float) -> ReferencePath:
    """From (0, offset) to the gap's centre line, then straight through it to x = 3."""
    return WaypointPath(np.array([[0.0, offset], [0.6, 0.0], [3.0, 0.0]]), start_heading=0.0)


@pytest.mark.parametrize(('solver', 'activation'), [
    ('fatrop', None),  # the default: boxes enter the NLP when the plan comes near
    ('fatrop', 0.0),  # none up front: constraint generation adds them
    ('ipopt', 10.0),  # both boxes in the NLP at every step
])
def test_the_jackal_drives_through_a_gap_of_0_60_m(solver: str,
                                                   activation: float | None) -> None:
    config = jackal_config().with_solving(solver=solver, activation_distance=activation)
    path = gap_path(0.3)
    mpc = PathReferenceMPC(Unicycle(), config, obstacles=GAP_BOXES, path=path)
    run = drive(mpc, np.array([0.0, 0.3, 0.0]), 70, GAP_BOXES)
    assert run.x[0] > 2.5  # well past the gap (its boxes end at x = 1.5)
    assert run.predicted >= 0.0 and run.true >= 0.0
    assert run.true >= config.farkas_margin - 1e-9
    assert all(source is PlanSource.SOLVER for source in run.sources), set(run.statuses)
    assert all(ok is not False for ok in run.lyapunov)
    # the clearance follows the motion: it does not slow the robot down in the gap, where
    # 0.085 m is left on each side and full speed needs 0.031 m
    in_gap = (run.states[:-1, 0] > 1.0 - 0.3) & (run.states[:-1, 0] < 1.5 + 0.3)
    assert np.sum(in_gap) >= 5
    assert np.all(run.inputs[in_gap, 0] > 0.3)


def test_the_shifted_candidate_of_a_polygon_plan_is_verified_and_applied() -> None:
    mpc = PathReferenceMPC(Unicycle(), jackal_config(), obstacles=GAP_BOXES, path=gap_path(0.3))
    x = np.array([0.0, 0.3, 0.0])
    run = drive(mpc, x, 14, GAP_BOXES)  # to the mouth of the gap, both boxes in the NLP
    assert mpc.last_active_obstacles and run.sources[-1] is PlanSource.SOLVER

    def failing_solver(nlp, w0, params, solver=None, **limits):  # backends.run_solver's
        return SolverRun(w=np.asarray(w0, dtype=float), value=np.inf, success=False,
                         status='injected failure', iterations=0, seconds=0.0)

    mpc.runner = failing_solver
    failed = drive(mpc, run.x, 6, GAP_BOXES)
    # the proof's candidate meets the NLP's smooth clearance rows with the exact multipliers
    assert all(status.endswith(f'({Decision.CANDIDATE_SOLVER_FAILED.value})')
               for status in failed.statuses)
    assert failed.true >= 0.0
    assert np.all(np.diff(failed.values) <= 1e-9)


def test_the_jackal_does_not_fit_the_papers_path_and_stops_safely_in_front_of_the_box() -> None:
    """Assumption 1 fails: on s in about [0.26, 0.74] the Jackal on the path meets the box.

    The prediction ends on the path, so its end cannot cross that stretch; V_N does not
    increase, so the MPC cannot give up progress either: it stops in front, clear of it.
    """
    path = paper_sinusoid()
    s = np.linspace(0.0, 1.0, 401)
    blocked = s[clearance(path.pose(s), [PAPER_BOX]) < 0.0]
    assert blocked.min() == pytest.approx(0.26, abs=0.01)
    assert blocked.max() == pytest.approx(0.74, abs=0.01)
    mpc = PathReferenceMPC(Unicycle(), jackal_config(), obstacles=[PAPER_BOX], path=path)
    run = drive(mpc, path.start.copy(), 40, [PAPER_BOX])
    assert run.true >= 0.0 and run.predicted >= 0.0
    assert np.max(run.progress) < blocked.min()
    assert PlanSource.STOP not in run.sources
    assert np.all(np.diff(run.values) <= 1e-6 * (1 + np.abs(run.values[:-1])))
    assert np.hypot(*(run.states[-1, :2] - run.states[-6, :2])) < 0.01  # standing


def test_the_jackal_reaches_the_target_in_the_papers_world_on_a_path_it_fits() -> None:
    path = sinusoid(1.5)  # over the box with 0.11 m to spare for the Jackal
    s = np.linspace(0.0, 1.0, 401)
    assert np.min(clearance(path.pose(s), [PAPER_BOX])) > 0.1
    mpc = PathReferenceMPC(Unicycle(), jackal_config(), obstacles=[PAPER_BOX], path=path)
    run = drive(mpc, path.start.copy(), 150, [PAPER_BOX], goal=path.goal)
    assert np.hypot(*(run.x[:2] - path.goal[:2])) < 0.01
    assert abs(run.x[2] - path.goal[2]) < 0.05
    assert run.true >= 0.0 and run.predicted >= 0.0
    assert np.max(run.states[:, 1]) > 1.2  # it went over the box
    assert PlanSource.STOP not in run.sources
    assert all(ok is not False for ok in run.lyapunov)


def test_changing_the_footprint_rebuilds_the_nlp() -> None:
    path = paper_sinusoid()
    mpc = PathReferenceMPC(Unicycle(),
                           MpcConfig(solving=SolverSettings(compile=False,
                                                            max_solve_time=NO_TIME_LIMIT)),
                           obstacles=[PAPER_BOX], path=path)
    mpc.solve(path.start)
    assert mpc.last_nlp.formulation.robot_faces == 0
    mpc.update_config(mpc.config.with_changes(footprint=[list(v) for v in JACKAL_VERTICES]))
    assert not mpc.nlps  # structural: rebuilt at the next solve
    sol = mpc.solve(path.start)
    assert mpc.last_nlp.formulation.robot_faces == 4
    assert sol.source is PlanSource.SOLVER
    # the same polygon again (as a tuple now) changes nothing: the plan is kept
    mpc.update_config(mpc.config.with_changes(footprint=JACKAL_VERTICES))
    assert mpc.nlps
    assert mpc.solve(path.start).lyapunov_ok is not None  # the plan's value was kept
    mpc.update_config(mpc.config.with_changes(footprint=()))
    assert mpc.solve(path.start).source is PlanSource.SOLVER
    assert mpc.last_nlp.formulation.robot_faces == 0
