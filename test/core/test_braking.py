# SPDX-License-Identifier: Apache-2.0
"""Braking along the last verified plan (core/braking.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core.braking import Brake
from mpc_local_planner.core.models import Unicycle, unicycle_arc

PLAN = np.array([[2.0, 1.0]] * 5 + [[1.0, -0.5]] * 5)  # N = 10 inputs of h = 0.2 s


def _brake(decel=(2.0, 6.0), elapsed=0.0, dt=0.05):
    brake = Brake(decel)
    brake.start(PLAN, 0.2, elapsed)
    commands = []
    while brake.active:
        commands.append(brake.command(dt))
    commands.append(brake.command(dt))
    return np.array(commands)


def test_braking_decelerates_within_the_limits_and_stops():
    commands = _brake()
    assert np.all(commands[-1] == 0.0)
    # the first part of the plan: every step's fall in speed within the limit
    first = commands[commands[:, 0] > 0]
    falls = -np.diff(np.abs(first[:8]), axis=0)
    assert np.all(falls[:, 0] <= 2.0 * 0.05 + 1e-9)
    assert np.all(falls[:, 1] <= 6.0 * 0.05 + 1e-9)
    # from 2 m/s at 2 m/s^2: a second
    assert len(commands) * 0.05 == pytest.approx(1.0, abs=0.1)


def test_braking_stays_on_the_plan_s_curve():
    """Scaling v and omega alike keeps the curvature: the robot traces the plan's curve."""
    commands = _brake()
    moving = commands[commands[:, 0] > 0]
    curvature = moving[:, 1] / moving[:, 0]
    assert np.all(np.isclose(curvature, 0.5) | np.isclose(curvature, -0.5))  # the plan's
    # and the braked path ends on the plan's curve, short of its end
    model = Unicycle(v_max=2.0, omega_max=4.0)
    plan_curve = [np.zeros(3)]
    for u in PLAN:
        for _ in range(200):
            plan_curve.append(unicycle_arc(plan_curve[-1], u[0], u[1], 0.001))
    plan_curve = np.array(plan_curve)
    pose = np.zeros(3)
    for u in commands:
        for _ in range(50):
            pose = unicycle_arc(pose, *model.saturate(u), 0.001)
    assert np.min(np.hypot(*(plan_curve[:, :2] - pose[:2]).T)) < 0.01


def test_braking_starts_where_the_robot_is_on_the_plan():
    commands = _brake(elapsed=1.1)  # in the second half: (1.0, -0.5)
    assert commands[0, 1] / commands[0, 0] == pytest.approx(-0.5)


def test_without_limits_the_stop_is_at_once():
    brake = Brake((math.inf, math.inf))
    brake.start(PLAN, 0.2, 0.0)
    assert not brake.active
    np.testing.assert_array_equal(brake.command(0.05), [0.0, 0.0])
