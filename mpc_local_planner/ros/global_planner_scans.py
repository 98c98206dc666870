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

"""global_planner's scans: each marks and clears the grid, placed with the pose at its stamp.

PlannerScans is a part of GlobalPlannerNode (ros/global_planner_node.py), which holds the
subscription, the grid and the pose source these use.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sensor_msgs.msg import LaserScan

from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.pose_history import MAX_EXTRAPOLATION_S
from mpc_local_planner.perception.scans import check_scan_stamp, validate_scan
from mpc_local_planner.ros.conversions import (
    frame_problem,
    scan_from_message,
    SCANS,
)
from mpc_local_planner.ros.robot_pose import (
    LocalizationError,
    ODOM_HISTORY_S,
)

__all__ = ['PlannerScans', 'SCAN_POSE_TOLERANCE']

# A scan farther than this (seconds) from every kept odometry stamp is dropped: the pose it
# would be placed with is not the robot's at the scan. A scan newer than the odometry by
# more than MAX_EXTRAPOLATION_S waits instead, and is discarded if no odometry has covered
# its stamp by the time it is this old (by this node's clock).
SCAN_POSE_TOLERANCE = 0.5


class PlannerScans:
    """GlobalPlannerNode's intake of scans: read, wait for a pose, mark the grid.

    And what the node's users (and tests) read of it: the pieces the scans made, the scans
    waiting for a pose, and the latest odometry, which places them.
    """

    @property
    def held_obstacles(self) -> tuple[ConvexPolygon, ...]:
        """The convex pieces the scans made (obstacle_memory): re-plans keep clear of them."""
        return tuple(self._memory.obstacles()) if self._memory is not None else ()

    @property
    def pending_scan_count(self) -> int:
        """Valid scans waiting for odometry that covers their stamps."""
        return len(self._pending_scans)

    @property
    def odom_state(self) -> np.ndarray | None:
        """A copy of the latest valid odometry's state (odom frame); None without one."""
        return None if self._state is None else self._state.copy()

    def scan_callback(self, msg: LaserScan) -> None:
        """Mark and clear the grid with a scan, placed with the pose at its stamp.

        A malformed scan, or one without odometry near its stamp, is dropped with one
        throttled error. One stamped more than MAX_EXTRAPOLATION_S after the latest
        odometry waits (_place_pending) until odometry covering its stamp has come: the
        older pose would mark its returns displaced by the motion since.
        """
        if self._grid is None:
            self.get_logger().info('scans are ignored until a map comes', once=True)
            return
        try:
            frame = str(self.get_parameter('robot_base_frame').value)
            problem = frame_problem(msg.header.frame_id, frame, SCANS)
            if problem is not None:
                raise ValueError(problem)
            scan = scan_from_message(msg)
            validate_scan(scan)  # before it is placed: a count the angles do not imply
            check_scan_stamp(scan.stamp, self._now())
        except Exception as err:  # ScanError (a ValueError); nothing may escape a callback
            self._refuse_scan(err)
            return
        self._pending_scans.append(scan)
        self._place_pending()

    def _place_pending(self) -> None:
        """Add to the grid the waiting scans whose stamps the pose now covers, in order.

        Called on each scan and each odometry message. What is covered is every stamp up to
        a threshold (MAX_EXTRAPOLATION_S past the latest odometry, or the latest
        transform), so a scan added is never newer than one left waiting. A scan still
        without a pose once SCAN_POSE_TOLERANCE old is discarded (said once a while).
        """
        if self._grid is None:
            self._pending_scans.clear()
            return
        waiting = []
        while self._pending_scans:
            scan = self._pending_scans.popleft()
            try:
                pose = self._pose_at(scan.stamp)
                if pose is None:
                    if self._now() - scan.stamp <= SCAN_POSE_TOLERANCE:
                        waiting.append(scan)  # until odometry covers its stamp
                    else:
                        self.get_logger().info(
                            f'scan discarded: no odometry covered its stamp {scan.stamp:.3f} '
                            f's (more than {MAX_EXTRAPOLATION_S:g} s past the latest) within '
                            f'{SCAN_POSE_TOLERANCE:g} s', throttle_duration_sec=2.0)
                    continue
                # returns inside the robot are the robot: the planner's footprint says where
                body = self._planner.footprint if self._planner is not None else None
                laser_pose = list(self.get_parameter('laser_pose').value)
                self._grid.add_scan(scan, pose, laser_pose=laser_pose, body=body)
                if self._memory is not None:  # the controller's convex pieces, for re-plans
                    self._remember(scan, pose, laser_pose, body)
            except LocalizationError as err:  # not the scan's fault: said where plans wait
                self.get_logger().info(f"scan dropped: no pose in the plan's frame ({err})",
                                       throttle_duration_sec=2.0)
                continue
            except Exception as err:  # ScanError (a ValueError); nothing may escape
                self._refuse_scan(err)
                continue
            self._problems.resolve('scan')
            self.scan_count += 1
        self._pending_scans.extend(waiting)

    def _remember(self, scan: Any, pose: np.ndarray, laser_pose: list[float],
                  body: Any) -> None:
        """Add a placed scan to the obstacle memory, as the controller does.

        A scan a little older than the newest remembered (out of order) adds nothing: the
        memory holds a newer view. One older by more than the odometry kept means the clock
        jumped back (a restarted simulation, a bag played again): the memory starts anew
        instead of refusing every scan from then on.
        """
        if scan.stamp < self._memory.stamp:
            if self._memory.stamp - scan.stamp <= ODOM_HISTORY_S:
                return
            self._memory.clear()
        self._memory.update(scan, pose, laser_pose=laser_pose, body=body)

    def _refuse_scan(self, err: Exception) -> None:
        """Say (throttled) that a scan was dropped."""
        if self._problems.report('scan'):
            self.get_logger().error(f'scan dropped: {err}')

    def _pose_at(self, stamp: float) -> np.ndarray | None:
        """Return the pose in the plan's frame at stamp (seconds): RobotPose.at.

        None: not yet (no odometry, or none within MAX_EXTRAPOLATION_S before the stamp;
        with tf2, no transform as new): the scan waits.

        Raises:
            ValueError: if no odometry kept is within SCAN_POSE_TOLERANCE of it (an old
                stamp), or there is no pose in the plan's frame (LocalizationError).

        """
        pose = self._pose_source.at(stamp)
        if pose is None:
            return None
        odometry = self._pose_source.located.odometry
        gap = odometry.gap(stamp)
        if not gap <= SCAN_POSE_TOLERANCE:  # with tf2 the odometry may lag, or be none
            problem = ('no odometry yet to place it' if len(odometry) == 0 else
                       f'no odometry within {SCAN_POSE_TOLERANCE:g} s of its stamp '
                       f'{stamp:.3f} s (nearest {gap:.3f} s away)')
            raise ValueError(problem)
        return pose
