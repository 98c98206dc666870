# SPDX-License-Identifier: Apache-2.0
"""The controllers by name: every one a LocalController, built from one setup."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core.baselines import Dwa, PurePursuit, TrackingMPC
from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.controllers import (
    build_controller,
    ControllerName,
    ControllerSetup,
    FOLLOWER_ARRIVAL,
)
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.local_controller import LocalController
from mpc_local_planner.core.models import Unicycle

SETUP = ControllerSetup(model=Unicycle(v_max=2.0, omega_max=4.0), footprint=JACKAL,
                        config=MpcConfig(solving=SolverSettings(compile=False)),
                        goal_tolerance=0.1)
PLAN = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
BASELINES = [ControllerName.TRACKING, ControllerName.PURE_PURSUIT, ControllerName.DWA,
             ControllerName.REGULATED_PURE_PURSUIT]


def test_the_names_are_the_rows_words() -> None:
    assert [name.value for name in ControllerName] == [
        'proposed', 'tracking', 'pure_pursuit', 'dwa', 'regulated_pure_pursuit']
    assert ControllerName('dwa') is ControllerName.DWA and ControllerName.DWA == 'dwa'
    assert f'{ControllerName.DWA}_000' == 'dwa_000' and str(ControllerName.DWA) == 'dwa'


@pytest.mark.parametrize('name', BASELINES)
def test_every_baseline_is_a_local_controller_that_follows_a_plan(name: ControllerName
                                                                  ) -> None:
    controller, reach = build_controller(name, SETUP)
    assert isinstance(controller, LocalController)
    assert reach >= 0.0
    assert controller.compute(np.zeros(3), None, 0.0).reason is Reason.NO_PLAN
    controller.set_plan(PLAN)
    controller.set_obstacles([])
    output = controller.compute(np.zeros(3), None, 0.0)
    assert output.reason.applies_input and output.u[0] > 0.0
    assert controller.compute(None, None, 0.2).reason is Reason.NO_ODOM
    controller.set_speed_limit(0.05)
    assert abs(controller.compute(np.zeros(3), None, 0.4).u[0]) <= 0.05 + 1e-12
    with pytest.raises(ValueError, match='speed limit'):
        controller.set_speed_limit(0.0)
    with pytest.raises(ValueError, match='plan'):
        controller.set_plan(np.zeros(3))


def test_the_papers_controller_is_a_local_controller_too() -> None:
    controller, reach = build_controller(ControllerName.PROPOSED, SETUP)
    assert isinstance(controller, LocalController)
    assert reach == SETUP.config.reach(2.0)
    assert controller.compute(np.zeros(3), None, 0.0).reason is Reason.NO_PLAN


def test_the_path_followers_answer_with_their_progress_and_time() -> None:
    for name in (ControllerName.PURE_PURSUIT, ControllerName.DWA):
        controller = build_controller(name, SETUP).controller
        controller.set_plan(PLAN)
        output = controller.compute(np.array([0.3, 0.0, 0.0]), None, 0.0)
        assert output.solution is None and output.progress == pytest.approx(0.15)
        assert output.compute_time_s >= 0.0
        controller.reset()  # forgets the plan
        assert controller.compute(np.zeros(3), None, 0.2).reason is Reason.NO_PLAN


def test_the_tracking_mpc_tracks_the_plans_end() -> None:
    mpc = build_controller(ControllerName.TRACKING, SETUP).controller
    assert isinstance(mpc, TrackingMPC)
    mpc.set_plan(PLAN[-1:])  # a plan of one pose is its target
    output = mpc.compute(np.zeros(3), None, 0.0)
    assert output.solution is not None and output.reason is Reason.TRACKING
    assert output.u[0] > 0.0
    mpc.set_plan(np.array([[0.0, 0.0, 0.0], [-2.0, 0.0, math.pi]]))  # a target behind
    assert mpc.compute(np.zeros(3), None, 0.2).u[0] <= 0.0
    with pytest.raises(ValueError, match='non-finite'):
        mpc.set_plan(np.array([[0.0, 0.0, 0.0], [math.nan, 0.0, 0.0]]))


def test_each_factory_reads_the_setup() -> None:
    real = ControllerSetup(model=Unicycle(v_max=2.0, omega_max=4.0), footprint=JACKAL,
                           goal_tolerance=1.0, control_period=0.05,
                           acceleration=(1.5, math.inf))
    dwa = build_controller(ControllerName.DWA, real).controller
    assert isinstance(dwa, Dwa)
    assert dwa.config.control_period == 0.05 and dwa.config.acc_lim_x == 1.5
    assert dwa.config.acc_lim_theta == Dwa().config.acc_lim_theta  # not finite: the default
    assert dwa.config.xy_goal_tolerance == FOLLOWER_ARRIVAL  # min(0.03, 1.0 / 2)
    pursuit = build_controller(ControllerName.PURE_PURSUIT, SETUP).controller
    assert isinstance(pursuit, PurePursuit)
    assert pursuit.config.v_max == 2.0 and pursuit.config.goal_tolerance == FOLLOWER_ARRIVAL
    regulated, reach = build_controller(ControllerName.REGULATED_PURE_PURSUIT, SETUP)
    assert regulated.config.collision_time > 0.0 and reach > JACKAL.radius
    assert build_controller(ControllerName.PURE_PURSUIT, SETUP).reach == 0.0


def test_an_unknown_name_is_refused_with_the_known_ones() -> None:
    with pytest.raises(ValueError, match="unknown controller 'teb'.*dwa"):
        build_controller('teb', SETUP)
