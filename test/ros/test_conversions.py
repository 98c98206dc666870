# SPDX-License-Identifier: Apache-2.0
"""Messages <-> NumPy: quaternions, paths, odometry and twists (no rclpy context needed)."""

from __future__ import annotations

import math

from geometry_msgs.msg import Quaternion, Twist
from hypothesis import given
from hypothesis import strategies as st
import numpy as np
import pytest

from mpc_local_planner.ros.conversions import (
    odometry_to_state,
    path_to_poses,
    poses_to_path,
    quaternion_to_yaw,
    seconds_to_stamp,
    stamp_to_seconds,
    state_to_odometry,
    twist_from_u,
    u_from_twist,
    yaw_to_quaternion,
)

angles = st.floats(min_value=-50.0, max_value=50.0, allow_nan=False)


@given(angles)
def test_yaw_survives_a_round_trip_through_a_quaternion_modulo_two_pi(yaw: float) -> None:
    back = quaternion_to_yaw(yaw_to_quaternion(yaw))
    assert -math.pi <= back <= math.pi
    assert math.isclose(math.remainder(back - yaw, 2 * math.pi), 0.0, abs_tol=1e-9)


def test_quaternion_to_yaw_normalises_a_scaled_quaternion() -> None:
    q = yaw_to_quaternion(0.7)
    scaled = Quaternion(x=3 * q.x, y=3 * q.y, z=3 * q.z, w=3 * q.w)
    assert quaternion_to_yaw(scaled) == pytest.approx(0.7)


def test_an_unset_zero_quaternion_raises_value_error() -> None:
    with pytest.raises(ValueError, match='zero norm'):
        quaternion_to_yaw(Quaternion(x=0.0, y=0.0, z=0.0, w=0.0))


def test_a_nan_quaternion_raises_value_error() -> None:
    with pytest.raises(ValueError, match='no orientation'):
        quaternion_to_yaw(Quaternion(x=0.0, y=0.0, z=math.nan, w=1.0))


def test_non_finite_yaw_is_refused() -> None:
    with pytest.raises(ValueError, match='finite'):
        yaw_to_quaternion(math.inf)


def test_poses_survive_a_round_trip_through_nav_msgs_path() -> None:
    poses = np.array([[0.0, 0.0, 0.3], [1.0, -2.0, -3.0], [2.5, 0.1, 3.1]])
    msg = poses_to_path(poses, frame_id='map', stamp=seconds_to_stamp(12.5))
    assert msg.header.frame_id == 'map'
    assert stamp_to_seconds(msg.poses[1].header.stamp) == pytest.approx(12.5)
    np.testing.assert_allclose(path_to_poses(msg), poses, atol=1e-12)


def test_an_empty_path_gives_zero_poses() -> None:
    assert path_to_poses(poses_to_path(np.zeros((0, 3)))).shape == (0, 3)


def test_poses_to_path_refuses_the_wrong_shape_and_nan() -> None:
    with pytest.raises(ValueError, match='shape'):
        poses_to_path(np.zeros((3, 2)))
    with pytest.raises(ValueError, match='NaN'):
        poses_to_path(np.array([[0.0, math.nan, 0.0]]))


def test_path_to_poses_refuses_a_pose_without_orientation() -> None:
    msg = poses_to_path(np.zeros((2, 3)))
    msg.poses[1].pose.orientation = Quaternion(x=0.0, y=0.0, z=0.0, w=0.0)
    with pytest.raises(ValueError, match='zero norm'):
        path_to_poses(msg)


def test_odometry_carries_the_state_and_the_twist_in_the_robot_frame() -> None:
    odom = state_to_odometry(np.array([1.0, 2.0, -2.5]), np.array([0.2, -0.4]),
                             stamp=seconds_to_stamp(3.0))
    assert (odom.header.frame_id, odom.child_frame_id) == ('odom', 'base_link')
    np.testing.assert_allclose(odometry_to_state(odom), [1.0, 2.0, -2.5])
    np.testing.assert_allclose(u_from_twist(odom.twist.twist), [0.2, -0.4])


def test_twist_maps_v_to_linear_x_and_omega_to_angular_z() -> None:
    twist = twist_from_u([0.3, -1.2])
    assert (twist.linear.x, twist.angular.z) == (0.3, -1.2)
    assert (twist.linear.y, twist.linear.z, twist.angular.x, twist.angular.y) == (0, 0, 0, 0)


def test_a_non_finite_twist_becomes_a_zero_command() -> None:
    twist = Twist()
    twist.linear.x = math.nan
    twist.angular.z = 0.5
    np.testing.assert_array_equal(u_from_twist(twist), [0.0, 0.5])


def test_stamps_round_trip_and_refuse_negative_times() -> None:
    stamp = seconds_to_stamp(1.75)
    assert (stamp.sec, stamp.nanosec) == (1, 750_000_000)
    assert stamp_to_seconds(stamp) == pytest.approx(1.75)
    with pytest.raises(ValueError, match='>= 0'):
        seconds_to_stamp(-1.0)
