# SPDX-License-Identifier: Apache-2.0
"""Recorded states of a real base with bounded input rates: the MPC must solve them in a step.

test/core/data/barn_real_replan_at_speed.json: laser-only BARN at 2 m/s on the `real` base,
at the step where a re-plan reached the robot at speed (1.5 m/s). With max_accel the robot
cannot stop at once; the stand-still candidate's first constraint-generation round held no
obstacle near it, and its rounds overran the step's 100 iterations. The robot braked off
the new path and stood until the run stalled. The first round now also holds the obstacles
near the motion in hand (the old plan's inputs, within the rate bounds).

test/core/data/barn_real_standing_off_heading.json: laser-only BARN world 62 at 2 m/s on the
`real` base with the first-order hold, the robot standing (it braked along its last plan) on
the start of a feasible path whose first segment leaves 1.6 rad off its heading. Every step's
cold try started from the guided start, which drove straight ahead at half speed: 1.4 m off
the path, among ten obstacles the plan never passes, and back to the path's start in one
jump. IPOPT from it declared the NLP infeasible or ran out of the 100 iterations at every
step, and the run stalled. The guided start of a first-order hold now follows the path.
World 55 (recorded with that start): the robot standing on the start of a path that leads
past two cylinders; the first round held only the obstacle beside the standing candidate,
its solution came near the others, and the rounds that added them ran out of every step's
budget. The first round now also holds the obstacles near the guided start's motion.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from recorded_states import perturbed, SEEDS

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import PathReferenceMPC, PlanSource
from mpc_local_planner.core.mpc.nlp_values import rate_limited_inputs
from mpc_local_planner.core.mpc.tries import Start
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import WaypointPath

STATES = json.loads((Path(__file__).parent / 'data' / 'barn_real_replan_at_speed.json')
                    .read_text(encoding='utf-8'))


@pytest.mark.parametrize('seed', SEEDS)
@pytest.mark.parametrize('world', ['world_024', 'world_066'])
def test_a_re_plan_at_speed_with_bounded_input_rates_is_solved_within_a_step(
        world: str, seed: int) -> None:
    case = perturbed(STATES[world], seed)
    config = MpcConfig(footprint=tuple((float(x), float(y)) for x, y in JACKAL.vertices),
                       robot_radius=0.0, collision_margin=0.03, max_accel=(4.0, 12.0),
                       # interpreted: the compiled functions' numbers, without gcc's wait
                       solving=SolverSettings(budget='iterations', max_solve_iterations=100,
                                              compile=False))
    path = WaypointPath(np.array(case['waypoints']), start_heading=case['start_heading'],
                        goal_heading=case['goal_heading'], turn_length=case['turn_length'],
                        capacity=case['capacity'])
    mpc = PathReferenceMPC(Unicycle(v_max=2.0, omega_max=4.0, v_min=0.0), config,
                           obstacles=[ConvexPolygon.from_vertices(np.array(v))
                                      for v in case['obstacles']], path=path)
    # set_path keeps the inputs of the last plan on the old path (the motion in hand)
    mpc.set_path(path, carried_inputs=np.array(case['carried']))
    solution = mpc.solve(np.array(case['x']), previous_input=np.array(case['u_before']))
    assert solution.source is PlanSource.SOLVER, solution.status
    rate = np.array(config.max_accel) * config.step
    changes = np.diff(np.vstack([case['u_before'], solution.u_pred, np.zeros(2)]), axis=0)
    assert np.all(np.abs(changes) <= rate + 1e-6)


def test_rate_limited_inputs_start_from_the_input_before_and_end_at_rest() -> None:
    rate = np.array([0.4, 1.2])
    u = rate_limited_inputs(np.tile([1.0, 0.0], (10, 1)), np.zeros(2), rate)
    changes = np.diff(np.vstack([np.zeros(2), u, np.zeros(2)]), axis=0)
    assert np.all(np.abs(changes) <= rate + 1e-12)
    assert u[:, 0].max() == pytest.approx(1.0)  # it still drives where it can
    # from speed: it brakes within the bounds
    u = rate_limited_inputs(np.zeros((10, 2)), np.array([1.6, -1.0]), rate)
    changes = np.diff(np.vstack([[1.6, -1.0], u, np.zeros(2)]), axis=0)
    assert np.all(np.abs(changes) <= rate + 1e-12)


STANDING = json.loads((Path(__file__).parent / 'data' / 'barn_real_standing_off_heading.json')
                      .read_text(encoding='utf-8'))


def _standing_mpc(case: dict) -> PathReferenceMPC:
    """Return the real-base suite's MPC (first-order hold at the base's limits) on case."""
    config = MpcConfig(footprint=tuple((float(x), float(y)) for x, y in JACKAL.vertices),
                       robot_radius=0.0, collision_margin=0.03, max_accel=(2.0, 6.0),
                       input_hold='first_order',
                       solving=SolverSettings(budget='iterations', max_solve_iterations=100,
                                              compile=False))
    path = WaypointPath(np.array(case['waypoints']), start_heading=case['start_heading'],
                        goal_heading=case['goal_heading'], turn_length=case['turn_length'],
                        capacity=case['capacity'])
    return PathReferenceMPC(Unicycle(v_max=2.0, omega_max=4.0, v_min=0.0), config,
                            obstacles=[ConvexPolygon.from_vertices(np.array(v))
                                       for v in case['obstacles']], path=path)


@pytest.mark.parametrize('seed', SEEDS)
@pytest.mark.parametrize('world', ['world_055', 'world_062', 'world_062_later'])
def test_a_standing_robot_off_the_paths_heading_is_solved_from_rest_within_a_step(
        world: str, seed: int) -> None:
    case = perturbed(STANDING[world], seed)
    mpc = _standing_mpc(case)
    solution = mpc.solve(np.array(case['x']), previous_input=np.array(case['u_before']))
    assert solution.source is PlanSource.SOLVER, solution.status
    assert solution.iterations <= 100


def test_the_path_following_start_turns_towards_the_path_within_the_rate_bounds() -> None:
    case = STANDING['world_062']
    mpc = _standing_mpc(case)
    config = mpc.config
    rate = np.array(config.max_accel) * config.step
    # the guided start of a robot at rest without carried inputs (path_following_inputs)
    problem = mpc.solver_problem(np.array(case['x']), start=Start.GUIDED)
    u = problem.w0[problem.nlp.formulation.layout.u]
    changes = np.diff(np.vstack([np.zeros(2), u]), axis=0)
    assert np.all(np.abs(changes) <= rate + 1e-12)
    # the path's first segment leaves about 1.6 rad clockwise of the robot's heading: it
    # turns that way first, and drives only once it faces the path
    assert u[0, 1] < 0.0 and u[0, 0] == 0.0
    assert u[:, 0].max() > 0.1
