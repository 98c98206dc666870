# SPDX-License-Identifier: Apache-2.0
"""How the suites record the paper's controller's answers (evaluation.rollout.control_step)."""

from __future__ import annotations

import math

import numpy as np

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.evaluation.metrics import compute_metrics
from mpc_local_planner.evaluation.rollout import control_step
from mpc_local_planner.evaluation.trajectory import trajectory_row
from mpc_local_planner.worlds.world import paper_world

WORLD = paper_world()
MODEL = Unicycle()
PLAN = np.array([[0.0, 0.0, WORLD.start[2]], [0.8, 1.3, 0.0], [1.7, 1.3, -0.96],
                 [2.5, 0.0, WORLD.goal[2]]])
PERIOD = 0.05  # 20 Hz: three calls of four hold the plan of the step h = 0.2 s


def test_calls_that_hold_the_plan_solve_nothing_and_leave_the_solve_statistics_alone():
    # the same under any load; interpreted: the compiled functions' numbers, without gcc
    config = MpcConfig(solving=SolverSettings(budget='iterations', compile=False))
    controller = MpcController(MODEL, config, obstacles=WORLD.obstacles,
                               settings=ControllerSettings(control_frequency=20.0))
    controller.set_plan(PLAN)
    x = np.array(WORLD.start, dtype=float)
    rows = []
    for k in range(12):
        step = control_step(controller.compute(x, None, k * PERIOD))
        rows.append(trajectory_row(k * PERIOD, x, step.u, s=step.s, value=step.value,
                                   solve_ms=1e3 * step.solve_time_s))
        x = MODEL.step(x, step.u, PERIOD)
    solved = [k for k, row in enumerate(rows) if math.isfinite(row[-1])]
    assert solved == [0, 4, 8]
    assert all(rows[k][-1] >= 0.0 for k in solved)
    # the median is over the solves, not dragged to 0 by the held calls
    metrics = compute_metrics(np.array(rows), goal=np.array(WORLD.goal), obstacles=[])
    assert metrics['solve_ms_median'] == np.median([rows[k][-1] for k in solved])
