# SPDX-License-Identifier: Apache-2.0
"""RobotPose: the mode chosen, the localizer's messages, and the tf2 path.

tf2_ros is not installable from PyPI, so the tf2 path is checked only here, against a
stand-in with the two methods of tf2_ros.Buffer the nodes call (can_transform with a
timeout, lookup_transform), never against tf2 itself.
"""

from __future__ import annotations

import math

from geometry_msgs.msg import PoseWithCovarianceStamped, TransformStamped
import numpy as np
import pytest
from rclpy.duration import Duration
from rclpy.time import Time

from mpc_local_planner.perception.pose_history import MAX_EXTRAPOLATION_S
from mpc_local_planner.ros.conversions import seconds_to_stamp, yaw_to_quaternion
from mpc_local_planner.ros.robot_pose import (
    choose_mode,
    LocalizationError,
    PoseMode,
    RobotPose,
    TfPose,
)


def test_the_localizer_topic_wins_then_tf2_then_odometry() -> None:
    assert choose_mode('amcl_pose', tf_available=True) is PoseMode.LOCALIZER
    assert choose_mode('amcl_pose', tf_available=False) is PoseMode.LOCALIZER
    assert choose_mode('', tf_available=True) is PoseMode.TF
    assert choose_mode('', tf_available=False) is PoseMode.ODOMETRY


NO_WAIT = Duration()


def transform(x: float, y: float, yaw: float, stamp: float) -> TransformStamped:
    msg = TransformStamped()
    msg.header.frame_id, msg.child_frame_id = 'map', 'base_link'
    msg.header.stamp = seconds_to_stamp(stamp)
    msg.transform.translation.x, msg.transform.translation.y = x, y
    msg.transform.rotation = yaw_to_quaternion(yaw)
    return msg


class StandInBuffer:
    """tf2_ros.Buffer's can_transform and lookup_transform over a list of map -> base_link.

    A time of 0 is the latest (tf2's Time()); another is the transform stamped exactly then.
    The calls are recorded, the timeout with them.
    """

    def __init__(self, transforms: list[TransformStamped]) -> None:
        self.transforms = transforms
        self.calls: list[tuple[str, str, str, float, float | None]] = []

    def _find(self, target: str, source: str, time: Time) -> TransformStamped | None:
        if (target, source) != ('map', 'base_link') or not self.transforms:
            return None
        if time.nanoseconds == 0:
            return self.transforms[-1]
        for t in self.transforms:
            if Time.from_msg(t.header.stamp).nanoseconds == time.nanoseconds:
                return t
        return None

    def can_transform(self, target: str, source: str, time: Time,
                      timeout: Duration = NO_WAIT) -> bool:
        self.calls.append(('can', target, source, time.nanoseconds * 1e-9,
                           timeout.nanoseconds * 1e-9))
        return self._find(target, source, time) is not None

    def lookup_transform(self, target: str, source: str, time: Time,
                         timeout: Duration = NO_WAIT) -> TransformStamped:
        self.calls.append(('lookup', target, source, time.nanoseconds * 1e-9, None))
        found = self._find(target, source, time)
        if found is None:
            raise RuntimeError('LookupException')  # tf2's, as far as the caller can tell
        return found


def test_tf2_gives_the_latest_transform_with_its_stamp_waiting_transform_tolerance() -> None:
    buffer = StandInBuffer([transform(1.0, 2.0, 0.5, 10.0), transform(1.5, 2.0, 0.6, 10.5)])
    source = RobotPose(PoseMode.TF, span=2.0, global_frame='map', buffer=buffer,
                       robot_base_frame='base_link', tolerance=0.25)
    source.add_odometry(10.5, np.array([9.0, 9.0, 0.0]))  # odom: not the pose with tf2
    pose, stamp = source.current(np.array([9.0, 9.0, 0.0]), 10.5)
    np.testing.assert_allclose(pose, [1.5, 2.0, 0.6])
    assert stamp == pytest.approx(10.5)
    assert buffer.calls[0] == ('can', 'map', 'base_link', 0.0, 0.25)  # latest, with timeout
    # a scan's stamp: the transform at that stamp
    np.testing.assert_allclose(source.at(10.0), [1.0, 2.0, 0.5])
    assert buffer.calls[-2][3] == pytest.approx(10.0)


