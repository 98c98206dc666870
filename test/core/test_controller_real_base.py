# SPDX-License-Identifier: Apache-2.0
"""MpcController on a real base: the control rate, braking stops, bounded input rates.

The closed loops run on sim/base.py's Base (lag, latency, acceleration limits, odometry
noise), the model the simulator node and the suites' rollout share.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.input_freshness import InputFreshness
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.evaluation.rollout import rollout, StopRule
from mpc_local_planner.sim.base import Base
from mpc_local_planner.sim.reality import Reality
from mpc_local_planner.worlds.world import paper_world

WORLD = paper_world()
MODEL = Unicycle()  # the paper's Turtlebot: 0.31 m/s, 1.9 rad/s
CONFIG = MpcConfig(solving=SolverSettings(max_solve_time=3600.0))
PLAN = np.array([[0.0, 0.0, WORLD.start[2]], [0.8, 1.3, 0.0], [1.7, 1.3, -0.96],
                 [2.5, 0.0, WORLD.goal[2]]])
PERIOD = 0.05  # 20 Hz


def _control(controller: MpcController, pose: np.ndarray, now: float,
             **inputs: object) -> ControlOutput:
    """Step as the controller node does: the inputs' ages are checked before compute."""
    refused = InputFreshness.of(controller.settings).check(now, **inputs)
    if refused is None:
        return controller.compute(pose, None, now)
    return controller.refuse_inputs(refused, now)


def _controller(config: MpcConfig = CONFIG, **settings) -> MpcController:
    controller = MpcController(MODEL, config, obstacles=WORLD.obstacles,
                               settings=ControllerSettings(**settings))
    controller.set_plan(PLAN)
    return controller


