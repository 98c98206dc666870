# SPDX-License-Identifier: Apache-2.0
import math

import numpy as np
import pytest

from mpc_local_planner.core.models import unicycle_arc
from mpc_local_planner.perception.pose_history import (
    MAX_EXTRAPOLATION_S,
    PoseHistory,
)


def test_a_pose_between_two_is_interpolated_and_turns_the_short_way() -> None:
    history = PoseHistory(span=2.0)
    history.add(1.0, np.array([0.0, 0.0, math.pi - 0.1]))
    history.add(1.2, np.array([0.2, 0.4, -math.pi + 0.1]))  # 0.2 rad turn across +-pi
    pose = history.at(1.05)
    np.testing.assert_allclose(pose[:2], [0.05, 0.1])
    assert pose[2] == pytest.approx(math.pi - 0.05)


def test_before_the_history_the_oldest_is_used_and_after_it_without_a_twist_nothing() -> None:
    history = PoseHistory(span=2.0)
    assert history.at(0.0) is None
    history.add(1.0, np.array([1.0, 0.0, 0.0]))
    history.add(2.0, np.array([2.0, 0.0, 0.0]))  # no twist: unknown, nothing extrapolated
    np.testing.assert_allclose(history.at(0.5), [1.0, 0.0, 0.0])
    np.testing.assert_allclose(history.at(2.0), [2.0, 0.0, 0.0])
    assert history.at(2.01) is None  # not the stale pose: not yet
    history.add(2.5, np.array([2.5, 0.0, 0.0]), (np.nan, 0.0))  # a twist that is not finite
    assert history.at(2.51) is None


def test_a_stamp_just_past_the_newest_pose_is_extrapolated_along_a_straight_line() -> None:
    history = PoseHistory(span=2.0)
    history.add(1.0, np.array([0.0, 0.0, 0.0]), (1.0, 0.0))
    history.add(1.05, np.array([0.05, 0.0, math.pi / 6]), (1.0, 0.0))
    pose = history.at(1.13)  # 80 ms after the newest at 1 m/s, heading 30 degrees
    np.testing.assert_allclose(pose, [0.05 + 0.08 * math.cos(math.pi / 6),
                                      0.08 * math.sin(math.pi / 6), math.pi / 6], atol=1e-12)
    np.testing.assert_allclose(unicycle_arc(np.array([0.0, 0.0, 0.0]), 1.0, 0.0, 0.1),
                               [0.1, 0.0, 0.0], atol=1e-15)


def test_a_stamp_past_the_newest_pose_follows_the_arc_of_its_twist() -> None:
    history = PoseHistory(span=2.0)
    v, omega = 0.5, 2.0  # an arc of radius 0.25 m
    history.add(1.0, np.array([1.0, 2.0, 0.0]), (v, omega))
    pose = history.at(1.0 + MAX_EXTRAPOLATION_S)
    turn = omega * MAX_EXTRAPOLATION_S
    # on the circle around (1, 2.25): the exact arc, not the chord nor the tangent
    np.testing.assert_allclose(pose, [1.0 + 0.25 * math.sin(turn),
                                      2.0 + 0.25 * (1.0 - math.cos(turn)), turn], atol=1e-12)
    assert math.hypot(pose[0] - 1.0, pose[1] - 2.25) == pytest.approx(0.25)
    # a vanishing yaw rate is the straight line, continuously
    np.testing.assert_allclose(unicycle_arc(np.array([0.0, 0.0, 0.3]), 1.0, 1e-7, 0.1),
                               unicycle_arc(np.array([0.0, 0.0, 0.3]), 1.0, 0.0, 0.1),
                               atol=1e-9)


def test_a_stamp_beyond_the_extrapolation_bound_is_not_yet_never_the_stale_pose() -> None:
    assert 0.05 <= MAX_EXTRAPOLATION_S <= 0.1  # about two odometry periods at 20-50 Hz
    history = PoseHistory(span=2.0)
    history.add(1.0, np.array([1.0, 0.0, 0.0]), (1.0, 0.0))
    assert history.at(1.0 + MAX_EXTRAPOLATION_S + 1e-6) is None
    assert history.at(1.5) is None
    history.add(1.5, np.array([1.5, 0.0, 0.0]), (1.0, 0.0))  # odometry covering it came
    np.testing.assert_allclose(history.at(1.5), [1.5, 0.0, 0.0])
    np.testing.assert_allclose(history.at(1.25), [1.25, 0.0, 0.0])  # interpolated, as before
    tight = PoseHistory(span=2.0, max_extrapolation=0.0)
    tight.add(1.0, np.zeros(3), (1.0, 0.0))
    assert tight.at(1.001) is None


def test_out_of_order_poses_are_sorted_in_and_old_ones_dropped() -> None:
    history = PoseHistory(span=1.0)
    history.add(1.0, np.array([1.0, 0.0, 0.0]))
    history.add(3.0, np.array([3.0, 0.0, 0.0]))
    history.add(2.5, np.array([2.5, 0.0, 0.0]))  # late, but within the span: kept in order
    assert len(history) == 2  # 1.0 is more than a span older than 3.0
    np.testing.assert_allclose(history.at(2.75), [2.75, 0.0, 0.0])


def test_a_clock_that_jumps_back_clears_the_history() -> None:
    history = PoseHistory(span=1.0)
    history.add(10.0, np.array([1.0, 0.0, 0.0]))
    history.add(2.0, np.array([5.0, 5.0, 0.0]))
    assert len(history) == 1
    np.testing.assert_allclose(history.at(2.0), [5.0, 5.0, 0.0])
    assert history.at(10.0) is None  # the old time is not covered by the new poses


def test_the_gap_is_the_time_to_the_nearest_pose_kept() -> None:
    history = PoseHistory(span=2.0)
    assert history.gap(1.0) == math.inf
    history.add(1.0, np.zeros(3))
    history.add(1.5, np.zeros(3))
    assert history.gap(1.1) == pytest.approx(0.1)
    assert history.gap(1.4) == pytest.approx(0.1)
    assert history.gap(0.2) == pytest.approx(0.8)
    assert history.gap(3.0) == pytest.approx(1.5)
