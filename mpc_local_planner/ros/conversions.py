# SPDX-License-Identifier: Apache-2.0
"""Messages <-> NumPy: planar poses, quaternions, paths, odometry and velocity commands.

Everything here is a pure function of its arguments (no node, no clock), so the tests need
no rclpy context. Planar means: z = 0, roll = pitch = 0, yaw = rotation about +z (REP-103).
"""

from __future__ import annotations

import math
import struct
from typing import Sequence

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import (
    Point,
    Point32,
    PolygonStamped,
    Pose,
    PoseStamped,
    Quaternion,
    Twist,
    TwistStamped,
)
from nav_msgs.msg import OccupancyGrid, Odometry, Path
import numpy as np
from sensor_msgs.msg import LaserScan
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker

from mpc_local_planner.perception.grids import grid_from_fields, GridError
from mpc_local_planner.perception.scans import Scan
from mpc_local_planner.worlds.map_files import OccupancyMap

__all__ = [
    'arrow_marker',
    'cylinder_marker',
    'delete_all_marker',
    'diagnostic_array',
    'frame_problem',
    'SCANS',
    'grid_from_message',
    'measured_time',
    'scan_beam_count',
    'scan_from_message',
    'odometry_to_state',
    'odometry_twist',
    'path_pose_count',
    'path_to_poses',
    'pose_to_array',
    'polygon_marker',
    'polygon_stamped',
    'poses_to_path',
    'quaternion_to_yaw',
    'seconds_to_stamp',
    'stamp_to_seconds',
    'state_to_odometry',
    'twist_from_u',
    'twist_stamped_from_u',
    'u_from_twist',
    'yaw_to_quaternion',
]

# What frame_problem says of scans: the nodes place a scan with laser_pose, not with tf.
SCANS = 'scans: laser_pose says where the laser sits'
# A quaternion shorter than this carries no orientation (an unset message is all zeros).
MIN_QUATERNION_NORM = 1e-9


def frame_problem(frame_id: str, expected: str, what: str) -> str | None:
    """Return why a message in frame_id is refused where expected is needed (None: it is not).

    The one frame rule of the nodes: they do not transform messages between frames (a pose
    in the plan's frame comes from ros/robot_pose.py instead).

    Args:
        frame_id: the message's header.frame_id.
        expected: the frame it must be in.
        what: what the message is, plural ('plans', 'scans', ...), for the reason.

    """
    if frame_id == expected:
        return None
    return f'frame {frame_id!r} is not {expected!r} (this node does not transform {what})'


def yaw_to_quaternion(yaw: float) -> Quaternion:
    """Return the unit quaternion of a rotation by yaw about +z.

    Raises:
        ValueError: if yaw is not finite.

    """
    yaw = float(yaw)
    if not math.isfinite(yaw):
        msg = f'yaw must be finite, got {yaw}'
        raise ValueError(msg)
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def quaternion_to_yaw(q: Quaternion) -> float:
    """Return the yaw in [-pi, pi] of a quaternion (normalised first).

    Raises:
        ValueError: if the quaternion has (almost) zero norm or non-finite components, as
            an unset ``orientation`` has.

    """
    values = np.array([q.x, q.y, q.z, q.w], dtype=float)
    finite = bool(np.all(np.isfinite(values)))
    scale = float(np.max(np.abs(values))) if finite else 0.0
    # scaled first: the norm of components near 1e308 overflows, and 1/inf would give 0
    norm = scale * float(np.linalg.norm(values / scale)) if scale > 0 else 0.0
    if not finite or norm < MIN_QUATERNION_NORM:
        msg = f'quaternion ({q.x}, {q.y}, {q.z}, {q.w}) has no orientation (zero norm or NaN)'
        raise ValueError(msg)
    x, y, z, w = values / scale / (norm / scale)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def pose_to_array(pose: Pose) -> np.ndarray:
    """Return (x, y, yaw) of a pose.

    Raises:
        ValueError: on a zero-norm orientation or a non-finite position.

    """
    xy = (float(pose.position.x), float(pose.position.y))
    if not all(map(math.isfinite, xy)):
        msg = f'pose position must be finite, got {xy}'
        raise ValueError(msg)
    return np.array([xy[0], xy[1], quaternion_to_yaw(pose.orientation)])


