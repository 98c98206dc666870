# SPDX-License-Identifier: Apache-2.0
"""Unit tests of the robot models (no ROS)."""

import numpy as np
import pytest

from mpc_local_planner.core.models import Unicycle


def test_unicycle_has_the_papers_turtlebot_bounds_by_default() -> None:
    model = Unicycle()
    np.testing.assert_allclose(model.u_max, [0.31, 1.9])
    np.testing.assert_allclose(model.u_min, [-0.31, -1.9])


def test_unicycle_rk4_step_matches_the_exact_arc() -> None:
    model = Unicycle()
    v, omega, h = 0.3, 0.5, 0.2
    x_next = model.step(np.array([0.0, 0.0, 0.3]), np.array([v, omega]), h)
    radius = v / omega
    exact = np.array([radius * (np.sin(0.3 + omega * h) - np.sin(0.3)),
                      -radius * (np.cos(0.3 + omega * h) - np.cos(0.3)), 0.3 + omega * h])
    np.testing.assert_allclose(x_next, exact, atol=1e-7)


def test_unicycle_step_saturates_the_input() -> None:
    model = Unicycle()
    x_next = model.step(np.zeros(3), np.array([10.0, 0.0]), 1.0)
    np.testing.assert_allclose(x_next, [0.31, 0.0, 0.0], atol=1e-12)


def test_every_pose_is_a_steady_state_with_zero_input() -> None:
    model = Unicycle()
    pose = np.array([1.0, -2.0, 0.7])
    x_s, u_s = model.steady_state(pose)
    np.testing.assert_allclose(np.asarray(model.discrete(0.2)(x_s, u_s)).ravel(), pose)


def test_unicycle_refuses_non_positive_bounds() -> None:
    with pytest.raises(ValueError, match='must be > 0'):
        Unicycle(v_max=0.0)
