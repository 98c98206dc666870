# SPDX-License-Identifier: Apache-2.0
"""MpcConfig's footprint: stored hashably, validated, structural, and what it inflates."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core.config import (
    BudgetKind,
    BUDGETS,
    INPUT_HOLDS,
    InputHold,
    MpcConfig,
    NlpSolver,
    OBSTACLE_SOURCES,
    ObstacleSource,
    SOLVERS,
    SolverSettings,
    STRUCTURAL_FIELDS,
)

JACKAL_VERTICES = ((0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215), (0.254, -0.215))


def test_a_footprint_given_as_lists_or_an_array_is_stored_as_a_hashable_tuple() -> None:
    from_lists = MpcConfig(footprint=[list(v) for v in JACKAL_VERTICES])
    from_array = MpcConfig(footprint=np.array(JACKAL_VERTICES))
    assert from_lists.footprint == JACKAL_VERTICES
    assert isinstance(from_lists.footprint, tuple)
    assert all(isinstance(v, tuple) for v in from_lists.footprint)
    # equal settings compare equal with != (update_config) and hash alike
    assert from_lists == from_array
    assert not (from_lists != from_array)
    assert hash(from_lists) == hash(from_array)


def test_nav2_string_form_is_read_too() -> None:
    config = MpcConfig(footprint='[[0.254, 0.215], [0.254, -0.215], [-0.254, -0.215], '
                                 '[-0.254, 0.215]]')
    assert set(config.footprint) == set(JACKAL_VERTICES)
    assert not config.robot_footprint.is_circle
    assert MpcConfig(footprint='[]').footprint == ()


def test_the_footprint_property_returns_the_polygon_or_the_circle_of_robot_radius() -> None:
    polygon = MpcConfig(footprint=JACKAL_VERTICES, robot_radius=0.5).robot_footprint
    assert not polygon.is_circle
    assert polygon.radius == pytest.approx(math.hypot(0.254, 0.215))
    circle = MpcConfig(robot_radius=0.2).robot_footprint
    assert circle.is_circle and circle.radius == 0.2


@pytest.mark.parametrize(('vertices', 'match'), [
    ([[0, 0], [2, 0], [1, 0.2], [2, 1], [0, 1]], 'not convex'),
    ([[0, 0], [1, 0], [2, 0]], 'collinear'),
    ([[0, 0], [1, 0]], 'at least 3'),
    ([[0, 0], [1, 0], [1, float('inf')]], 'finite'),
    ([[0, 0, 1], [1, 0, 1], [0, 1, 1]], 'sequence of \\(x, y\\) vertices'),
    (np.ones((3, 3)), 'sequence of \\(x, y\\) vertices'),
    ('[[0, 0], [1, 0]', 'sequence of \\(x, y\\) vertices'),
    (5, 'sequence of \\(x, y\\) vertices'),
])
def test_non_convex_or_degenerate_footprints_are_refused_with_the_reason(
        vertices: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        MpcConfig(footprint=vertices)


def test_the_footprint_is_structural_and_the_update_check_sees_its_change() -> None:
    assert 'footprint' in STRUCTURAL_FIELDS
    old, new = MpcConfig(), MpcConfig(footprint=JACKAL_VERTICES)
    assert old.footprint != new.footprint
    assert new.with_changes(horizon=5).footprint == new.footprint


def test_a_polygon_inflates_obstacles_by_the_explicit_collision_margin_only() -> None:
    v_max = 0.31
    # a circle: radius plus half the longest step, as before
    assert MpcConfig(robot_radius=0.2).inflation(v_max) == pytest.approx(0.2 + v_max * 0.1)
    assert MpcConfig(robot_radius=0.2, collision_margin=0.05).inflation(v_max) == \
        pytest.approx(0.25)
    # a polygon: no radius, no default margin (its NLP's clearance follows the motion)
    polygon = MpcConfig(footprint=JACKAL_VERTICES, robot_radius=0.4)
    assert polygon.inflation(v_max) == 0.0
    assert polygon.with_changes(collision_margin=0.03).inflation(v_max) == pytest.approx(0.03)


def test_the_reach_of_a_polygon_counts_its_farthest_corner() -> None:
    v_max = 0.31
    circle = MpcConfig(robot_radius=0.2)
    assert circle.reach(v_max) == pytest.approx(v_max * 0.2 * 10 + 0.2 + v_max * 0.1)
    polygon = MpcConfig(footprint=JACKAL_VERTICES)
    assert polygon.reach(v_max) == pytest.approx(v_max * 0.2 * 10 + math.hypot(0.254, 0.215))


def test_the_solver_settings_are_validated_apart_and_their_structure_is_in_the_key() -> None:
    config = MpcConfig()
    assert config.with_solving(max_iterations=50).structure_key() != config.structure_key()
    # the budget is not structural: nothing is rebuilt for it
    assert config.with_solving(max_solve_time=1.0).structure_key() == config.structure_key()
    assert config.with_solving(solver='ipopt').solving == SolverSettings(solver='ipopt')
    with pytest.raises(ValueError, match='invalid MPC solver settings: solver must be one of'):
        config.with_solving(solver='sqp')
    with pytest.raises(ValueError, match='solving must be a SolverSettings'):
        MpcConfig(solving={'solver': 'ipopt'})


def test_the_closed_choices_are_str_enums_that_parse_and_compare_as_the_strings_written() -> None:
    settings = SolverSettings(solver='ipopt', budget='iterations')
    assert settings.solver is NlpSolver.IPOPT and settings.budget is BudgetKind.ITERATIONS
    config = MpcConfig(max_accel=(0.5, 2.0), input_hold='first_order')
    assert config.input_hold is InputHold.FIRST_ORDER and config.first_order_hold
    assert MpcConfig().input_hold is InputHold.ZERO and MpcConfig().solving.solver == 'fatrop'
    for member in (*NlpSolver, *BudgetKind, *InputHold, *ObstacleSource):
        # what a user writes and what a log or a CSV shows: the string itself
        assert member == member.value and str(member) == f'{member}' == member.value
        assert {member.value: True}[member] and member in {member.value}
    assert settings == SolverSettings(solver=NlpSolver.IPOPT, budget=BudgetKind.ITERATIONS)
    assert hash(settings) == hash(SolverSettings(solver='ipopt', budget='iterations'))
    assert (SOLVERS, BUDGETS, INPUT_HOLDS, OBSTACLE_SOURCES) == (
        ('fatrop', 'ipopt'), ('wall', 'iterations'), ('zero', 'first_order'),
        ('world', 'scan', 'map'))
    with pytest.raises(ValueError, match=r"^invalid MPC solver settings: solver must be one of "
                                         r"\('fatrop', 'ipopt'\), got 'sqp'$"):
        SolverSettings(solver='sqp')
    with pytest.raises(ValueError, match=r"input_hold must be one of \('zero', 'first_order'\), "
                                         r"got 'ramp'$"):
        MpcConfig(input_hold='ramp')
