# SPDX-License-Identifier: Apache-2.0
"""Problem (6) as written in formulation.py: cost (5), terminal condition, Farkas rows."""

from __future__ import annotations

import dataclasses
import hashlib

import casadi as ca
import numpy as np
import pytest

from mpc_local_planner.core.baselines.tracking_mpc import target_terminal
from mpc_local_planner.core.config import CostWeights, MpcConfig
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.moving_obstacles import MOTION_SIZE, MovingPolygon
from mpc_local_planner.core.mpc.formulation import (
    disc_collision_rows,
    formulate,
    Formulation,
    gap_closing_rows,
    initial_state_rows,
    obstacle_halfplanes,
    path_terminal,
    polygon_collision_rows,
    rate_rows,
    Row,
    stage_cost,
    stage_offsets,
    symbolic_weights,
    terminal_rows,
    TerminalCondition,
    variable_bounds,
)
from mpc_local_planner.core.mpc.nlp_values import (
    feasible_multipliers,
    obstacle_parameters,
    parameter_vector,
)
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import paper_sinusoid, WaypointPath

BOX = ConvexPolygon.from_box(1.0, -1.0, 1.5, 1.0)
SLOT = 3 * 4 + MOTION_SIZE  # an obstacle slot of 4 faces: A, b, then its motion


def test_cost_weights_are_named_in_the_order_the_solver_reads_them() -> None:
    weights = MpcConfig(weight_position=2.0, weight_heading=0.3, weight_v=4.0,
                        weight_omega=5.0, offset_weight=600.0).cost_weights()
    assert weights == CostWeights(position=2.0, heading=0.3, v=4.0, omega=5.0, offset=600.0)
    assert weights.as_vector() == [2.0, 0.3, 4.0, 5.0, 600.0]


def test_stage_cost_is_the_papers_quartic_with_named_weights() -> None:
    weights = CostWeights(position=2.0, heading=0.5, v=3.0, omega=7.0, offset=1.0)
    x, x_s, u = np.array([1.0, -2.0, 0.5]), np.array([0.5, -1.0, 0.0]), np.array([0.2, -0.4])
    value = float(stage_cost(Unicycle(), 4)(x, u, x_s, weights.as_vector()))
    dx = x - x_s
    expected = 2.0 * (dx[0] ** 4 + dx[1] ** 4) + 0.5 * dx[2] ** 4 + 3.0 * 0.2 ** 4 + 7.0 * 0.4 ** 4
    assert value == pytest.approx(expected, rel=1e-12)


def test_a_plan_ending_on_the_path_at_rest_is_feasible_and_costs_the_offset() -> None:
    model, path, config = Unicycle(), paper_sinusoid(), MpcConfig(horizon=3)
    form = formulate(model, config, path_terminal(model, path), slots=1, faces=4)
    s = 0.3
    pose = path.pose(s)
    x = np.tile(pose, (config.horizon + 1, 1))  # at rest on the path: x_l = g_p(s)
    u = np.zeros((config.horizon, model.nu))
    mu = feasible_multipliers(x, [BOX], form.slots, form.faces)
    w = form.pack(x, np.array([s]), u, mu)
    params = parameter_vector(pose, config.cost_weights(),
                              obstacle_parameters([BOX], form.slots, form.faces),
                              path.parameters())
    g = np.asarray(form.g_fn(w, params)).reshape(-1)
    assert np.all(g >= form.lbg - 1e-9) and np.all(g <= form.ubg + 1e-9)
    assert np.all(w >= form.lbw) and np.all(w <= form.ubw)
    # no stage cost at the steady state: J_N = offset_weight (1 - s)^2
    assert float(form.cost_fn(w, params)) == pytest.approx(1000.0 * (1 - s) ** 2)


def test_a_position_inside_an_obstacle_violates_its_farkas_row() -> None:
    model, path, config = Unicycle(), paper_sinusoid(), MpcConfig(horizon=2)
    form = formulate(model, config, path_terminal(model, path), slots=1, faces=4)
    x = np.array([[0.0, 0.0, 0.0], [1.25, 0.0, 0.0], [1.25, 0.0, 0.0]])
    mu = feasible_multipliers(x, [BOX], form.slots, form.faces)
    w = form.pack(x, np.array([0.5]), np.zeros((2, 2)), mu)
    params = parameter_vector(x[0], config.cost_weights(),
                              obstacle_parameters([BOX], form.slots, form.faces),
                              path.parameters())
    g = np.asarray(form.g_fn(w, params)).reshape(-1)
    assert np.any(g < form.lbg - 1e-3)


