# SPDX-License-Identifier: Apache-2.0
"""Where the robot is in the plan's frame, for the controller and the planner node alike.

The plan is in ``map``; odometry is in ``odom`` and drifts. Three ways to the pose in the
plan's frame (``global_frame``), chosen at configure (`choose_mode`):

* a localizer's pose topic (``localization_topic``, geometry_msgs/PoseWithCovarianceStamped
  in ``global_frame``, as AMCL's ``amcl_pose``): its correction map <- odom is applied to the
  odometry (perception/localization.py, ROS-free). Chosen whenever the topic is set.
* tf2 (``tf2_ros`` importable, i.e. a sourced ROS install): ``global_frame ->
  robot_base_frame`` (Nav2's names, as its costmaps and controller_server use them) is
  looked up, waiting at most ``transform_tolerance`` (Nav2's name) for the latest one.
  Checked here only against a stand-in of the buffer's interface (``can_transform``,
  ``lookup_transform``), never against tf2_ros itself: tf2 is not installable from PyPI.
* neither: the odometry is the pose in the plan's frame (the simulator, whose ``odom`` is
  ``map``), exactly as before. So is odometry whose header.frame_id IS ``global_frame``, with
  tf2 too (closed_loop's exact simulator publishes it so): there is nothing to look up.

With a localizer or tf2 and no pose (no localizer message yet, one older than the odometry
kept, no transform) the controller stops and says why; the planner waits. So they do when
the localizer falls silent while the robot moves: after ``localization_max_travel`` m or
``localization_max_rotation`` rad of odometry since its last pose's stamp (AMCL publishes
after 0.25 m or 0.2 rad of motion, and nothing at rest, so a time limit would not fit it).

A scan's stamp (`RobotPose.at`) is often newer than the latest odometry. Within
MAX_EXTRAPOLATION_S of it the odometry is extrapolated along its twist (PoseHistory.at; the
localizer's correction is then applied as at any stamp: only odometry is extrapolated);
beyond, ``at`` says "not yet" (None) and the nodes keep the scan until odometry covering
its stamp has come. With tf2, a stamp newer than the latest transform is "not yet" too
(tf2 does not extrapolate): the nodes wait for it the same way.
"""

from __future__ import annotations

from enum import Enum
from typing import Any, Protocol

from geometry_msgs.msg import PoseWithCovarianceStamped, TransformStamped
import numpy as np
from rclpy.duration import Duration
from rclpy.time import Time

from mpc_local_planner.perception.localization import LocalizationError, LocalizedPose
from mpc_local_planner.ros.conversions import (
    frame_problem,
    pose_to_array,
    quaternion_to_yaw,
    stamp_to_seconds,
)
from mpc_local_planner.ros.parameters import ParameterSpec

try:  # a sourced ROS install; PyPI has no tf2_ros
    import tf2_ros
except ImportError:  # pragma: no cover - depends on the installation
    tf2_ros = None

__all__ = ['LocalizationError', 'ODOM_HISTORY_S', 'PENDING_SCANS', 'PoseMode', 'pose_parameters',
           'RobotPose', 'TF_AVAILABLE', 'TfPose', 'choose_mode', 'make_buffer',
           'transform_to_pose']

TF_AVAILABLE = tf2_ros is not None
# Seconds of odometry both nodes keep (RobotPose's span), to place each scan and localizer
# pose at its stamp.
ODOM_HISTORY_S = 2.0
# Scans a node keeps waiting for odometry that covers their stamps (the latest; an older one
# falls out). A few: at 10-40 Hz, three scans span 75-300 ms, more than odometry is normally
# late, and a waiting scan too old is discarded anyway.
PENDING_SCANS = 3

def pose_parameters(without_pose: str) -> tuple[ParameterSpec, ...]:
    """Return the parameters both nodes declare for the pose (besides the frames).

    Args:
        without_pose: what the node does while it has no pose in global_frame (the
            localizer silent or lost, no transform), as its descriptions say it.

    """
    return (
        ParameterSpec('localization_topic', '',
                      "a localizer's pose topic (geometry_msgs/PoseWithCovarianceStamped in "
                      "global_frame, as AMCL's amcl_pose), composed with odometry as the pose "
                      "in global_frame; '' = none: tf2's global_frame -> robot_base_frame if "
                      'tf2_ros is importable, else the odometry is that pose; read at '
                      'configure'),
        ParameterSpec('localization_max_travel', 1.0,
                      'with localization_topic, how far (m) the odometry may move from its '
                      "pose at the last localizer pose's stamp (net, as AMCL measures) before "
                      f'the localizer is taken as silent or lost: {without_pose} until its '
                      "next pose; 4 x AMCL's update_min_d; 0 = no limit; read at configure",
                      float_range=(0.0, 1000.0)),
        ParameterSpec('localization_max_rotation', 0.8,
                      'with localization_topic, the same for the odometry rotation (rad); 4 x '
                      "AMCL's update_min_a; 0 = no limit; read at configure",
                      float_range=(0.0, 1000.0)),
        ParameterSpec('transform_tolerance', 0.1,
                      'with tf2, how long (s) to wait for global_frame -> robot_base_frame '
                      f"(Nav2's name); none by then: {without_pose} until one comes",
                      float_range=(0.0, 10.0)),
    )


