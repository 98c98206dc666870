# SPDX-License-Identifier: Apache-2.0
"""global_planner's scans: each marks and clears the grid, placed with the pose at its stamp.

PlannerScans is a component GlobalPlannerNode (ros/global_planner_node.py) owns: the scan
intake (perception/scan_intake.py: waiting for a pose, the out-of-order and clock-jump rules,
the controller's too) and the obstacle memory re-plans keep clear of (with ``track_moving``
it tracks the scans' clusters and forgets what a moving one built). The node hands it each
scan with what it owns: the grid, the pose source and the planner's footprint.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
from rclpy.impl.rcutils_logger import RcutilsLogger
from sensor_msgs.msg import LaserScan

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.grids import PlanningGrid
from mpc_local_planner.perception.pose_history import MAX_EXTRAPOLATION_S
from mpc_local_planner.perception.scan_intake import (
    Discarded,
    Dropped,
    Placed,
    ScanIntake,
    ScanOrder,
)
from mpc_local_planner.perception.scan_obstacles import ObstacleMemory
from mpc_local_planner.perception.tracking import ScanTracker, Track
from mpc_local_planner.ros.conversions import (
    frame_problem,
    scan_from_message,
    SCANS,
)
from mpc_local_planner.ros.robot_pose import (
    LocalizationError,
    ODOM_HISTORY_S,
    PENDING_SCANS,
    RobotPose,
)
from mpc_local_planner.ros.throttle import ProblemThrottle

__all__ = ['PlannerScans', 'SCAN_POSE_TOLERANCE']

# A scan farther than this (seconds) from every kept odometry stamp is dropped: the pose it
# would be placed with is not the robot's at the scan. A scan newer than the odometry by
# more than MAX_EXTRAPOLATION_S waits instead, and is discarded if no odometry has covered
# its stamp by the time it is this old (by this node's clock).
SCAN_POSE_TOLERANCE = 0.5


class PlannerScans:
    """GlobalPlannerNode's intake of scans: read, wait for a pose, mark the grid.

    Args:
        logger: the node's logger.
        now: the node's clock, seconds.
        parameter: the current value of a node parameter (robot_base_frame, laser_pose).
        body: the planner's footprint in force (returns inside it are the robot), if any.

    Attributes:
        count: scans added to the grid.

    """

    def __init__(self, *, logger: RcutilsLogger, now: Callable[[], float],
                 parameter: Callable[[str], Any],
                 body: Callable[[], Footprint | None]) -> None:
        self._logger = logger
        self._body = body
        self._now = now
        self._parameter = parameter
        self._problems = ProblemThrottle()
        self._intake = ScanIntake(capacity=PENDING_SCANS, span=ODOM_HISTORY_S)
        # with use_scan: the convex pieces the scans make, as the controller remembers them
        self._memory: ObstacleMemory | None = None
        self.count = 0

    @property
    def held_obstacles(self) -> tuple[ConvexPolygon, ...]:
        """The convex pieces the scans made (obstacle_memory): re-plans keep clear of them."""
        return tuple(self._memory.obstacles()) if self._memory is not None else ()

    @property
    def tracks(self) -> list[Track] | None:
        """The live tracks of the scans' clusters (None: it does not track)."""
        return self._memory.tracks if self._memory is not None else None

    @property
    def pending(self) -> int:
        """Valid scans waiting for odometry that covers their stamps."""
        return self._intake.pending

    def reset(self, memory_ttl: float | None = None, *, track_moving: bool = False) -> None:
        """Start anew: no scan waiting or taken; a memory of memory_ttl s (None: none).

        track_moving: the memory tracks the scans' clusters and forgets what a moving one
        built, as the controller's does (perception/tracking.py; needs a memory). The grid
        still marks every return where it is now.
        """
        if track_moving and memory_ttl is None:
            msg = 'track_moving needs the scans (use_scan)'
            raise ValueError(msg)
        self._intake = ScanIntake(capacity=PENDING_SCANS, span=ODOM_HISTORY_S)
        tracker = ScanTracker() if track_moving else None
        self._memory = (ObstacleMemory(memory_ttl, tracker=tracker)
                        if memory_ttl is not None else None)

    def take(self, msg: LaserScan, grid: PlanningGrid | None, pose_source: RobotPose) -> None:
        """Mark and clear the grid with a scan, placed with the pose at its stamp.

        A malformed scan, or one without odometry near its stamp, is dropped with one
        throttled error. One stamped more than MAX_EXTRAPOLATION_S after the latest
        odometry waits (place_pending) until odometry covering its stamp has come: the
        older pose would mark its returns displaced by the motion since.

        Args:
            msg: the scan.
            grid: the grid it marks (None: no map yet, the scan is ignored).
            pose_source: the robot's pose in the plan's frame.

        """
        if grid is None:
            self._logger.info('scans are ignored until a map comes', once=True)
            return
        try:
            frame = str(self._parameter('robot_base_frame'))
            problem = frame_problem(msg.header.frame_id, frame, SCANS)
            if problem is not None:
                raise ValueError(problem)
            # validated before it is placed: a count the angles do not imply, among others
            self._intake.add(scan_from_message(msg), self._now())
        except Exception as err:  # ScanError (a ValueError); nothing may escape a callback
            self._refuse_scan(err)
            return
        self.place_pending(grid, pose_source)

    def place_pending(self, grid: PlanningGrid | None, pose_source: RobotPose) -> None:
        """Add to the grid the waiting scans whose stamps the pose now covers, in order.

        Called on each scan and each odometry message. A scan still without a pose once
        SCAN_POSE_TOLERANCE old is discarded (said once a while).
        """
        if grid is None:
            self._intake.clear()
            return

        def pose_at(stamp: float) -> np.ndarray | None:
            return _pose_at(pose_source, stamp)

        for event in self._intake.place(pose_at, self._now(), SCAN_POSE_TOLERANCE):
            if isinstance(event, Discarded):
                self._logger.info(
                    f'scan discarded: no odometry covered its stamp {event.scan.stamp:.3f} '
                    f's (more than {MAX_EXTRAPOLATION_S:g} s past the latest) within '
                    f'{SCAN_POSE_TOLERANCE:g} s', throttle_duration_sec=2.0)
            elif isinstance(event, Dropped):
                if isinstance(event.error, LocalizationError):  # not the scan's fault
                    self._logger.info(f"scan dropped: no pose in the plan's frame "
                                      f'({event.error})', throttle_duration_sec=2.0)
                else:
                    self._refuse_scan(event.error)
            elif isinstance(event, Placed):
                self._add(event, grid)

    def _add(self, placed: Placed, grid: PlanningGrid) -> None:
        """Add a placed scan to the grid and the obstacle memory; count it."""
        try:
            body = self._body()
            laser_pose = list(self._parameter('laser_pose'))
            grid.add_scan(placed.scan, placed.pose, laser_pose=laser_pose, body=body)
            if self._memory is not None:  # the controller's convex pieces, for re-plans
                self._remember(placed, laser_pose, body)
        except Exception as err:  # ScanError (a ValueError); nothing may escape
            self._refuse_scan(err)
            return
        self._problems.resolve('scan')
        self.count += 1

    def _remember(self, placed: Placed, laser_pose: list[float], body: Any) -> None:
        """Add a placed scan to the obstacle memory, as the controller does (ScanOrder)."""
        scan = placed.scan
        order = self._intake.order(scan.stamp)
        if order is ScanOrder.LATE:
            return
        if order is ScanOrder.CLOCK_JUMP:
            self._memory.clear()
        self._memory.update(scan, placed.pose, laser_pose=laser_pose, body=body)
        self._intake.taken(scan.stamp, placed.receipt)

    def _refuse_scan(self, err: Exception) -> None:
        """Say (throttled) that a scan was dropped."""
        if self._problems.report('scan'):
            self._logger.error(f'scan dropped: {err}')


def _pose_at(pose_source: RobotPose, stamp: float) -> np.ndarray | None:
    """Return the pose in the plan's frame at stamp (seconds): RobotPose.at.

    None: not yet (no odometry, or none within MAX_EXTRAPOLATION_S before the stamp; with
    tf2, no transform as new): the scan waits.

    Raises:
        ValueError: if no odometry kept is within SCAN_POSE_TOLERANCE of it (an old
            stamp), or there is no pose in the plan's frame (LocalizationError).

    """
    pose = pose_source.at(stamp)
    if pose is None:
        return None
    odometry = pose_source.located.odometry
    gap = odometry.gap(stamp)
    if not gap <= SCAN_POSE_TOLERANCE:  # with tf2 the odometry may lag, or be none
        problem = ('no odometry yet to place it' if len(odometry) == 0 else
                   f'no odometry within {SCAN_POSE_TOLERANCE:g} s of its stamp '
                   f'{stamp:.3f} s (nearest {gap:.3f} s away)')
        raise ValueError(problem)
    return pose
