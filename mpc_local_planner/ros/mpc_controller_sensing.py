# Copyright 2026 mpc_local_planner developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""What mpc_controller senses: scans and the map, turned into the obstacles it avoids.

ControllerSensing is a part of MpcControllerNode (ros/mpc_controller_node.py), which holds
the subscriptions and the state these callbacks fill; each control step hands the obstacles
within reach to the controller.

What the controller avoids, each control step: the world file's obstacles (source 'world'),
the map's occupied cells near the robot merged into rectangles (source 'map'; recomputed
when the map comes or the robot enters another cell), and what the laser saw (source 'scan':
each scan's returns, read beam by beam as REP 117 says (classify_beams: NaN and readings
outside [range_min, range_max] are ignored, +inf clears the beam up to range_max, -inf is an
obstacle at range_min; a return inside the robot's footprint, from the laser at
``laser_pose``, is the robot itself and ignored, so a -inf from a laser within the body stops
nothing), placed in the plan's frame with the robot's pose there AT THE SCAN'S STAMP
(ros/robot_pose.py: the odometry interpolated in the last ODOM_HISTORY_S seconds, a scan
older than that using the oldest pose kept; a scan newer than the latest odometry by at most
MAX_EXTRAPOLATION_S with the latest pose moved along its twist's arc, a newer one waiting
(the latest PENDING_SCANS, in order of arrival) until odometry covering its stamp has come
and discarded if none has within ``scan_timeout``, never placed with the older pose; with
the localizer's correction; or tf2's transform at the stamp, waited for the same way),
clustered into convex pieces and remembered for ``obstacle_memory`` seconds).