def test_the_stage_sizes_match_the_variables_and_constraints() -> None:
    model, path, config = Unicycle(), paper_sinusoid(), MpcConfig(horizon=4)
    form = formulate(model, config, path_terminal(model, path), slots=2, faces=4)
    structure = form.structure
    nw = sum(structure['nx']) + sum(structure['nu'])
    layout = form.layout
    assert nw == form.lbw.shape[0] == (layout.x.size + layout.r.size + layout.u.size
                                       + layout.mu.size)
    dynamics_rows = config.horizon * (model.nx + 1)
    assert sum(structure['ng']) + dynamics_rows == form.lbg.shape[0]


def test_a_waypoint_path_is_evaluated_once_its_steady_state_carried_along_the_horizon() -> None:
    model, config = Unicycle(), MpcConfig(horizon=4)
    path = WaypointPath(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]), capacity=16)
    form = formulate(model, config, path_terminal(model, path), slots=1, faces=4)
    layout, structure = form.layout, form.structure
    assert layout.xs.shape == (config.horizon + 1, model.nx)
    assert sum(structure['nx']) + sum(structure['nu']) == form.lbw.shape[0] == (
        layout.x.size + layout.r.size + layout.xs.size + layout.u.size + layout.mu.size)
    # a plan at rest on the path is feasible, with the carried x_s = g_p(s) at every stage
    s = 0.4
    x = np.tile(path.pose(s), (config.horizon + 1, 1))
    mu = feasible_multipliers(x, [BOX], form.slots, form.faces)
    w = form.pack(x, np.array([s]), np.zeros((config.horizon, model.nu)), mu,
                  steady=path.pose(s))
    params = parameter_vector(x[0], config.cost_weights(),
                              obstacle_parameters([BOX], form.slots, form.faces),
                              path.parameters())
    g = np.asarray(form.g_fn(w, params)).reshape(-1)
    assert np.all(g >= form.lbg - 1e-9) and np.all(g <= form.ubg + 1e-9)
    assert float(form.cost_fn(w, params)) == pytest.approx(1000.0 * (1 - s) ** 2)
    # a wrong copy of x_s violates the terminal stage's rows
    w[layout.xs] += 0.1
    g = np.asarray(form.g_fn(w, params)).reshape(-1)
    assert np.any(np.abs(g - np.clip(g, form.lbg, form.ubg)) > 0.05)
    # the path appears once in the NLP, not in every stage cost
    terminal = path_terminal(model, path)
    copied = formulate(model, config, dataclasses.replace(terminal, carried=False), slots=1,
                       faces=4)
    assert form.g_fn.n_instructions() + form.cost_fn.n_instructions() < (
        copied.g_fn.n_instructions() + copied.cost_fn.n_instructions()) / 2
    with pytest.raises(ValueError, match='steady state'):
        form.pack(x, np.array([s]), np.zeros((config.horizon, model.nu)), mu)


# ----------------------------------------------------------------------------- row families
def _values(rows: list[Row], symbols: list[ca.SX], values: list[np.ndarray]
            ) -> list[tuple[np.ndarray, float, float]]:
    """Evaluate each row's expression at the given values of its symbols."""
    out = []
    for row in rows:
        fn = ca.Function('row', symbols, [ca.vec(row.expr)])
        out.append((np.asarray(fn(*values), dtype=float).reshape(-1), row.lower, row.upper))
    return out


def test_the_gap_closing_rows_hold_for_the_next_stage_the_dynamics_give() -> None:
    z, x_next, r, carried = (ca.SX.sym('z', 5), ca.SX.sym('x', 3), ca.SX.sym('r', 1),
                             ca.SX.sym('c', 1))
    (row,) = gap_closing_rows(z, x_next, r, [carried])
    assert (row.lower, row.upper) == (0.0, 0.0)
    good = np.array([1.0, 2.0, 0.5, 0.3, 0.7])
    ((value, _, _),) = _values([row], [z, x_next, r, carried],
                               [good, good[:3], good[3:4], good[4:]])
    np.testing.assert_array_equal(value, np.zeros(5))


