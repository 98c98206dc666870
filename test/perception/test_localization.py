# SPDX-License-Identifier: Apache-2.0
"""LocalizedPose: odometry composed with a localizer's correction, against hand-computed poses."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.perception.localization import (
    compose,
    invert,
    LocalizationError,
    LocalizedPose,
)


def test_compose_with_the_inverse_is_the_identity() -> None:
    a = np.array([1.0, -2.0, 2.5])
    np.testing.assert_allclose(compose(a, invert(a)), np.zeros(3), atol=1e-12)
    np.testing.assert_allclose(compose(invert(a), a), np.zeros(3), atol=1e-12)


def test_without_a_localizer_the_odometry_is_the_pose() -> None:
    located = LocalizedPose(2.0)
    located.add_odometry(1.0, np.array([1.0, 2.0, 0.3]))
    assert located.problem is None
    np.testing.assert_array_equal(located.at(1.0), [1.0, 2.0, 0.3])
    np.testing.assert_array_equal(located.pose(np.array([4.0, 5.0, -1.0])), [4.0, 5.0, -1.0])


def test_the_correction_at_a_stamp_between_two_odometry_samples_moves_the_latest_odometry(
) -> None:
    located = LocalizedPose(2.0, localized=True, source='amcl_pose')
    located.add_odometry(1.0, np.array([1.0, 0.0, 0.0]))
    located.add_odometry(2.0, np.array([2.0, 0.0, 0.0]))
    assert located.at(2.0) is None and 'amcl_pose' in located.problem  # none before the first
    # odom at 1.5 s is (1.5, 0, 0); the localizer says the robot was at (0, 2.5) heading +y:
    # map <- odom = (0, 2.5, pi/2) * inverse(1.5, 0, 0) = (0, 1, pi/2)
    correction = located.add_localizer(1.5, np.array([0.0, 2.5, math.pi / 2]))
    np.testing.assert_allclose(correction, [0.0, 1.0, math.pi / 2], atol=1e-12)
    assert located.problem is None
    # the latest odometry, 0.5 m further along odom's x, is 0.5 m further along map's y
    np.testing.assert_allclose(located.at(2.0), [0.0, 3.0, math.pi / 2], atol=1e-12)
    np.testing.assert_allclose(located.at(1.0), [0.0, 2.0, math.pi / 2], atol=1e-12)


def test_the_heading_is_interpolated_at_the_localizer_stamp() -> None:
    located = LocalizedPose(2.0, localized=True)
    located.add_odometry(0.0, np.array([0.0, 0.0, 0.0]))
    located.add_odometry(1.0, np.array([0.0, 0.0, 1.0]))
    located.add_localizer(0.25, np.array([0.0, 0.0, 0.35]))  # odom heading 0.25 there
    np.testing.assert_allclose(located.correction, [0.0, 0.0, 0.1], atol=1e-12)
    np.testing.assert_allclose(located.at(1.0), [0.0, 0.0, 1.1], atol=1e-12)


def test_a_localizer_pose_older_than_the_history_drops_the_correction_until_a_usable_one(
) -> None:
    located = LocalizedPose(1.0, localized=True, source='amcl_pose')
    for t in (10.0, 11.0, 12.0):
        located.add_odometry(t, np.array([t, 0.0, 0.0]))  # 1 s kept: 11 and 12
    located.add_localizer(11.5, np.array([11.5, 1.0, 0.0]))
    np.testing.assert_allclose(located.at(12.0), [12.0, 1.0, 0.0])
    with pytest.raises(LocalizationError, match='older than the odometry kept'):
        located.add_localizer(10.5, np.array([10.5, 1.0, 0.0]))
    assert located.at(12.0) is None and 'older' in located.problem
    located.add_localizer(11.0, np.array([11.0, -1.0, 0.0]))
    assert located.problem is None
    np.testing.assert_allclose(located.at(12.0), [12.0, -1.0, 0.0])


def test_a_localizer_pose_before_any_odometry_is_refused() -> None:
    located = LocalizedPose(1.0, localized=True)
    with pytest.raises(LocalizationError, match='no odometry yet'):
        located.add_localizer(1.0, np.zeros(3))


def test_a_jump_in_the_correction_moves_every_pose_at_once_the_past_ones_too() -> None:
    located = LocalizedPose(2.0, localized=True)
    located.add_odometry(0.0, np.array([0.0, 0.0, 0.0]))
    located.add_odometry(1.0, np.array([1.0, 0.0, 0.0]))
    located.add_localizer(1.0, np.array([1.0, 0.0, 0.0]))  # no drift yet
    np.testing.assert_allclose(located.at(0.5), [0.5, 0.0, 0.0], atol=1e-12)
    located.add_odometry(2.0, np.array([2.0, 0.0, 0.0]))
    # the localizer re-localises: the robot is 0.4 m to the left and turned by 0.1 rad
    located.add_localizer(2.0, np.array([2.0, 0.4, 0.1]))
    c, s = math.cos(0.1), math.sin(0.1)
    # map <- odom = (2, 0.4, 0.1) * inverse(2, 0, 0) = (2 - 2c, 0.4 - 2s, 0.1)
    np.testing.assert_allclose(located.correction, [2 - 2 * c, 0.4 - 2 * s, 0.1], atol=1e-12)
    np.testing.assert_allclose(located.at(2.0), [2.0, 0.4, 0.1], atol=1e-12)
    # a scan from before the jump is placed with the new correction (the one in force)
    np.testing.assert_allclose(located.at(1.5), [2 - 0.5 * c, 0.4 - 0.5 * s, 0.1], atol=1e-12)
    assert located.corrections == 2


def test_clear_forgets_the_odometry_and_the_correction() -> None:
    located = LocalizedPose(2.0, localized=True)
    located.add_odometry(0.0, np.zeros(3))
    located.add_localizer(0.0, np.ones(3))
    located.clear()
    assert located.at(0.0) is None and located.correction is None and located.problem


def drive(located: LocalizedPose, start: float, stop: float, *, v: float = 0.0,
          omega: float = 0.0, dt: float = 0.1) -> None:
    """Add odometry along a straight line (v) or a turn on the spot (omega), every dt."""
    for k in range(round((stop - start) / dt) + 1):
        t = start + k * dt
        located.add_odometry(t, np.array([v * t, 0.0, omega * t]), (v, omega))


def test_a_silent_localizer_is_stale_after_the_odometry_travelled_max_travel() -> None:
    located = LocalizedPose(2.0, localized=True, source='amcl_pose', max_travel=1.0)
    drive(located, 0.0, 1.0, v=0.5)
    located.add_localizer(1.0, np.array([0.5, 0.0, 0.0]))
    assert located.staleness() is None
    drive(located, 1.1, 2.9, v=0.5)  # 0.95 m since the pose's stamp: still fresh
    assert located.travel == pytest.approx(0.95)
    assert located.staleness() is None
    drive(located, 3.0, 3.2, v=0.5)  # 1.1 m: the localizer should have spoken by now
    problem = located.staleness()
    assert problem is not None and 'amcl_pose' in problem and 'localization_max_travel' in problem
    assert located.pose(np.array([1.6, 0.0, 0.0])) is not None  # scans are still placed
    # a late pose counts from its stamp: the 0.4 m travelled since then are not forgotten
    located.add_localizer(2.8, np.array([1.4, 0.0, 0.0]))
    assert located.travel == pytest.approx(0.2) and located.staleness() is None


def test_a_localizer_silent_at_rest_is_never_stale() -> None:
    located = LocalizedPose(2.0, localized=True, max_travel=1.0, max_rotation=0.8)
    drive(located, 0.0, 0.5, v=0.0)
    located.add_localizer(0.5, np.zeros(3))
    for t in np.arange(0.6, 1000.0, 0.5):  # as AMCL: nothing while the robot stands
        located.add_odometry(float(t), np.zeros(3), (0.0, 0.0))
    assert located.staleness() is None


def test_noisy_odometry_at_rest_never_adds_up_to_travel() -> None:
    # white noise on the odometry's pose (1 cm, 0.01 rad a sample, 50 Hz for an hour): summed
    # sample by sample it would be ~700 m; the displacement from the anchor stays centimetres
    rng = np.random.default_rng(7)
    located = LocalizedPose(2.0, localized=True, max_travel=1.0, max_rotation=0.8)
    located.add_odometry(0.0, np.zeros(3), (0.0, 0.0))
    located.add_localizer(0.0, np.zeros(3))
    for k in range(1, 180_000):
        located.add_odometry(k * 0.02, rng.normal(0.0, 0.01, 3), (0.0, 0.0))
    assert located.travel < 0.1 and located.rotation < 0.1
    assert located.staleness() is None


def test_a_robot_that_moved_away_and_back_without_a_localizer_pose_stays_stale() -> None:
    located = LocalizedPose(2.0, localized=True, max_travel=1.0, max_rotation=0.8)
    drive(located, 0.0, 0.1, v=0.5)
    located.add_localizer(0.1, np.array([0.05, 0.0, 0.0]))
    drive(located, 0.2, 2.4, v=0.5)  # 1.15 m out
    assert located.staleness() is not None
    for k, x in enumerate(np.linspace(1.1, 0.05, 12)):  # and back to where it was localized
        located.add_odometry(2.5 + 0.1 * k, np.array([x, 0.0, 0.0]), (-0.5, 0.0))
    assert located.travel == pytest.approx(1.15)
    assert located.staleness() is not None


def test_a_turn_on_the_spot_beyond_max_rotation_is_stale_and_zero_turns_the_limit_off(
) -> None:
    for limit, stale in ((0.8, True), (0.0, False)):
        located = LocalizedPose(2.0, localized=True, max_travel=1.0, max_rotation=limit)
        drive(located, 0.0, 0.1, omega=1.0)
        located.add_localizer(0.1, np.array([0.0, 0.0, 0.1]))
        drive(located, 0.2, 1.0, omega=1.0)  # 0.9 rad, turned in 0.1 rad steps
        assert located.rotation == pytest.approx(0.9)
        assert (located.staleness() is not None) is stale
        if stale:
            assert 'localization_max_rotation' in located.staleness()