class PoseMode(Enum):
    """Where the pose in the plan's frame comes from."""

    ODOMETRY = 'odometry'  # the odometry's frame is the plan's
    LOCALIZER = 'localizer'  # odometry corrected by a localizer's pose topic
    TF = 'tf'  # tf2's global_frame -> robot_base_frame


def choose_mode(localization_topic: str, *, tf_available: bool = TF_AVAILABLE) -> PoseMode:
    """Return the mode: the localizer if its topic is set, else tf2 if there, else odometry."""
    if localization_topic:
        return PoseMode.LOCALIZER
    return PoseMode.TF if tf_available else PoseMode.ODOMETRY


class TransformBuffer(Protocol):
    """What is used of tf2_ros.Buffer."""

    def can_transform(self, target_frame: str, source_frame: str, time: Time,
                      timeout: Duration = ...) -> bool: ...

    def lookup_transform(self, target_frame: str, source_frame: str, time: Time,
                         timeout: Duration = ...) -> TransformStamped: ...


def transform_to_pose(transform: TransformStamped) -> tuple[np.ndarray, float]:
    """Return the planar pose (x, y, yaw) of a transform and its stamp (seconds).

    Raises:
        ValueError: on a non-finite translation or a rotation without orientation.

    """
    t = transform.transform
    pose = np.array([t.translation.x, t.translation.y, quaternion_to_yaw(t.rotation)],
                    dtype=float)
    if not np.all(np.isfinite(pose)):
        problem = f'transform {pose.tolist()} is not finite'
        raise ValueError(problem)
    return pose, stamp_to_seconds(transform.header.stamp)


class TfPose:
    """The robot's pose from a tf2 buffer: global_frame -> robot_frame.

    Args:
        buffer: a tf2_ros.Buffer (or a stand-in with its can_transform, lookup_transform).
        global_frame: the plan's frame.
        robot_frame: the robot's frame.
        tolerance: seconds to wait for the latest transform.

    """

    def __init__(self, buffer: TransformBuffer, *, global_frame: str, robot_frame: str,
                 tolerance: float) -> None:
        self.buffer = buffer
        self.global_frame = global_frame
        self.robot_frame = robot_frame
        self.tolerance = float(tolerance)

    def lookup(self, stamp: float | None = None) -> tuple[np.ndarray, float]:
        """Return the pose and its stamp: the latest (stamp None) or at stamp (a scan's).

        Waits up to tolerance for it (a scan's stamp is often newer than the latest
        odom -> base_link, as Nav2's message filters wait); this blocks the node's callback.

        Raises:
            LocalizationError: if the transform is not there (in time).

        """
        time = Time() if stamp is None else Time(nanoseconds=int(round(stamp * 1e9)))
        timeout = Duration(seconds=self.tolerance)
        frames = f'{self.global_frame} -> {self.robot_frame}'
        if not self.buffer.can_transform(self.global_frame, self.robot_frame, time, timeout):
            when = '' if stamp is None else f' at {stamp:.3f} s'
            problem = (f'no transform {frames}{when} within transform_tolerance '
                       f'({self.tolerance:g} s)')
            raise LocalizationError(problem)
        try:
            return transform_to_pose(self.buffer.lookup_transform(
                self.global_frame, self.robot_frame, time))
        except Exception as err:  # tf2's LookupException and kin, a malformed transform
            problem = f'transform {frames}: {err or type(err).__name__}'
            raise LocalizationError(problem) from None

    def at(self, stamp: float) -> np.ndarray | None:
        """Return the pose at stamp, or None if the transforms have not reached it yet.

        A stamp with no transform (after waiting up to tolerance) but newer than the latest
        one is "not yet" (tf2 does not extrapolate; the transform may still come). Any
        other failure is the lookup's LocalizationError.

        Raises:
            LocalizationError: if there is no transform at stamp and the latest is not older.

        """
        try:
            return self.lookup(stamp)[0]
        except LocalizationError:
            latest = Time()
            if not self.buffer.can_transform(self.global_frame, self.robot_frame, latest,
                                             Duration()):
                raise
            try:
                _, newest = transform_to_pose(self.buffer.lookup_transform(
                    self.global_frame, self.robot_frame, latest))
            except Exception:  # the latest cannot be read either: the first error stands
                newest = stamp
            if newest < stamp:
                return None
            raise