def test_the_rate_rows_bound_each_input_change_and_rest_at_the_end() -> None:
    q, u, u_prev = ca.SX.sym('q', 2), ca.SX.sym('u', 2), ca.SX.sym('p', 2)
    rate = np.array([0.1, 0.4])
    first = rate_rows(0, 3, q, u, u_prev, rate, first_order=False)
    assert [(r.lower, r.upper) for r in first] == [(0.0, 0.0), (-0.1, 0.1), (-0.4, 0.4)]
    values = _values(first, [q, u, u_prev], [np.array([0.2, 0.0]), np.array([0.25, 0.3]),
                                             np.array([0.2, 0.0])])
    np.testing.assert_allclose([v for v, _, _ in values[1:]], [[0.05], [0.3]])
    middle = rate_rows(1, 3, q, u, u_prev, rate, first_order=False)
    assert len(middle) == 2  # q_1 is fixed by the gap-closing rows, not here
    last = rate_rows(3, 3, q, None, u_prev, rate, first_order=False)
    assert [(r.lower, r.upper) for r in last] == [(-0.1, 0.1), (-0.4, 0.4)]
    ramp_end = rate_rows(3, 3, q, None, u_prev, rate, first_order=True)
    assert [(r.lower, r.upper) for r in ramp_end] == [(0.0, 0.0), (0.0, 0.0)]


def test_the_initial_state_row_fixes_x0_to_the_measured_state() -> None:
    x0, xk = ca.SX.sym('x0', 3), ca.SX.sym('xk', 3)
    ((value, lower, upper),) = _values(initial_state_rows(x0, xk), [x0, xk],
                                       [np.array([1.0, 2.0, 3.0]), np.array([1.0, 2.5, 3.0])])
    np.testing.assert_array_equal(value, [0.0, -0.5, 0.0])
    assert (lower, upper) == (0.0, 0.0)


def test_the_obstacle_parameter_splits_into_each_slots_half_planes_and_motion() -> None:
    other = MovingPolygon.moving(ConvexPolygon.from_box(3.0, 3.0, 4.0, 5.0), [0.5, -1.0], 0.2)
    obs = ca.SX.sym('obs', SLOT * 2)
    A_list, b_list, motion_list = obstacle_halfplanes(obs, 2, 4)
    fn = ca.Function('ab', [obs], [*A_list, *b_list, *motion_list])
    A0, A1, b0, b1, m0, m1 = (np.asarray(v) for v in fn(
        obstacle_parameters([BOX, other], 2, 4)))
    np.testing.assert_array_equal(A0, BOX.A)
    np.testing.assert_array_equal(b0.reshape(-1), BOX.b)
    np.testing.assert_array_equal(A1, other.A)
    np.testing.assert_array_equal(b1.reshape(-1), other.b)
    np.testing.assert_array_equal(m0.reshape(-1), [0.0, 0.0, 0.0, 0.0])  # static
    np.testing.assert_array_equal(m1.reshape(-1), [0.5, -1.0, 0.2, np.hypot(0.5, 1.0)])


def test_a_stage_holds_a_moving_obstacle_where_it_is_then_and_a_static_one_to_the_bit() -> None:
    walker = MovingPolygon.moving(ConvexPolygon.from_box(3.0, 3.0, 4.0, 5.0), [0.5, -1.0], 0.2)
    obs = ca.SX.sym('obs', SLOT * 2)
    A_list, b_list, motion_list = obstacle_halfplanes(obs, 2, 4)
    t, half_step = 1.2, 0.1
    fn = ca.Function('b', [obs], [stage_offsets(A, b, m, t, half_step)
                                  for A, b, m in zip(A_list, b_list, motion_list, strict=True)])
    static_b, moving_b = (np.asarray(v).reshape(-1)
                          for v in fn(obstacle_parameters([BOX, walker], 2, 4)))
    np.testing.assert_array_equal(static_b, BOX.b)
    # the polygon the geometric checks build: moved by t v, grown by t growth + h/2 (|v| + g)
    expected = walker.at(t, half_step * (walker.speed + walker.growth))
    np.testing.assert_allclose(moving_b, expected.b, rtol=0, atol=1e-12)
    np.testing.assert_allclose(expected.vertices.mean(axis=0), [3.5 + 0.6, 4.0 - 1.2])