def test_at_20_hz_the_mpc_solves_once_a_step_and_the_calls_between_apply_its_plan():
    controller = _controller(control_frequency=20.0)
    x = np.array(WORLD.start, dtype=float)
    outputs = []
    for k in range(40):  # 2 s
        out = controller.compute(x, None, k * PERIOD)
        outputs.append(out)
        x = MODEL.step(x, out.u, PERIOD)
    fresh = [k for k, out in enumerate(outputs) if out.fresh]
    assert fresh == list(range(0, 40, 4))  # every h = 0.2 s
    for k, out in enumerate(outputs):
        solved = outputs[4 * (k // 4)]
        assert out.reason is solved.reason
        np.testing.assert_array_equal(out.u, solved.u)  # the plan's input over its step


def test_a_timer_that_fires_early_still_solves_at_the_step():
    controller = _controller(control_frequency=20.0)
    x = np.array(WORLD.start, dtype=float)
    times = [0.0, 0.049, 0.101, 0.148, 0.199, 0.251]
    fresh = [controller.compute(x, None, t).fresh for t in times]
    assert fresh == [True, False, False, False, True, False]


def test_a_stop_of_a_moving_robot_brakes_along_the_plan_within_max_decel():
    decel = (0.5, 2.0)
    controller = _controller(control_frequency=20.0, max_decel=decel, odom_timeout=0.3)
    x = np.array(WORLD.start, dtype=float)
    t = 0.0
    for k in range(40):  # get going
        t = k * PERIOD
        out = _control(controller, x, t, pose_time=t)
        x = MODEL.step(x, out.u, PERIOD)
    assert out.reason is Reason.TRACKING and out.u[0] > 0.2
    last = out.u
    braking = []
    for k in range(1, 40):  # odometry stops coming at t
        out = _control(controller, x, t + k * PERIOD, pose_time=t)
        if out.reason is Reason.STALE_ODOM:
            braking.append(out.u)
    braking = np.array(braking)
    assert np.all(braking[-1] == 0.0)
    assert braking[0, 0] > 0.0  # not zero at once
    speeds = np.vstack([last, braking])
    assert np.all(np.diff(np.abs(speeds[:, 0])) <= decel[0] * PERIOD + 0.02)  # + the plan's


def test_without_max_decel_a_stop_is_zero_at_once():
    controller = _controller(control_frequency=20.0, odom_timeout=0.3)
    x = np.array(WORLD.start, dtype=float)
    for k in range(20):
        out = _control(controller, x, k * PERIOD, pose_time=k * PERIOD)
        x = MODEL.step(x, out.u, PERIOD)
    out = _control(controller, x, 2.0, pose_time=0.95)
    assert out.reason is Reason.STALE_ODOM
    np.testing.assert_array_equal(out.u, [0.0, 0.0])


def test_with_max_accel_the_commands_change_within_the_bounds_and_the_robot_arrives():
    accel = (0.5, 3.0)
    controller = _controller(CONFIG.with_changes(max_accel=accel), control_frequency=5.0)
    x = np.array(WORLD.start, dtype=float)
    commands = []
    for k in range(150):
        out = controller.compute(x, None, k * 0.2)
        commands.append(out.u)
        if out.reason is Reason.GOAL_REACHED:
            break
        x = MODEL.step(x, out.u, 0.2)
    assert out.reason is Reason.GOAL_REACHED
    changes = np.abs(np.diff(np.vstack([np.zeros(2), commands]), axis=0))
    bound = np.array(accel) * 0.2 + 1e-6
    # the MPC's inputs (not the final in-place turn to the heading) respect the bounds
    turn = next((k for k in range(len(commands)) if commands[k][0] == 0.0 and k > 5),
                len(commands))
    assert turn > 20  # the MPC drove most of the way
    assert np.all(changes[:turn] <= bound)
    # and without the bounds the same loop jumps by more: the bound is what held them
    free = _controller(control_frequency=5.0)
    x = np.array(WORLD.start, dtype=float)
    jumps = []
    for k in range(30):
        out = free.compute(x, None, k * 0.2)
        jumps.append(out.u)
        x = MODEL.step(x, out.u, 0.2)
    assert np.max(np.abs(np.diff(np.vstack([np.zeros(2), jumps]), axis=0))[:, 1]) > bound[1]


@pytest.mark.parametrize('reality', [
    Reality(lag=(0.1, 0.1), latency=0.05),
    Reality(lag=(0.1, 0.1), latency=0.05, acceleration=(1.0, 4.0), odom_noise=(0.005, 0.005),
            seed=2),
], ids=['lag and delay', 'lag, delay, acceleration limits and odometry noise'])
def test_a_closed_loop_with_lag_and_delay_reaches_the_goal_and_settles(reality):
    """Item 8 of issue 21: arrival is declared, and the commands stay zero from then on."""
    controller = _controller(control_frequency=20.0, max_decel=(1.0, 4.0))
    base = Base(MODEL, reality, WORLD.start, dt=0.01)

    class Stepper:
        def step(self, x):
            from mpc_local_planner.evaluation.rollout import ControlStep
            out = controller.compute(x, base.twist(), round(base.time, 9))
            return ControlStep(u=out.u, detail=out)

    rule = StopRule(time_limit=40.0, position_tolerance=-1.0)  # run on past arrival
    run = rollout(Stepper(), base, WORLD.start, WORLD.goal, h=PERIOD, rule=rule)
    reasons = [step.detail.reason for step in run.steps]
    assert Reason.GOAL_REACHED in reasons
    arrived = reasons.index(Reason.GOAL_REACHED)
    assert all(r is Reason.GOAL_REACHED for r in reasons[arrived:])
    assert all(np.all(step.u == 0.0) for step in run.steps[arrived:])
    final = run.rows[-1, 1:3]
    assert math.hypot(*(final - WORLD.goal[:2])) <= 0.1 + 0.02  # xy tolerance + coasting


def test_after_a_stop_the_mpc_tries_again_at_the_next_step_not_at_every_call():
    """A stop is kept for its step as a plan is: at 20 Hz the solver still runs at 5 Hz."""
    from mpc_local_planner.core.obstacles import ConvexPolygon

    trapped = ConvexPolygon.from_vertices([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    controller = MpcController(MODEL, CONFIG, obstacles=[trapped],
                               settings=ControllerSettings(control_frequency=20.0))
    controller.set_plan(np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]))
    solves = []
    solve = controller.mpc.solve

    def counted(x, *args, **kwargs):
        solves.append(x)
        return solve(x, *args, **kwargs)

    controller.mpc.solve = counted
    outputs = [controller.compute(np.zeros(3), None, k * PERIOD) for k in range(20)]
    assert all(out.reason is Reason.STOP for out in outputs)
    assert len(solves) == 5
    assert [out.fresh for out in outputs[:5]] == [True, False, False, False, True]


def test_a_clock_that_jumps_back_solves_at_once():
    controller = _controller(control_frequency=20.0)
    x = np.array(WORLD.start, dtype=float)
    assert controller.compute(x, None, 5.0).fresh
    assert not controller.compute(x, None, 5.05).fresh
    assert controller.compute(x, None, 1.0).fresh  # e.g. a simulation restarted its /clock
