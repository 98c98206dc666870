# SPDX-License-Identifier: Apache-2.0
"""config/jackal.yaml: the Jackal's parameters are the ones the suites measure on a real base."""

from __future__ import annotations

from typing import Any

import pytest
import yaml

from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.evaluation import sensing_suites
from mpc_local_planner.ros.mpc_controller_parameters import build_settings, DEFAULTS, PARAMETERS
from mpc_local_planner.sim.reality import reality_preset
from mpc_local_planner.worlds.data_files import resolve_data_file


def jackal_values() -> dict[str, Any]:
    """Return the defaults with config/jackal.yaml over them (as two --params-file do)."""
    text = resolve_data_file('jackal.yaml').read_text(encoding='utf-8')
    given = yaml.safe_load(text)['mpc_controller']['ros__parameters']
    declared = {spec.name for spec in PARAMETERS}
    assert set(given) <= declared, f'undeclared: {sorted(set(given) - declared)}'
    return {**DEFAULTS, **given}


def test_the_jackal_file_bounds_input_rates_as_the_suites_do_on_the_real_base() -> None:
    config, model, settings = build_settings(jackal_values())
    base = reality_preset('real').acceleration_limits
    assert base is not None
    assert config.max_accel == pytest.approx(
        [sensing_suites.REALITY_ACCEL_FACTOR * a for a in base])
    assert settings.max_decel == pytest.approx(base)
    # the first-order hold, its ramp led by the base's latency + lag, as the suites run it
    assert config.input_hold == sensing_suites.REALITY_INPUT_HOLD
    assert settings.actuation_delay == pytest.approx(
        sensing_suites.actuation_delay(reality_preset('real')))
    assert config.collision_margin == pytest.approx(sensing_suites.REALITY_MARGIN)
    jackal = sensing_suites.ROBOTS['jackal']
    assert config.robot_footprint.vertices.tolist() == JACKAL.vertices.tolist()
    assert model.u_min[0] == 0.0 and not jackal.reverses
    assert (model.u_max[0], model.u_max[1]) == (2.0, 4.0)  # the suites' BARN runs
    # a solve holds as many obstacles as the suites prepare (BARN 276 and 296 stood still
    # through the nodes on the physics plant with the default 4, and reached with these)
    assert config.solving.obstacle_slots == sensing_suites.PREPARED_SLOTS


def test_the_jackal_file_plans_as_the_suites_plan_for_the_jackal() -> None:
    from mpc_local_planner.ros.global_planner_parameters import PARAMETERS as PLANNER

    text = resolve_data_file('jackal.yaml').read_text(encoding='utf-8')
    given = yaml.safe_load(text)['global_planner']['ros__parameters']
    declared = {spec.name for spec in PLANNER}
    assert set(given) <= declared, f'undeclared: {sorted(set(given) - declared)}'
    # the planner node as a user runs it with the Jackal's file is the suites' planner
    assert given['iterations'] == sensing_suites.PLANNER_ITERATIONS
    assert given['range'] == pytest.approx(sensing_suites.PLANNER_RANGE)
    assert given['time_limit'] == pytest.approx(sensing_suites.PLANNER_TIME_LIMIT)
    assert given['clearance'] == pytest.approx(sensing_suites.POLYGON_CLEARANCE)
    assert yaml.safe_load(given['footprint']) == JACKAL.vertices.tolist()