def test_the_disc_rows_are_farkas_with_multipliers_on_the_simplex() -> None:
    p, mu = ca.SX.sym('p', 2), ca.SX.sym('mu', 4)
    obs = ca.SX.sym('obs', SLOT)
    A_list, b_list, _ = obstacle_halfplanes(obs, 1, 4)
    rows = disc_collision_rows(p, mu, A_list, b_list, 4, 0.01)
    assert [(r.lower, r.upper) for r in rows] == [(0.01, ca.inf), (1.0, 1.0)]
    params = obstacle_parameters([BOX], 1, 4)
    outside = np.array([0.5, 0.0])  # left of the box: its face x >= 1.0 separates
    face = int(np.argmax(BOX.A @ outside - BOX.b))
    on_face = np.eye(4)[face]
    (separation, _, _), (total, _, _) = _values(rows, [p, mu, obs], [outside, on_face, params])
    assert separation[0] == pytest.approx(0.5) and total[0] == 1.0
    inside = np.array([1.25, 0.0])
    for k in range(4):  # no multiplier on the simplex separates a point inside
        (separation, _, _), _ = _values(rows, [p, mu, obs], [inside, np.eye(4)[k], params])
        assert separation[0] < 0.01


def test_the_polygon_rows_of_an_empty_slot_hold_and_count_each_sweep() -> None:
    body = JACKAL.body
    G, g_body = ca.DM(body.A), ca.DM(body.b)
    x, m = ca.SX.sym('x', 3), ca.SX.sym('m', 4 + body.num_faces)
    obs = ca.SX.sym('obs', SLOT)
    A_list, b_list, _ = obstacle_halfplanes(obs, 1, 4)
    sweeps = [ca.SX(0.02), ca.SX(0.03)]
    rows = polygon_collision_rows(x, 2, m, A_list, b_list, 4, G, g_body, 0.01, sweeps)
    assert [(r.lower, r.upper) for r in rows] == [(0.01, ca.inf), (0.01, ca.inf),
                                                  (0.0, 0.0), (-ca.inf, 1.0)]
    # an empty slot (A = 0, b = -1) holds with lambda_0 = margin + sweep and mu = 0
    multipliers = np.zeros(4 + body.num_faces)
    multipliers[0] = 0.01 + 0.03
    values = _values(rows, [x, m, obs], [np.array([1.0, 2.0, 0.3]), multipliers,
                                         obstacle_parameters([], 1, 4)])
    for value, lower, upper in values:
        assert np.all(value >= lower - 1e-12) and np.all(value <= upper + 1e-12)


def test_the_terminal_rows_end_on_the_path_and_evaluate_a_carried_steady_state_once() -> None:
    model = Unicycle()
    terminal = path_terminal(model, FINGERPRINT_WAYPOINTS)
    x_n, x_s, r = ca.SX.sym('xn', 3), ca.SX.sym('xs', 3), ca.SX.sym('r', 1)
    params = ca.SX.sym('path', terminal.num_params)
    weights = symbolic_weights(ca.SX.sym('w', len(CostWeights._fields)))
    rows, offset = terminal_rows(terminal, x_n, x_s, r, params, weights, carried=True)
    assert len(rows) == 2 and all((row.lower, row.upper) == (0.0, 0.0) for row in rows)
    not_carried, _ = terminal_rows(terminal, x_n, x_s, r, params, weights, carried=False)
    assert len(not_carried) == 1
    pose = FINGERPRINT_WAYPOINTS.pose(0.4)
    values = _values(rows, [x_n, x_s, r, params],
                     [pose, pose, np.array([0.4]), FINGERPRINT_WAYPOINTS.parameters()])
    assert all(np.allclose(value, 0.0, atol=1e-12) for value, _, _ in values)
    fn = ca.Function('offset', [r], [offset])
    assert float(fn(0.4)) == pytest.approx(0.36)