def stamp_to_seconds(stamp: Time) -> float:
    """Return a builtin_interfaces/Time in seconds."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def measured_time(stamp: float, receipt: float) -> float:
    """Return when a message was measured: its stamp, but never later than its arrival.

    A stamp from the future must not keep the data fresh after it stops coming; an unset
    stamp (0) is taken as the arrival. The controller and the planner judge odometry's age
    from this (core.controller_settings.is_stale).
    """
    return min(stamp, receipt) if stamp > 0 else receipt


def seconds_to_stamp(seconds: float) -> Time:
    """Return seconds as a builtin_interfaces/Time.

    Raises:
        ValueError: unless 0 <= seconds < 2**31 (Time.sec is an int32; NaN and inf too).

    """
    value = float(seconds)
    if not 0.0 <= value < 2.0**31:
        msg = f'a stamp must be >= 0 s and < 2**31 s, got {seconds}'
        raise ValueError(msg)
    nanoseconds = int(round(value * 1e9))
    sec = min(nanoseconds // 1_000_000_000, 2**31 - 1)
    return Time(sec=sec, nanosec=nanoseconds - sec * 1_000_000_000)


def path_to_poses(path: Path) -> np.ndarray:
    """Return the (M, 3) poses (x, y, yaw) of a nav_msgs/Path.

    Raises:
        ValueError: if a pose has a zero-norm orientation or a non-finite position.

    """
    if not path.poses:
        return np.zeros((0, 3))
    return np.array([pose_to_array(p.pose) for p in path.poses])


def _sequence_length_after_header(data: bytes, *, skip: int) -> int | None:
    """Return the uint32 sequence length that follows a std_msgs/Header and skip bytes.

    CDR: a 4-byte encapsulation header (byte 1 is 1 for little endian), then the Header's
    stamp (8 bytes) and frame_id (uint32 length with the NUL, then the characters, padded to
    4), then skip bytes of fixed fields, then the sequence length. None if data is too short
    or not CDR.
    """
    if len(data) < 16 or data[0] != 0 or data[1] not in (0, 1):
        return None
    order = '<' if data[1] == 1 else '>'
    body = 4
    (length,) = struct.unpack_from(f'{order}I', data, body + 8)
    offset = 12 + length
    offset += -offset % 4
    offset += skip
    if body + offset + 4 > len(data):
        return None
    (count,) = struct.unpack_from(f'{order}I', data, body + offset)
    return int(count)


def path_pose_count(data: bytes) -> int | None:
    """Return how many poses a serialised nav_msgs/Path holds, without deserialising it.

    Deserialising a Path costs about 15 us per pose in rclpy (1.5 s for 100,000 poses), all
    of it on the executor thread before a callback can refuse the message; the count is
    read from the CDR bytes instead: the encapsulation header (byte 1 is 1 for little
    endian), stamp (8 bytes), frame_id (uint32 length with the NUL, then the characters),
    then the sequence length as a uint32 aligned to 4 bytes of the body.

    Returns:
        The count, or None if data is too short or not CDR (deserialise it to find out why).

    """
    return _sequence_length_after_header(data, skip=0)


def poses_to_path(poses: np.ndarray | Sequence[Sequence[float]], *, frame_id: str = 'map',
                  stamp: Time | None = None) -> Path:
    """Return a nav_msgs/Path of (M, 3) poses (x, y, yaw); the stamp goes on every pose.

    Raises:
        ValueError: if poses is not (M, 3) finite numbers.

    """
    arr = np.asarray(poses, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        msg = f'poses must have shape (M, 3), got {arr.shape}'
        raise ValueError(msg)
    if not np.all(np.isfinite(arr)):
        msg = 'poses contain NaN or inf'
        raise ValueError(msg)
    msg_path = Path()
    msg_path.header.frame_id = frame_id
    if stamp is not None:
        msg_path.header.stamp = stamp
    for x, y, yaw in arr:
        pose = PoseStamped()
        pose.header = msg_path.header
        pose.pose.position.x = float(x)
        pose.pose.position.y = float(y)
        pose.pose.orientation = yaw_to_quaternion(yaw)
        msg_path.poses.append(pose)
    return msg_path


def odometry_to_state(odom: Odometry) -> np.ndarray:
    """Return the unicycle state (x, y, yaw) of an odometry message.

    Raises:
        ValueError: on a zero-norm orientation or a non-finite position.

    """
    return pose_to_array(odom.pose.pose)


def odometry_twist(odom: Odometry) -> np.ndarray:
    """Return the (v, omega) an odometry message measured: twist.linear.x, twist.angular.z.

    nav_msgs/Odometry's twist is in child_frame_id (base_link): linear.x is along the
    robot's heading. Unlike u_from_twist, NaN and inf are kept: a twist that is not finite
    is unknown (nothing is extrapolated from it), not a standstill.
    """
    twist = odom.twist.twist
    return np.array([twist.linear.x, twist.angular.z], dtype=float)


def state_to_odometry(state: np.ndarray, u: np.ndarray, *, stamp: Time,
                      frame_id: str = 'odom', child_frame_id: str = 'base_link') -> Odometry:
    """Return an Odometry for the state (x, y, yaw) moving with u = (v, omega).

    The twist is in the child frame, as nav_msgs/Odometry specifies: v along +x.
    """
    odom = Odometry()
    odom.header.stamp = stamp
    odom.header.frame_id = frame_id
    odom.child_frame_id = child_frame_id
    odom.pose.pose.position.x = float(state[0])
    odom.pose.pose.position.y = float(state[1])
    odom.pose.pose.orientation = yaw_to_quaternion(float(state[2]))
    odom.twist.twist = twist_from_u(u)
    return odom


def twist_from_u(u: np.ndarray | Sequence[float]) -> Twist:
    """Return the Twist of u = (v, omega): linear.x = v, angular.z = omega."""
    twist = Twist()
    twist.linear.x = float(u[0])
    twist.angular.z = float(u[1])
    return twist


def u_from_twist(twist: Twist) -> np.ndarray:
    """Return u = (v, omega) of a Twist; NaN and inf become 0 (a safe command).

    The other four components are ignored: a unicycle cannot follow them.
    """
    u = np.array([twist.linear.x, twist.angular.z], dtype=float)
    u[~np.isfinite(u)] = 0.0
    return u


def twist_stamped_from_u(u: np.ndarray | Sequence[float], *, stamp: Time,
                         frame_id: str = 'base_link') -> TwistStamped:
    """Return the TwistStamped of u = (v, omega) in frame_id (Nav2's stamped cmd_vel)."""
    msg = TwistStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.twist = twist_from_u(u)
    return msg


def _closed_ring(vertices: np.ndarray | Sequence[Sequence[float]]) -> np.ndarray:
    ring = np.asarray(vertices, dtype=float).reshape(-1, 2)
    if len(ring) < 2 or not np.all(np.isfinite(ring)):
        msg = f'a polygon needs at least two finite vertices, got {ring.tolist()}'
        raise ValueError(msg)
    return ring


def polygon_stamped(vertices: np.ndarray | Sequence[Sequence[float]], *, frame_id: str,
                    stamp: Time) -> PolygonStamped:
    """Return a geometry_msgs/PolygonStamped of (K, 2) vertices (implicitly closed).

    Raises:
        ValueError: if vertices are not at least two finite (x, y) pairs.

    """
    msg = PolygonStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    msg.polygon.points = [Point32(x=float(x), y=float(y), z=0.0)
                          for x, y in _closed_ring(vertices)]
    return msg


def polygon_marker(vertices: np.ndarray | Sequence[Sequence[float]], *, ns: str,
                   marker_id: int, frame_id: str, stamp: Time,
                   rgba: Sequence[float], width: float) -> Marker:
    """Return a LINE_STRIP Marker tracing the closed polygon of (K, 2) vertices.

    Args:
        vertices: the polygon's corners in order; the first is repeated at the end.
        ns: the marker namespace (RViz lists and toggles markers by it).
        marker_id: the id within ns (a marker with the same ns and id is replaced).
        frame_id: the frame of the vertices.
        stamp: the header stamp.
        rgba: colour, four numbers in [0, 1].
        width: line width (m).

    Raises:
        ValueError: if vertices are not at least two finite (x, y) pairs.

    """
    ring = _closed_ring(vertices)
    marker = _added_marker(Marker.LINE_STRIP, ns=ns, marker_id=marker_id, frame_id=frame_id,
                           stamp=stamp, rgba=rgba)
    marker.scale.x = float(width)
    marker.points = [Point(x=float(x), y=float(y), z=0.0)
                     for x, y in np.vstack([ring, ring[:1]])]
    return marker


def cylinder_marker(x: float, y: float, radius: float, *, ns: str, marker_id: int,
                    frame_id: str, stamp: Time, rgba: Sequence[float],
                    height: float) -> Marker:
    """Return a CYLINDER Marker of a disk of radius at (x, y), height tall, standing on z = 0.

    Args as polygon_marker's; height is the cylinder's (m).
    """
    marker = _added_marker(Marker.CYLINDER, ns=ns, marker_id=marker_id, frame_id=frame_id,
                           stamp=stamp, rgba=rgba)
    marker.pose.position.x, marker.pose.position.y = float(x), float(y)
    marker.pose.position.z = 0.5 * float(height)
    marker.scale.x = marker.scale.y = 2.0 * float(radius)
    marker.scale.z = float(height)
    return marker


def arrow_marker(start: Sequence[float], end: Sequence[float], *, ns: str, marker_id: int,
                 frame_id: str, stamp: Time, rgba: Sequence[float],
                 width: float) -> Marker:
    """Return an ARROW Marker from start (x, y) to end (x, y), at z = 0.

    Args as polygon_marker's; width is the shaft's diameter (m; the head is twice as wide).

    Raises:
        ValueError: if a point is not finite.

    """
    points = np.array([start, end], dtype=float).reshape(2, 2)
    if not np.all(np.isfinite(points)):
        msg = f'an arrow needs finite ends, got {points.tolist()}'
        raise ValueError(msg)
    marker = _added_marker(Marker.ARROW, ns=ns, marker_id=marker_id, frame_id=frame_id,
                           stamp=stamp, rgba=rgba)
    marker.scale.x, marker.scale.y, marker.scale.z = float(width), 2.0 * float(width), 0.0
    marker.points = [Point(x=float(x), y=float(y), z=0.0) for x, y in points]
    return marker


def _added_marker(kind: int, *, ns: str, marker_id: int, frame_id: str, stamp: Time,
                  rgba: Sequence[float]) -> Marker:
    """Return an ADD Marker of kind with its header, ns, id, identity orientation and colour."""
    marker = Marker()
    marker.header.frame_id = frame_id
    marker.header.stamp = stamp
    marker.ns = ns
    marker.id = int(marker_id)
    marker.type = kind
    marker.action = Marker.ADD
    marker.pose.orientation.w = 1.0
    marker.color = ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]),
                             a=float(rgba[3]))
    return marker