A scan that cannot be interpreted or a malformed grid (a zero or non-finite increment,
limits that are not finite or not 0 <= range_min < range_max, mismatched lengths, a beam
count the angles do not imply within one increment, too many beams, another frame, a stamp
more than MAX_SCAN_FUTURE_S ahead of this node's clock; a grid whose data is not width x
height, a resolution <= 0, a non-finite origin) is dropped with one throttled error; with
'scan' a source, the robot stops until a scan comes and whenever the latest valid one
placed is older than ``scan_timeout`` (a waiting scan renews nothing); with 'map' a source,
it stops until a valid map has come (as before the first scan: what the map would show is
unknown). A scan without a usable reading (every beam NaN, outside [range_min, range_max]
or inside the footprint) is valid but blind: it is used (it shows nothing and clears
nothing) and does not renew ``scan_timeout``, so one such scan among good ones changes
nothing, and a laser that sees nothing usable for ``scan_timeout`` stops the robot as a
silent one does (with a throttled warning).
"""

from __future__ import annotations

from typing import Any

from nav_msgs.msg import OccupancyGrid
import numpy as np
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import LaserScan

from mpc_local_planner.core.config import ObstacleSource
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.pose_history import MAX_EXTRAPOLATION_S
from mpc_local_planner.perception.scans import (
    check_scan_stamp,
    classify_beams,
    MAX_BEAMS,
    validate_scan,
)
from mpc_local_planner.ros.conversions import (
    frame_problem,
    grid_from_message,
    scan_beam_count,
    scan_from_message,
    SCANS,
)
from mpc_local_planner.ros.robot_pose import ODOM_HISTORY_S
from mpc_local_planner.ros.throttle import ERROR_THROTTLE_S

__all__ = ['ControllerSensing', 'MAX_SCAN_BYTES', 'SENSING_MARGIN']

# Metres beyond the horizon's reach (MpcConfig.reach: v_max N h, the inflation and a
# polygon's circumscribed radius) within which map cells and remembered scan obstacles are
# handed to the MPC.
SENSING_MARGIN = 0.5
# A serialised scan larger than this (both arrays at MAX_BEAMS float32, plus a header with
# a long frame id) is refused before it is decoded.
MAX_SCAN_BYTES = 2 * 4 * MAX_BEAMS + 4096


class ControllerSensing:
    """MpcControllerNode's intake of scan and map, and the obstacles it hands over."""

    @property
    def scan_stamp(self) -> float | None:
        """The stamp of the latest scan placed and used (s of ROS time; None: none yet)."""
        return self._scan_stamp

    @property
    def scan_time(self) -> float | None:
        """What scan_timeout is measured from (None: no usable scan yet).

        The latest usable scan's stamp, never later than its arrival (see _use_scan).
        """
        return self._scan_time

    @property
    def pending_scans(self) -> int:
        """How many valid scans wait for odometry that covers their stamps."""
        return len(self._pending_scans)

    def scan_callback(self, msg: LaserScan | bytes) -> None:
        """Take a scan: placed now if the odometry covers its stamp, else it waits.

        The robot's pose is its pose in the plan's frame at the scan's stamp (see pose_at;
        the one the controller steers with, so scan and plan agree). A scan stamped more
        than MAX_EXTRAPOLATION_S after the latest odometry waits (with at most
        PENDING_SCANS - 1 others, the oldest falling out) until odometry covering its stamp
        has come (_place_pending), renewing nothing meanwhile; the older pose would displace
        what it saw by the motion since. A malformed scan is dropped with one throttled
        error, so the scan goes stale if only bad ones come.

        Args:
            msg: the scan, or its CDR bytes as the raw subscription delivers them.

        """
        memory = self._local.memory if self._local is not None else None
        if memory is None or self.controller is None:
            return  # 'scan' is not a source (or not configured)
        receipt = self._now()
        try:
            scan, stamp = self._read_scan(msg, receipt)
        except Exception as err:  # ScanError mostly; never leave a callback
            self._refuse_scan(err)
            return
        self._pending_scans.append((scan, stamp, receipt))
        self._place_pending()

    def _place_pending(self) -> None:
        """Place the waiting scans whose stamps the pose now covers, in arrival order.

        Called on each scan, each odometry message and each control step. What is covered
        is every stamp up to a threshold (MAX_EXTRAPOLATION_S past the latest odometry, or
        the latest transform), so a scan placed here is never newer than one left waiting:
        the memory sees them in order. A scan still without a pose once older than
        scan_timeout is discarded (it would be stale when placed); one whose pose cannot be
        had (no localizer correction, no transform) is dropped, as before.
        """
        if self._local is None or self._local.memory is None or self.controller is None:
            self._pending_scans.clear()
            return
        waiting: list[tuple[Any, float, float]] = []
        while self._pending_scans:
            scan, stamp, receipt = self._pending_scans.popleft()
            try:
                pose = self.pose_at(stamp)
            except Exception as err:  # LocalizationError mostly; never leave a callback
                self.get_logger().info(f"scan dropped: no pose in the plan's frame to place "
                                       f'it ({err})', throttle_duration_sec=ERROR_THROTTLE_S)
                continue
            if pose is not None:
                self._use_scan(scan, stamp, receipt, pose)
                continue
            timeout = float(self.get_parameter('scan_timeout').value)
            if self._now() - stamp <= timeout:
                waiting.append((scan, stamp, receipt))  # until odometry covers its stamp
                continue
            self.get_logger().info(
                f'scan discarded: no odometry covered its stamp {stamp:.3f} s (more than '
                f'{MAX_EXTRAPOLATION_S:g} s past the latest) within scan_timeout '
                f'({timeout:g} s)', throttle_duration_sec=ERROR_THROTTLE_S)
        self._pending_scans.extend(waiting)

    def _use_scan(self, scan: Any, stamp: float, receipt: float, pose: np.ndarray) -> None:
        """Remember a placed scan's obstacles; renew scan_timeout if it has a usable reading.

        The scan's time (its stamp, but never later than its arrival) is what scan_timeout
        is measured against, set only here, once the scan is placed and used: a waiting
        scan renews nothing. A blind scan (no beam that is not ignored, see
        classify_beams) is used but does not renew it, so only blind scans go stale as no
        scans do.
        """
        memory = self._local.memory
        try:
            if self._scan_stamp is not None and stamp < self._scan_stamp:
                if self._scan_stamp - stamp <= ODOM_HISTORY_S:
                    return  # out of order: the memory holds a newer view already
                memory.clear()  # the clock jumped back
            laser = [float(v) for v in self.get_parameter('laser_pose').value]
            body = self.controller.config.robot_footprint  # returns inside are the robot
            memory.update(scan, pose, laser_pose=laser, body=body)
        except Exception as err:  # never leave a callback
            self._refuse_scan(err)
            return
        self._local.scan_updated()
        self._scan_stamp = stamp
        if self._problems.resolve('scan'):
            self.get_logger().info('scans are valid again')
        if not classify_beams(scan, body=body, laser_pose=laser).usable.any():
            self.get_logger().warning(
                'scan without a usable reading (every beam NaN, outside [range_min, '
                "range_max] or inside the robot's footprint): it does not renew scan_timeout",
                throttle_duration_sec=ERROR_THROTTLE_S)
            return
        self._scan_time = min(stamp, receipt)

    def _refuse_scan(self, err: Exception) -> None:
        """Say (throttled) that a scan was dropped as invalid."""
        problem = str(err) or type(err).__name__
        if self._problems.report('scan'):
            self.get_logger().error(f'invalid scan: {problem}; scan dropped (cmd_vel is '
                                    'zero once the scan is stale)')

    def _read_scan(self, msg: LaserScan | bytes, receipt: float) -> tuple[Any, float]:
        """Return the scan (validated, stamped) and its stamp in seconds.

        Raises:
            ValueError: if it is too large, in another frame, or malformed.

        """
        if isinstance(msg, (bytes, bytearray)):
            count = scan_beam_count(bytes(msg))
            if count is not None and count > MAX_BEAMS:
                problem = f'{count} beams, more than the {MAX_BEAMS} accepted'
                raise ValueError(problem)
            if len(msg) > MAX_SCAN_BYTES:
                problem = f'{len(msg)} bytes, more than {MAX_SCAN_BYTES} (too many values)'
                raise ValueError(problem)
            msg = deserialize_message(bytes(msg), LaserScan)
        if len(msg.ranges) > MAX_BEAMS:
            problem = f'{len(msg.ranges)} beams, more than the {MAX_BEAMS} accepted'
            raise ValueError(problem)
        frame = str(self.get_parameter('robot_base_frame').value)
        problem = frame_problem(msg.header.frame_id, frame, SCANS)
        if problem is not None:
            raise ValueError(problem)
        scan = scan_from_message(msg)
        stamp = scan.stamp if scan.stamp > 0 else receipt
        scan = scan._replace(stamp=stamp)
        validate_scan(scan)
        check_scan_stamp(stamp, receipt)
        return scan, stamp

    def map_callback(self, msg: OccupancyGrid) -> None:
        """Keep a valid map (its rectangles near the robot are recomputed); drop a bad one."""
        if ObstacleSource.MAP not in self._sources or self.controller is None:
            return
        try:
            frame = str(self.get_parameter('global_frame').value)
            grid = grid_from_message(msg, frame_id=frame)
        except Exception as err:  # GridError mostly; never leave a callback
            problem = str(err) or type(err).__name__
            if self._problems.report('map'):
                self.get_logger().error(f'invalid map: {problem}; map dropped (the previous '
                                        'one, if any, stays in force)')
            return
        self._grid = grid
        if self._local is not None:
            self._local.occupancy = grid
        self._problems.resolve('map')
        self.get_logger().info(f'new map: {grid.width} x {grid.height} cells of '
                               f'{grid.resolution:g} m')

    def _sensing_radius(self) -> float:
        """Return how far from the robot sensed obstacles matter (reach plus a margin).

        MpcConfig.reach: the horizon's travel, the inflation and, for a polygon, the
        circumscribed radius (a polygon's obstacles are not grown by the body, so the
        inflation alone would leave out those its corners can hit).
        """
        config, model = self.controller.config, self.controller.model
        return config.reach(float(model.u_max[0])) + SENSING_MARGIN

    def _update_obstacles(self) -> None:
        """Hand the obstacles in force to the controller: world + map + scan memory."""
        sensed: list[ConvexPolygon] = []
        if self._local is not None and self._state is not None:
            sensed = self._local.near(self._state[:2], self._sensing_radius())
        self.controller.set_obstacles(self._world_obstacles + sensed)
