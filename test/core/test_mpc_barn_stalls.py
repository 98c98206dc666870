# SPDX-License-Identifier: Apache-2.0
"""Recorded BARN states where the MPC failed at every step: it must drive from each now.

Each state (test/core/data/barn_standing_new_plans.json) is a laser-only BARN run at the
Jackal's limits, at the step where a new plan reached the robot and the MPC began to fail:
with the evaluation's budget of 100 solver iterations a step, the robot stood still there
until the run stalled (50 and more consecutive failures). The causes: fatrop from the
stand-still candidate (the quartic cost is flat there) spent every step's budget (world 23);
a second constraint-generation round was cut at every step because the first was solved
again each time (world 44); the same failing try came first at every step (world 55).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from recorded_states import perturbed, SEEDS

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.obstacles import ConvexPolygon

STATES = json.loads((Path(__file__).parent / 'data' / 'barn_standing_new_plans.json')
                    .read_text(encoding='utf-8'))
H = 0.2
# Steps (2 s) within which the robot must be driving on a solver solution; it stood still
# for 50 and more before.
WITHIN_STEPS = 10


def barn_controller() -> MpcController:
    """Return the evaluation's MPC on laser-only BARN as it was when these were recorded.

    Interpreted (compile=False): the compiled functions' numbers (test_backends), and no wait
    for gcc on a fresh machine.

    The Jackal at 2 m/s, 100 iterations a step, reversing allowed: the suite's Jackal now
    drives forwards only (Robot.reverses), which these states predate.
    """
    config = MpcConfig(footprint=tuple((float(x), float(y)) for x, y in JACKAL.vertices),
                       robot_radius=0.0,
                       solving=SolverSettings(budget='iterations', max_solve_iterations=100,
                                              compile=False))
    settings = ControllerSettings(xy_goal_tolerance=0.05, yaw_goal_tolerance=math.pi,
                                  capacity=128)
    return MpcController(Unicycle(v_max=2.0, omega_max=4.0), config, settings=settings)


def steps_until_tracking(controller: MpcController, x: np.ndarray
                         ) -> tuple[list[Reason], ControlOutput]:
    """Step the nominal closed loop from x until the MPC tracks, for WITHIN_STEPS at most."""
    model = controller.model.discrete(H)
    reasons = []
    for k in range(WITHIN_STEPS):
        output = controller.compute(x, None, k * H)
        reasons.append(output.reason)
        if output.reason is Reason.TRACKING:
            break
        x = np.asarray(model(x, output.u)).reshape(-1)
    return reasons, output

@pytest.mark.parametrize('seed', SEEDS)
@pytest.mark.parametrize('world', ['world_023', 'world_044', 'world_055'])
def test_a_new_plan_for_a_standing_robot_among_barn_cylinders_is_driven_within_2_s(
        world: str, seed: int) -> None:
    case = perturbed(STATES[world], seed)
    controller = barn_controller()
    controller.set_plan(np.array(case['plan']))
    controller.set_obstacles([ConvexPolygon.from_vertices(np.array(v))
                              for v in case['obstacles']])
    reasons, output = steps_until_tracking(controller, np.array(case['x']))
    assert reasons[-1] is Reason.TRACKING, reasons
    assert abs(output.u[0]) > 0.1  # it drives (forward or, to turn in a tight spot, back)


# Recorded with the suite's Jackal as it drives now: forwards only (Robot.reverses False).
FORWARD_ONLY = json.loads((Path(__file__).parent / 'data' / 'barn_forward_only.json')
                          .read_text(encoding='utf-8'))
# Steps (8 s) within which the robot must have left the waiting point; it stood there for the
# 20 s that end a run as stalled.
LEAVES_WITHIN_STEPS = 40


def forward_only_controller(case: dict) -> MpcController:
    """Return the evaluation's MPC for the Jackal driving forwards only, with case's plan."""
    config = MpcConfig(footprint=tuple((float(x), float(y)) for x, y in JACKAL.vertices),
                       robot_radius=0.0,
                       solving=SolverSettings(budget='iterations', max_solve_iterations=100,
                                              compile=False))
    settings = ControllerSettings(xy_goal_tolerance=0.05, yaw_goal_tolerance=math.pi,
                                  capacity=128)
    controller = MpcController(Unicycle(v_max=2.0, omega_max=4.0, v_min=0.0), config,
                               settings=settings)
    controller.set_plan(np.array(case['poses']))
    controller.set_obstacles([ConvexPolygon.from_vertices(np.array(v))
                              for v in case['obstacles']])
    return controller


@pytest.mark.parametrize('seed', SEEDS)
def test_a_plan_that_puts_off_its_motion_does_not_hold_the_robot_in_open_space(
        seed: int) -> None:
    """Laser-only BARN world 212 at 2 m/s: a re-plan for a robot standing in open space.

    The plan starts with a turn in place from the robot's heading, rounded into the first
    segment. The cold solve from rest converged to "turn part-way and wait" (s frozen at the
    rounded knot, the motion put off to the horizon's end); the warm starts of the following
    steps, from that plan's shifted candidate, put it off again at every step, and the robot
    stood 1.1 m from the nearest cylinder until the run stalled. A plan that neither drives
    now nor advances s counts as standing and gets the cold tries, which leave that point.
    """
    case = perturbed(FORWARD_ONLY['world_212'], seed)
    controller = forward_only_controller(case)
    model = controller.model.discrete(H)
    x = start = np.array(case['x'])
    for k in range(LEAVES_WITHIN_STEPS):
        output = controller.compute(x, None, k * H)
        x = np.asarray(model(x, output.u)).reshape(-1)
        if float(np.hypot(*(x[:2] - start[:2]))) > 1.0:
            break
    assert float(np.hypot(*(x[:2] - start[:2]))) > 1.0, (x, output.reason)


@pytest.mark.parametrize('seed', SEEDS)
def test_a_solve_longer_than_two_steps_goes_on_while_the_robot_stands(seed: int) -> None:
    """Laser-only BARN world 258 at 2 m/s: a re-plan for a robot standing among cylinders.

    IPOPT from the guided start needs about 245 iterations here, against 100 a step: cut at
    the first step, and again when it went on at the second, it counted as failed and began
    again from scratch every other step, and the robot stood until the run stalled. A cut
    solve now goes on until it has made MAX_CONTINUED_ITERATIONS.
    """
    case = perturbed(FORWARD_ONLY['world_258'], seed)
    controller = forward_only_controller(case)
    reasons, output = steps_until_tracking(controller, np.array(case['x']))
    assert reasons[-1] is Reason.TRACKING, reasons
    assert output.u[0] > 0.1


def test_a_new_plan_at_speed_starts_from_the_motion_in_hand() -> None:
    """Laser-only BARN world 213 at 2 m/s: a re-plan while driving at 1.5 m/s among cylinders.

    The recorded second before it (states, plans and sensed obstacles of each step) is
    replayed, then the loop is closed on the nominal model. From rest on the new plan, the
    guided start drove straight ahead at half speed, whatever the old plan was doing: no
    try was verified within the budget, step after step, and the robot stood until the run
    stalled. The guided start now rolls out the old plan's inputs: the MPC tracks the new
    plan within 2 s.
    """
    sequence = json.loads((Path(__file__).parent / 'data' / 'barn_213_replan_sequence.json')
                          .read_text(encoding='utf-8'))
    controller = forward_only_controller(sequence[0])
    poses = sequence[0]['poses']
    for step in sequence:
        if step['poses'] != poses:
            poses = step['poses']
            controller.set_plan(np.array(poses))  # the re-plan, at the last recorded step
        controller.set_obstacles([ConvexPolygon.from_vertices(np.array(v))
                                  for v in step['obstacles']])
        output = controller.compute(np.array(step['x']), None, step['t'])
    assert poses != sequence[0]['poses']  # the sequence ends with the re-plan
    model = controller.model.discrete(H)
    x = np.asarray(model(np.array(sequence[-1]['x']), output.u)).reshape(-1)
    reasons, output = steps_until_tracking(controller, x)
    assert reasons[-1] is Reason.TRACKING, reasons
    assert np.max(np.abs(output.u)) > 0.1


# NLPs the evaluation prepares: up to this many obstacles (sensing_suites.PREPARED_SLOTS).
PREPARED_SLOTS = 10


def prepared_controller(case: dict) -> MpcController:
    """Return the forward-only MPC with the evaluation's NLPs built, on case's plan.

    case's obstacles are polygons as A p <= b with their vertices (as the run held them).
    """
    controller = forward_only_controller({'poses': case['poses'], 'obstacles': []})
    controller.mpc.prepare(PREPARED_SLOTS)
    controller.set_obstacles([ConvexPolygon(A=np.array(o['A']), b=np.array(o['b']),
                                            vertices=np.array(o['vertices']))
                              for o in case['obstacles']])
    return controller


@pytest.mark.parametrize('seed', SEEDS)
def test_a_cut_round_in_the_largest_nlp_goes_on_until_it_is_solved(seed: int) -> None:
    """Laser-only BARN world 283 at 2 m/s: a robot standing beside a row of cylinders.

    From rest the first constraint-generation round (4 obstacles) solves, the second asks for
    12 and the largest prepared NLP (10 slots, faces enough for all 12) holds 10: cut. The
    next step resumed that round with the 10 it held but picked its NLP anew, by their faces
    (10 slots, 4 faces): not the NLP of the cut try, which started over and was cut; the
    step after went on with that one, solved it, and made a round that held the same 10
    again in the other NLP (the missed obstacles did not fit): cut, and so on, step after
    step, until the run stalled. A resumed round now runs in the NLP its cut try ran in, and
    a round that would hold the same obstacles again is not made.
    """
    case = perturbed(json.loads((Path(__file__).parent / 'data' / 'barn_283_capped_round.json')
                                .read_text(encoding='utf-8')), seed)
    reasons, output = steps_until_tracking(prepared_controller(case), np.array(case['x']))
    assert reasons[-1] is Reason.TRACKING, reasons
    assert output.u[0] > 0.1


@pytest.mark.parametrize('seed', SEEDS)
def test_a_round_beyond_the_largest_nlp_holds_what_its_solution_would_hit(seed: int) -> None:
    """Laser-only BARN world 212 at 2 m/s: a re-plan among cylinders, the robot at a stand.

    The second constraint-generation round asks for more obstacles than the largest
    prepared NLP holds (10). It held the nearest to the candidate and left out those the
    first round's solution came near, and every try solved it to the same plan, which hit
    one of those: the robot stood until the run stalled. A round now holds first what the
    last solution comes nearest, and a try whose solution hits an obstacle left out goes
    last while the robot stands.
    """
    case = perturbed(json.loads((Path(__file__).parent / 'data' / 'barn_212_full_nlp.json')
                                .read_text(encoding='utf-8')), seed)
    reasons, output = steps_until_tracking(prepared_controller(case), np.array(case['x']))
    assert reasons[-1] is Reason.TRACKING, reasons
    assert np.max(np.abs(output.u)) > 0.1