class RobotPose:
    """A node's pose in the plan's frame: odometry in, poses out (its mode's way).

    Args:
        mode: the PoseMode.
        span: seconds of odometry kept (scans' and the localizer's stamps are looked up in it).
        global_frame: the plan's frame (the localizer's messages must be in it).
        topic: the localizer's topic (LOCALIZER).
        buffer: the tf2 buffer (TF; required then).
        robot_base_frame: the robot's frame (TF).
        tolerance: transform_tolerance (TF).
        max_travel: localization_max_travel (LOCALIZER; 0 = no limit).
        max_rotation: localization_max_rotation (LOCALIZER; 0 = no limit).

    """

    def __init__(self, mode: PoseMode, *, span: float, global_frame: str, topic: str = '',
                 buffer: TransformBuffer | None = None, robot_base_frame: str = 'base_link',
                 tolerance: float = 0.1, max_travel: float = 0.0,
                 max_rotation: float = 0.0) -> None:
        self.mode = mode
        self.global_frame = global_frame
        self.located = LocalizedPose(span, localized=mode is PoseMode.LOCALIZER, source=topic,
                                     max_travel=max_travel, max_rotation=max_rotation)
        self.tf: TfPose | None = None
        self._odom_in_plan_frame = False  # the latest odometry's frame is global_frame
        if mode is PoseMode.TF:
            if buffer is None:
                problem = 'tf2 mode needs a transform buffer'
                raise ValueError(problem)
            self.tf = TfPose(buffer, global_frame=global_frame, robot_frame=robot_base_frame,
                             tolerance=tolerance)

    def describe(self) -> str:
        """Say where the pose comes from, for the log at configure."""
        if self.mode is PoseMode.LOCALIZER:
            return (f'the odometry corrected by the localizer on {self.located.source!r} '
                    f'(pose in {self.global_frame!r})')
        if self.tf is not None:
            return f'tf2: {self.tf.global_frame} -> {self.tf.robot_frame}'
        return f'the odometry, taken as the pose in {self.global_frame!r}'

    def clear(self) -> None:
        """Forget the odometry and the localizer's correction."""
        self.located.clear()

    def add_odometry(self, time: float, pose: np.ndarray, frame_id: str = '',
                     twist: np.ndarray | tuple[float, float] | None = None) -> None:
        """Keep an odometry pose and its twist (for scans' stamps and the localizer's).

        The twist (v, omega; None or not finite: unknown) lets a scan stamped just after
        this pose be placed without waiting (PoseHistory.at).
        """
        self.located.add_odometry(time, pose, twist)
        self._odom_in_plan_frame = frame_id == self.global_frame

    @property
    def _tf(self) -> TfPose | None:
        """The tf2 lookup in force: none when the odometry is in the plan's frame already."""
        return None if self._odom_in_plan_frame else self.tf

    def add_localizer(self, msg: PoseWithCovarianceStamped, receipt: float) -> np.ndarray:
        """Take a localizer message (its stamp, or the receipt if unset); return the correction.

        Raises:
            ValueError: if it is in another frame or not a pose; LocalizationError (a
                ValueError) if the odometry kept cannot place it: no pose until one can.

        """
        problem = frame_problem(msg.header.frame_id, self.global_frame, 'localizer poses')
        if problem is not None:
            raise ValueError(problem)
        pose = pose_to_array(msg.pose.pose)
        stamp = stamp_to_seconds(msg.header.stamp)
        return self.located.add_localizer(stamp if stamp > 0 else receipt, pose)

    def current(self, odom: np.ndarray | None, odom_time: float | None
                ) -> tuple[np.ndarray | None, float | None]:
        """Return the pose in the plan's frame now and when it was measured.

        (None, None) without odometry (the controller says no odometry, as before).

        Raises:
            LocalizationError: if there is odometry but no pose in the plan's frame, or the
                localizer's correction is stale (LocalizedPose.staleness).

        """
        if odom is None:
            return None, None
        if self._tf is not None:
            return self._tf.lookup()
        pose = self.located.pose(odom)
        if pose is None:
            raise LocalizationError(self.located.problem or 'no localizer pose')
        stale = self.located.staleness()
        if stale is not None:
            raise LocalizationError(stale)
        return pose, odom_time

    def at(self, stamp: float) -> np.ndarray | None:
        """Return the pose in the plan's frame at stamp (a scan's); None: not yet, wait.

        None without odometry, for a stamp more than MAX_EXTRAPOLATION_S past the newest
        odometry (or past it at all when its twist is unknown), and with tf2 for a stamp
        newer than the latest transform: the pose at the stamp is not known yet, and an
        older one is not where the robot was (a scan placed with it is displaced).

        Raises:
            LocalizationError: if there is odometry at stamp but no pose in the plan's
                frame (no localizer correction), or no transform that can ever come.

        """
        if self._tf is not None:
            return self._tf.at(stamp)
        odom = self.located.odometry.at(stamp)
        if odom is None:
            return None
        pose = self.located.pose(odom)
        if pose is None:
            raise LocalizationError(self.located.problem or 'no localizer pose')
        return pose

    @property
    def problem(self) -> str | None:
        """Why there is no pose from the localizer (None: there is, or no localizer)."""
        return self.located.problem


def make_buffer(node: Any) -> tuple[Any, Any]:
    """Return a tf2_ros Buffer and the TransformListener filling it (its own spin thread).

    Raises:
        RuntimeError: if tf2_ros is not importable.

    """
    if tf2_ros is None:
        problem = 'tf2_ros is not importable (source a ROS install)'
        raise RuntimeError(problem)
    buffer = tf2_ros.Buffer()
    return buffer, tf2_ros.TransformListener(buffer, node, spin_thread=True)