def test_a_missing_transform_is_a_localization_error_naming_the_frames() -> None:
    buffer = StandInBuffer([])
    source = RobotPose(PoseMode.TF, span=2.0, global_frame='map', buffer=buffer,
                       robot_base_frame='base_link', tolerance=0.1)
    assert source.current(None, None) == (None, None)  # no odometry: said as before
    with pytest.raises(LocalizationError, match=r'no transform map -> base_link within '
                                                r'transform_tolerance \(0.1 s\)'):
        source.current(np.zeros(3), 1.0)
    with pytest.raises(LocalizationError, match='at 3.000 s'):
        source.at(3.0)
    other = TfPose(StandInBuffer([transform(0, 0, 0, 1.0)]), global_frame='odom',
                   robot_frame='base_link', tolerance=0.1)
    with pytest.raises(LocalizationError, match='odom -> base_link'):
        other.lookup()


def test_a_transform_that_cannot_be_looked_up_after_all_is_a_localization_error() -> None:
    buffer = StandInBuffer([transform(0.0, 0.0, 0.0, 1.0)])
    buffer.lookup_transform = lambda *args, **kwargs: (_ for _ in ()).throw(
        RuntimeError('ExtrapolationException'))
    tf = TfPose(buffer, global_frame='map', robot_frame='base_link', tolerance=0.1)
    with pytest.raises(LocalizationError, match='ExtrapolationException'):
        tf.lookup()


def localizer_message(x: float, y: float, yaw: float, stamp: float,
                      frame_id: str = 'map') -> PoseWithCovarianceStamped:
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = seconds_to_stamp(stamp)
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation = yaw_to_quaternion(yaw)
    return msg


def test_the_localizer_message_corrects_the_odometry_and_another_frame_is_refused() -> None:
    source = RobotPose(PoseMode.LOCALIZER, span=2.0, global_frame='map', topic='amcl_pose')
    source.add_odometry(1.0, np.array([1.0, 0.0, 0.0]))
    with pytest.raises(LocalizationError, match="no localizer pose yet on 'amcl_pose'"):
        source.current(np.array([1.0, 0.0, 0.0]), 1.0)
    with pytest.raises(ValueError, match="frame 'odom' is not 'map'"):
        source.add_localizer(localizer_message(0, 0, 0, 1.0, frame_id='odom'), 1.0)
    source.add_localizer(localizer_message(1.0, 1.0, math.pi / 2, 1.0), 1.2)
    pose, time = source.current(np.array([2.0, 0.0, 0.0]), 1.5)
    # map <- odom = (1, 1, pi/2) * inverse(1, 0, 0) = (1, 0, pi/2): odom (2, 0) is map (1, 1)
    np.testing.assert_allclose(pose, [1.0, 1.0 + 1.0, math.pi / 2], atol=1e-12)
    assert time == 1.5
    # no stamp: the receipt is the localizer's time
    source.add_localizer(localizer_message(1.0, 0.0, 0.0, 0.0), 1.0)
    np.testing.assert_allclose(source.located.correction, [0.0, 0.0, 0.0], atol=1e-12)


def test_a_localizer_silent_while_the_robot_moves_gives_no_pose_until_it_speaks() -> None:
    source = RobotPose(PoseMode.LOCALIZER, span=2.0, global_frame='map', topic='amcl_pose',
                       max_travel=1.0, max_rotation=0.8)
    for k in range(11):  # 0.5 m/s from 0 to 1 s
        source.add_odometry(k / 10, np.array([k / 20, 0.0, 0.0]), twist=(0.5, 0.0))
    source.add_localizer(localizer_message(0.0, 0.0, 0.0, 0.0), 0.0)
    assert source.current(np.array([0.5, 0.0, 0.0]), 1.0)[0] is not None
    for k in range(11, 23):  # 1.1 m since the localizer's stamp
        source.add_odometry(k / 10, np.array([k / 20, 0.0, 0.0]), twist=(0.5, 0.0))
    with pytest.raises(LocalizationError, match="no localizer pose on 'amcl_pose' while the "
                                                'odometry moved 1.10 m'):
        source.current(np.array([1.1, 0.0, 0.0]), 2.2)
    source.add_localizer(localizer_message(1.1, 0.0, 0.0, 2.2), 2.2)
    pose, _ = source.current(np.array([1.1, 0.0, 0.0]), 2.2)
    np.testing.assert_allclose(pose, [1.1, 0.0, 0.0], atol=1e-12)