def delete_all_marker(*, frame_id: str, stamp: Time) -> Marker:
    """Return the Marker that deletes every marker of its publisher (DELETEALL)."""
    marker = Marker()
    marker.header.frame_id = frame_id
    marker.header.stamp = stamp
    marker.action = Marker.DELETEALL
    return marker


def diagnostic_array(*, name: str, hardware_id: str, level: int, message: str,
                     values: Sequence[tuple[str, str]], stamp: Time) -> DiagnosticArray:
    """Return a DiagnosticArray of one status (what each node publishes on its diagnostics)."""
    status = DiagnosticStatus()
    status.name = name
    status.hardware_id = hardware_id
    status.level = bytes([int(level)])
    status.message = message
    status.values = [KeyValue(key=k, value=v) for k, v in values]
    array = DiagnosticArray()
    array.header.stamp = stamp
    array.status = [status]
    return array


def scan_beam_count(data: bytes) -> int | None:
    """Return how many ranges a serialised sensor_msgs/LaserScan holds, without decoding it.

    A corrupt or hostile scan may claim millions of beams; the count is read from the CDR
    bytes (as `path_pose_count` reads a Path's) so that such a scan is refused before rclpy
    decodes it into Python floats: the encapsulation header, stamp (8 bytes), frame_id
    (uint32 length with the NUL, then the characters, padded to 4), seven float32 (angle_min,
    angle_max, angle_increment, time_increment, scan_time, range_min, range_max), then the
    ranges' sequence length as a uint32.

    Returns:
        The count, or None if data is too short or not CDR (deserialise it to find out why).

    """
    return _sequence_length_after_header(data, skip=7 * 4)  # the seven float32 fields


