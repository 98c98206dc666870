# SPDX-License-Identifier: Apache-2.0
"""The diagnostics records: keys defined once, written and read back without loss."""

from __future__ import annotations

import math

import numpy as np

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.control_output import Blockage, ControlOutput, Reason
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.diagnostics import (
    ControllerDiagnostics,
    Key,
    Level,
    level_of,
    PlannerDiagnostics,
    PlannerKey,
)
from mpc_local_planner.core.mpc import PlanSource
from mpc_local_planner.core.paths import analytic_path
from mpc_local_planner.worlds.world import paper_world

WORLD = paper_world()


def same(a: tuple, b: tuple) -> bool:
    """Field by field, NaN equal to NaN."""
    return all(x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y))
               for x, y in zip(a, b, strict=True))


def test_every_key_names_a_record_field_in_order() -> None:
    assert [key.name.lower() for key in Key] == list(ControllerDiagnostics._fields)
    assert [key.name.lower() for key in PlannerKey] == list(PlannerDiagnostics._fields)
    assert len({key.value for key in Key}) == len(Key)


def test_a_solved_step_survives_the_round_trip_through_strings() -> None:
    # time enough for the solve: the round trip, not the solve time budget, is tested here
    controller = MpcController(config=MpcConfig(solving=SolverSettings(max_solve_time=3600.0)),
                               obstacles=WORLD.obstacles)
    controller.set_path(analytic_path('paper_sinusoid'))
    output = controller.compute(WORLD.start, None, 0.0)
    assert output.reason is Reason.TRACKING
    record = ControllerDiagnostics.from_output(output, state=WORLD.start, state_time=1.5,
                                               failures_total=0)
    values = record.to_values()
    assert [key for key, _ in values] == [key.value for key in Key]
    assert all(isinstance(value, str) for _, value in values)
    back = ControllerDiagnostics.from_values(values)
    assert same(back, record)
    assert back.source is PlanSource.SOLVER and back.reason is Reason.TRACKING
    assert back.s >= 0 and back.value > 0 and back.solve_ms > 0 and back.state_time == 1.5
    np.testing.assert_allclose([back.x, back.y, back.theta], WORLD.start)
    np.testing.assert_allclose([back.v, back.omega], output.u)
    assert back.level is Level.OK and back.message == 'tracking'


def test_a_refused_step_carries_reason_and_detail_apart() -> None:
    output = ControlOutput(np.zeros(2), None, Reason.INVALID_PLAN, "frame 'odom' is not 'map'")
    record = ControllerDiagnostics.from_output(output, state=None, state_time=None,
                                               failures_total=3)
    values = dict(record.to_values())
    assert values['reason'] == 'invalid_plan'
    assert values['detail'] == "frame 'odom' is not 'map'"
    assert values['source'] == '' and values['lyapunov_ok'] == '' and values['x'] == 'nan'
    back = ControllerDiagnostics.from_values(values)
    assert back.reason is Reason.INVALID_PLAN and back.failures_total == 3
    assert back.source is None
    assert back.message == "invalid plan: frame 'odom' is not 'map'"
    assert back.level is Level.ERROR and not back.goal_reached


def test_goal_reached_is_written_from_the_reason() -> None:
    output = ControlOutput(np.zeros(2), None, Reason.GOAL_REACHED)
    record = ControllerDiagnostics.from_output(output, state=WORLD.goal, state_time=9.0,
                                               failures_total=0)
    assert dict(record.to_values())['goal_reached'] == 'true'
    assert ControllerDiagnostics.from_values(record.to_values()).goal_reached


def test_missing_malformed_and_unknown_values_keep_their_defaults() -> None:
    back = ControllerDiagnostics.from_values({'reason': 'no such reason', 's_k': 'x',
                                              'failures': '', 'other': '1'})
    assert back.reason is None and math.isnan(back.s) and back.failures == 0
    assert back.level is Level.WARN and back.message == 'unknown'


def test_levels_follow_the_reason() -> None:
    assert level_of(Reason.TRACKING) is Level.OK and level_of(Reason.GOAL_REACHED) is Level.OK
    assert level_of(Reason.ROTATE_TO_HEADING) is Level.OK  # arriving, not waiting
    for reason in (Reason.STOP, Reason.ERROR, Reason.INVALID_ODOM, Reason.INVALID_PLAN):
        assert level_of(reason) is Level.ERROR
    for reason in (Reason.CANDIDATE, Reason.NO_PLAN, Reason.NO_ODOM, Reason.STALE_ODOM):
        assert level_of(reason) is Level.WARN


def test_the_planner_outcome_survives_the_round_trip() -> None:
    failed = PlannerDiagnostics(planned=False, detail='no plan to (1, 2): walled off')
    back = PlannerDiagnostics.from_values(failed.to_values())
    assert not back.planned and back.detail == failed.detail and back.level is Level.ERROR
    planned = PlannerDiagnostics(planned=True, detail='published', poses=5, length=2.5)
    assert PlannerDiagnostics.from_values(planned.to_values()) == planned


def test_a_blocked_plan_is_reported_with_where_it_is_blocked() -> None:
    output = ControlOutput(np.zeros(2), None, Reason.STALE_SCAN)
    record = ControllerDiagnostics.from_output(output, state=WORLD.start, state_time=1.0,
                                               failures_total=0,
                                               blockage=Blockage(True, 0.75))
    values = dict(record.to_values())
    assert values['path_blocked'] == 'true' and values['blocked_at'] == '0.75'
    back = ControllerDiagnostics.from_values(values)
    assert back.path_blocked and back.blocked_at == 0.75
    assert back.reason is Reason.STALE_SCAN and back.message == 'scan is stale'
    assert back.level is Level.WARN and level_of(Reason.NO_SCAN) is Level.WARN
    clear = ControllerDiagnostics.from_output(output, state=None, state_time=None,
                                              failures_total=0)
    assert dict(clear.to_values())['path_blocked'] == 'false'
    assert math.isnan(ControllerDiagnostics.from_values(clear.to_values()).blocked_at)