def test_the_variable_bounds_are_the_models_the_terminal_range_and_nonnegative_multipliers(
        ) -> None:
    model = Unicycle(v_max=0.5, omega_max=1.0)
    config = MpcConfig(horizon=3)
    form = formulate(model, config, path_terminal(model, paper_sinusoid()), 1, 4)
    layout = form.layout
    lbw, ubw = variable_bounds(model, path_terminal(model, paper_sinusoid()), layout, 3,
                               form.lbw.size)
    np.testing.assert_array_equal(lbw[layout.u], np.tile([-0.5, -1.0], (3, 1)))
    np.testing.assert_array_equal(ubw[layout.u], np.tile([0.5, 1.0], (3, 1)))
    assert np.all(lbw[layout.r] == 0.0) and np.all(ubw[layout.r] == 1.0)
    assert np.all(lbw[layout.mu] == 0.0) and np.all(ubw[layout.mu] == np.inf)
    np.testing.assert_array_equal(lbw, form.lbw)
    np.testing.assert_array_equal(ubw, form.ubw)


# ----------------------------------------------------------------------------- fingerprint
JACKAL_VERTICES = tuple((float(x), float(y)) for x, y in JACKAL.vertices)
FINGERPRINT_WAYPOINTS = WaypointPath(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]),
                                     capacity=5)
# The symbolic problem of each variant as written when these were recorded: the C code of
# (w, p) -> (J_N, g) (every expression, the constraints in their order), the bounds of w and
# g, the stage structure and the layout of w. A restructuring of formulate keeps all of it.
# Re-recorded when each obstacle slot gained its motion (core/moving_obstacles.py): the
# numbers of a static problem are those before (test_mpc_first_order_hold's zero-hold probes,
# with the motion zero).
FINGERPRINTS = {
    'circle': 'b3a137c3dd35cec7',
    'polygon_waypoints': '73dde9f6a0730145',
    'circle_rates': '1e10cf78dcd89d0e',
    'circle_first_order': 'a081ee8a3c82902f',
    'polygon_first_order': 'c885ef50d81ccd56',
    'tracking': 'b08a47ce84c1ee6b',
    'one_step': '708ba28a7bc08ab7',
}


def _fingerprint_case(name: str) -> tuple[MpcConfig, TerminalCondition, int, int]:
    model, rates = Unicycle(), (0.5, 2.0)
    sinusoid = path_terminal(model, paper_sinusoid())
    waypoints = path_terminal(model, FINGERPRINT_WAYPOINTS)
    return {
        'circle': (MpcConfig(horizon=4), sinusoid, 2, 4),
        'polygon_waypoints': (MpcConfig(horizon=4, footprint=JACKAL_VERTICES), waypoints, 2, 4),
        'circle_rates': (MpcConfig(horizon=4, max_accel=rates), waypoints, 1, 4),
        'circle_first_order': (MpcConfig(horizon=4, max_accel=rates, input_hold='first_order'),
                               sinusoid, 1, 4),
        'polygon_first_order': (MpcConfig(horizon=3, footprint=JACKAL_VERTICES,
                                          max_accel=rates, input_hold='first_order'),
                                waypoints, 2, 4),
        'tracking': (MpcConfig(horizon=4), target_terminal(model), 1, 4),
        'one_step': (MpcConfig(horizon=1), sinusoid, 1, 4),
    }[name]


def fingerprint(form: Formulation) -> str:
    """Return a digest of the symbolic problem, its bounds, structure and layout."""
    problem = form.problem
    generator = ca.CodeGenerator('fingerprint.c', {'with_header': False})
    generator.add(ca.Function('nlp', [problem['x'], problem['p']],
                              [problem['f'], problem['g']]))
    digest = hashlib.sha256(generator.dump().encode())
    for array in (form.lbw, form.ubw, form.lbg, form.ubg):
        digest.update(np.ascontiguousarray(array, dtype=float).tobytes())
    digest.update(repr(form.structure).encode())
    for part in form.layout:
        digest.update(np.ascontiguousarray(part, dtype=np.int64).tobytes())
    return digest.hexdigest()[:16]


@pytest.mark.parametrize('name', sorted(FINGERPRINTS))
def test_the_formulation_fingerprint_holds(name: str) -> None:
    config, terminal, slots, faces = _fingerprint_case(name)
    assert fingerprint(formulate(Unicycle(), config, terminal, slots, faces)) == \
        FINGERPRINTS[name]
