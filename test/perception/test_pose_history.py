import math

import numpy as np
import pytest

from mpc_local_planner.perception.pose_history import PoseHistory


def test_a_pose_between_two_is_interpolated_and_turns_the_short_way() -> None:
    history = PoseHistory(span=2.0)
    history.add(1.0, np.array([0.0, 0.0, math.pi - 0.1]))
    history.add(1.2, np.array([0.2, 0.4, -math.pi + 0.1]))  # 0.2 rad turn across +-pi
    pose = history.at(1.05)
    np.testing.assert_allclose(pose[:2], [0.05, 0.1])
    assert pose[2] == pytest.approx(math.pi - 0.05)


def test_outside_the_history_the_nearest_end_is_used_without_extrapolation() -> None:
    history = PoseHistory(span=2.0)
    assert history.at(0.0) is None
    history.add(1.0, np.array([1.0, 0.0, 0.0]))
    history.add(2.0, np.array([2.0, 0.0, 0.0]))
    np.testing.assert_allclose(history.at(0.5), [1.0, 0.0, 0.0])
    np.testing.assert_allclose(history.at(9.0), [2.0, 0.0, 0.0])


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
    np.testing.assert_allclose(history.at(10.0), [5.0, 5.0, 0.0])


def test_the_gap_is_the_time_to_the_nearest_pose_kept() -> None:
    history = PoseHistory(span=2.0)
    assert history.gap(1.0) == math.inf
    history.add(1.0, np.zeros(3))
    history.add(1.5, np.zeros(3))
    assert history.gap(1.1) == pytest.approx(0.1)
    assert history.gap(1.4) == pytest.approx(0.1)
    assert history.gap(0.2) == pytest.approx(0.8)
    assert history.gap(3.0) == pytest.approx(1.5)
