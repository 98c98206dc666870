# SPDX-License-Identifier: Apache-2.0
"""A robot standing within its collision margin plans with half the clearance it stands at.

On the physics plant through the nodes, BARN 23, 272, 276 and 296 ended with the Jackal
standing 27 to 56 mm from the laser's pieces, its margin 30 mm, and no feasible plan at any
step after (core/margin_relief.py says why).
"""

from __future__ import annotations

import numpy as np
import pytest

from mpc_local_planner.core import margin_relief
from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.margin_relief import (
    footprint_clearance_at,
    MarginRelief,
    RELIEF_FACTOR,
    standing,
    STANDING_TWIST,
)
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.obstacles import ConvexPolygon

MARGIN = 0.03
# a box beside the Jackal's right flank, 20 mm below it and 20 mm ahead of its nose: the
# footprint stands 28 mm from it, within the margin; going straight on keeps 20 mm
BOX = ConvexPolygon.from_box(0.274, -0.6, 0.8, -0.235)
MODEL = Unicycle(v_max=2.0, omega_max=4.0, v_min=0.0)  # forward only, as BARN's Jackal
CONFIG = MpcConfig(footprint=tuple(map(tuple, JACKAL.vertices.tolist())),
                   collision_margin=MARGIN, max_accel=(2.0, 6.0), input_hold='first_order',
                   solving=SolverSettings(compile=False, budget='iterations',
                                          max_solve_iterations=100))
PLAN = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]])


def drive(steps: int) -> list[tuple[Reason, str, float, float]]:
    """Run the controller on the model from the pose by the box: (reason, detail, x, clearance)."""
    controller = MpcController(MODEL, CONFIG, obstacles=[BOX])
    controller.set_plan(PLAN)
    x, u, rows = np.zeros(3), np.zeros(2), []
    for k in range(steps):
        output = controller.compute(x, u, k * CONFIG.step)
        u = output.u
        x = MODEL.step(x, u, CONFIG.step)
        rows.append((output.reason, output.detail, float(x[0]),
                     footprint_clearance_at(CONFIG.robot_footprint, x, [BOX])))
    return rows


def test_the_start_is_within_the_margin() -> None:
    clearance = footprint_clearance_at(CONFIG.robot_footprint, np.zeros(3), [BOX])
    assert 0 < clearance < MARGIN


def test_a_robot_standing_within_the_margin_drives_out_keeping_half_its_clearance() -> None:
    # slowly: 20 mm beside the box with a 14 mm margin, the swept clearance's h/2 |v| allows
    # about 0.06 m/s until it is past the box
    rows = drive(25)
    assert rows[0][0] is Reason.STOP  # grown by the margin, the box leaves no first step
    # relieved: standing on the candidate while the budget's cut solve goes on, then away
    relieved = rows[1:]
    assert all(reason in (Reason.CANDIDATE, Reason.TRACKING) and 'relieved' in detail
               for reason, detail, _, _ in relieved)
    assert relieved[-1][2] > 0.1  # on its way along the plan
    # never nearer the box than the relieved margin, half the 28 mm it stood at
    assert min(clearance for *_, clearance in rows) > 0.014


def test_without_the_relief_the_robot_stands_for_good(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(margin_relief, 'RELIEF_FACTOR', 0.0)  # never near enough
    rows = drive(3)
    assert all(reason is Reason.STOP and x == 0.0 for reason, _, x, _ in rows)


def relief_after(*updates: dict) -> bool:
    relief = MarginRelief()
    for update in updates:
        relief.update(**{'margin': MARGIN, 'solver_stopped': True, 'is_standing': True,
                         **update})
    return relief.active


NEAR, FAR = RELIEF_FACTOR * MARGIN - 1e-3, RELIEF_FACTOR * MARGIN + 1e-3


def test_the_relief_starts_only_at_a_standing_robot_the_solver_stopped_near_an_obstacle(
        ) -> None:
    assert relief_after({'clearance': NEAR})
    assert not relief_after({'clearance': FAR})
    assert not relief_after({'clearance': NEAR, 'solver_stopped': False})
    assert not relief_after({'clearance': NEAR, 'is_standing': False})
    assert not relief_after({'clearance': NEAR, 'margin': 0.0})


def test_the_relief_lasts_while_the_robot_is_near_moving_or_not_and_ends_beyond() -> None:
    moving = {'solver_stopped': False, 'is_standing': False}
    assert relief_after({'clearance': NEAR}, {'clearance': 0.001, **moving})
    assert not relief_after({'clearance': NEAR}, {'clearance': FAR, **moving})
    # ended, it starts again only from a stop
    assert not relief_after({'clearance': NEAR}, {'clearance': FAR},
                            {'clearance': NEAR, **moving})


def test_the_relieved_margin_is_half_the_clearance_at_the_start_and_stays() -> None:
    relief = MarginRelief()
    stop = {'margin': MARGIN, 'solver_stopped': True, 'is_standing': True}
    assert relief.update(clearance=NEAR, **stop)
    assert relief.margin == pytest.approx(margin_relief.RELIEVED_SHARE * NEAR)
    assert 0.0 < relief.margin < MARGIN
    # creeping nearer does not shrink it (a margin re-read at every step would reach zero)
    assert relief.update(clearance=0.2 * NEAR, margin=MARGIN, solver_stopped=False,
                         is_standing=False)
    assert relief.margin == pytest.approx(margin_relief.RELIEVED_SHARE * NEAR)
    touching = MarginRelief()
    assert touching.update(clearance=-0.001, **stop) and touching.margin == 0.0


def test_standing_is_a_twist_within_the_odometry_noise_of_a_standing_base() -> None:
    assert standing(np.zeros(2))
    assert standing(np.array(STANDING_TWIST))
    assert not standing(np.array([2 * STANDING_TWIST[0], 0.0]))
    assert not standing(np.array([0.0, -2 * STANDING_TWIST[1]]))
    assert not standing(None)  # not known to stand