def test_without_localizer_or_tf2_the_odometry_is_the_pose_unchanged() -> None:
    source = RobotPose(PoseMode.ODOMETRY, span=2.0, global_frame='map')
    odom = np.array([1.0, 2.0, 3.0])
    source.add_odometry(1.0, odom)
    pose, time = source.current(odom, 0.9)
    np.testing.assert_array_equal(pose, odom)
    assert time == 0.9
    np.testing.assert_array_equal(source.at(1.0), odom)


def test_with_tf2_odometry_already_in_the_plan_frame_is_the_pose_without_a_lookup() -> None:
    buffer = StandInBuffer([])  # no transform at all
    source = RobotPose(PoseMode.TF, span=2.0, global_frame='map', buffer=buffer,
                       robot_base_frame='base_link', tolerance=0.1)
    odom = np.array([1.0, 2.0, 0.3])
    source.add_odometry(1.0, odom, 'map')  # the exact simulator's odometry
    pose, time = source.current(odom, 1.0)
    np.testing.assert_array_equal(pose, odom)
    np.testing.assert_array_equal(source.at(1.0), odom)
    assert buffer.calls == []
    source.add_odometry(1.1, odom, 'odom')  # odometry in odom: tf2 again
    with pytest.raises(LocalizationError, match='no transform'):
        source.current(odom, 1.1)


def test_a_scan_stamp_past_the_odometry_is_extrapolated_along_its_twist_then_waits() -> None:
    source = RobotPose(PoseMode.ODOMETRY, span=2.0, global_frame='map')
    assert source.at(1.0) is None  # no odometry: not yet
    source.add_odometry(1.0, np.array([1.0, 0.0, 0.0]), 'map', (1.0, 0.0))
    np.testing.assert_allclose(source.at(1.08), [1.08, 0.0, 0.0], atol=1e-12)
    assert source.at(1.0 + MAX_EXTRAPOLATION_S + 0.01) is None  # beyond the bound: wait
    source.add_odometry(1.5, np.array([1.5, 0.0, 0.0]), 'map', (1.0, 0.0))
    np.testing.assert_allclose(source.at(1.45), [1.45, 0.0, 0.0], atol=1e-12)


def test_with_a_localizer_the_extrapolated_odometry_is_corrected_at_the_stamp() -> None:
    source = RobotPose(PoseMode.LOCALIZER, span=2.0, global_frame='map', topic='amcl_pose')
    source.add_odometry(1.0, np.array([1.0, 0.0, 0.0]), 'odom', (1.0, 0.0))
    source.add_localizer(localizer_message(1.0, 1.0, math.pi / 2, 1.0), 1.0)
    # map <- odom = (1, 0, pi/2); odom at 1.1 s is (1.1, 0, 0): in map (1, 1.1, pi/2)
    np.testing.assert_allclose(source.at(1.1), [1.0, 1.1, math.pi / 2], atol=1e-12)
    assert source.at(1.3) is None
    # a localizer stamp past the bound still gives a correction (with the newest odometry)
    source.add_localizer(localizer_message(0.0, 0.0, 0.0, 1.3), 1.3)
    np.testing.assert_allclose(source.located.correction, [-1.0, 0.0, 0.0], atol=1e-12)


def test_with_tf2_a_stamp_newer_than_the_latest_transform_is_not_yet() -> None:
    buffer = StandInBuffer([transform(1.0, 2.0, 0.5, 10.0)])
    source = RobotPose(PoseMode.TF, span=2.0, global_frame='map', buffer=buffer,
                       robot_base_frame='base_link', tolerance=0.1)
    assert source.at(10.2) is None  # the transform at 10.2 may still come: wait
    buffer.transforms.append(transform(1.2, 2.0, 0.5, 10.2))
    np.testing.assert_allclose(source.at(10.2), [1.2, 2.0, 0.5])
    with pytest.raises(LocalizationError, match='at 10.100 s'):
        source.at(10.1)  # older than the latest, and not there: it will not come