def scan_from_message(msg: LaserScan) -> Scan:
    """Return the perception layer's Scan of a sensor_msgs/LaserScan (not validated here).

    The ranges and intensities are float32 arrays as the message holds them (numpy views
    of its buffers where rclpy gives array.array); the stamp is in seconds.
    """
    return Scan(angle_min=float(msg.angle_min), angle_increment=float(msg.angle_increment),
                range_min=float(msg.range_min), range_max=float(msg.range_max),
                ranges=np.asarray(msg.ranges, dtype=np.float32),
                intensities=np.asarray(msg.intensities, dtype=np.float32),
                stamp=stamp_to_seconds(msg.header.stamp), angle_max=float(msg.angle_max))


def grid_from_message(msg: OccupancyGrid, *, frame_id: str | None = None) -> OccupancyMap:
    """Return the occupancy map of a nav_msgs/OccupancyGrid, its fields checked.

    Args:
        msg: the grid.
        frame_id: the frame it must be in (the nodes do not transform maps); None: any.

    Raises:
        GridError: if the grid is in another frame, the data length is not width x height,
            the resolution is not > 0, the origin (or its orientation) is not finite, or a
            value is outside -1..100.

    """
    problem = None if frame_id is None else frame_problem(msg.header.frame_id, frame_id, 'maps')
    if problem is not None:
        raise GridError(problem)
    info = msg.info
    origin = info.origin
    try:
        yaw = quaternion_to_yaw(origin.orientation)
    except ValueError as err:
        msg_text = f'grid origin orientation: {err}'
        raise GridError(msg_text) from None
    data = np.frombuffer(msg.data, dtype=np.int8) if isinstance(msg.data, (bytes, bytearray)) \
        else np.asarray(msg.data, dtype=np.int8)
    return grid_from_fields(data, int(info.width), int(info.height), float(info.resolution),
                            (float(origin.position.x), float(origin.position.y), yaw))
