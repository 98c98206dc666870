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
from mpc_local_planner.core.mpc.formulation import (
    formulate,
    Formulation,
    path_terminal,
    stage_cost,
    TerminalCondition,
)
from mpc_local_planner.core.mpc.nlp_values import (
    feasible_multipliers,
    obstacle_parameters,
    parameter_vector,
)
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import paper_sinusoid, WaypointPath

BOX = ConvexPolygon.from_box(1.0, -1.0, 1.5, 1.0)


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


# ----------------------------------------------------------------------------- fingerprint
JACKAL_VERTICES = tuple((float(x), float(y)) for x, y in JACKAL.vertices)
FINGERPRINT_WAYPOINTS = WaypointPath(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]),
                                     capacity=5)
# The symbolic problem of each variant as written when these were recorded: the C code of
# (w, p) -> (J_N, g) (every expression, the constraints in their order), the bounds of w and
# g, the stage structure and the layout of w. A restructuring of formulate keeps all of it.
FINGERPRINTS = {
    'circle': '9234f294f1c696c8',
    'polygon_waypoints': '197d217082793513',
    'circle_rates': '28cb313050c6229b',
    'circle_first_order': '6ced69ef7796e55a',
    'polygon_first_order': '1e2a7547dd96cf21',
    'tracking': '072abfdde1c4555c',
    'one_step': '5d8f05404d943918',
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
