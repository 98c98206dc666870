# SPDX-License-Identifier: Apache-2.0
"""What mpc_controller senses: scans and the map, turned into the obstacles it avoids.

ControllerSensing is a component MpcControllerNode (ros/mpc_controller_node.py) builds at
configure: it owns the scan intake (perception/scan_intake.py), the obstacle memory and the
map; the node's scan and map callbacks hand it the messages, and each control step hands the
obstacles within reach to the controller.

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

from typing import Any, Callable

from nav_msgs.msg import OccupancyGrid
import numpy as np
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import LaserScan

from mpc_local_planner.core.config import ObstacleSource
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.local_obstacles import LocalObstacles, SENSING_MARGIN
from mpc_local_planner.perception.pose_history import MAX_EXTRAPOLATION_S
from mpc_local_planner.perception.scan_intake import (
    Discarded,
    Dropped,
    Placed,
    ScanIntake,
    ScanOrder,
)
from mpc_local_planner.perception.scan_obstacles import ObstacleMemory
from mpc_local_planner.perception.scans import MAX_BEAMS, Scan
from mpc_local_planner.perception.tracking import ScanTracker, Track
from mpc_local_planner.ros.conversions import (
    frame_problem,
    grid_from_message,
    scan_beam_count,
    scan_from_message,
    SCANS,
)
from mpc_local_planner.ros.robot_pose import ODOM_HISTORY_S, PENDING_SCANS
from mpc_local_planner.ros.throttle import ERROR_THROTTLE_S, ProblemThrottle
from mpc_local_planner.worlds.map_files import OccupancyMap

__all__ = ['ControllerSensing', 'MAX_SCAN_BYTES', 'SENSING_MARGIN']

# A serialised scan larger than this (both arrays at MAX_BEAMS float32, plus a header with
# a long frame id) is refused before it is decoded.
MAX_SCAN_BYTES = 2 * 4 * MAX_BEAMS + 4096


class ControllerSensing:
    """MpcControllerNode's intake of scan and map, and the obstacles it hands over.

    Args:
        controller: the node's MpcController (its footprint, reach and faces).
        sources: the obstacle sources ('scan' and 'map' are taken in here).
        memory_ttl: obstacle_memory, seconds.
        track_moving: the memory tracks the scans' clusters and forgets what moving ones
            built (perception/tracking.py), and `tracks` says where they are.
        logger: the node's logger.
        now: the node's clock, seconds.
        parameter: the current value of a node parameter (frames, laser_pose,
            scan_timeout: read when used, so a change applies at once).
        pose_at: the robot's pose in the plan's frame at a stamp (None: not yet).

    """

    def __init__(self, controller: MpcController, *, sources: frozenset[ObstacleSource],
                 memory_ttl: float, logger: RcutilsLogger, now: Callable[[], float],
                 track_moving: bool = False,
                 parameter: Callable[[str], Any],
                 pose_at: Callable[[float], np.ndarray | None]) -> None:
        self._controller = controller
        self._logger = logger
        self._now = now
        self._parameter = parameter
        self._pose_at = pose_at
        self._problems = ProblemThrottle(ERROR_THROTTLE_S)
        self._take_map = ObstacleSource.MAP in sources
        # the map's and the laser's obstacles (the scan memory inside), the latest valid map
        tracker = ScanTracker() if track_moving else None
        self.local = LocalObstacles(
            controller.config.solving.faces_per_obstacle,
            memory=(ObstacleMemory(memory_ttl, tracker=tracker)
                    if ObstacleSource.SCAN in sources else None))
        self.grid: OccupancyMap | None = None
        self._intake = (ScanIntake(capacity=PENDING_SCANS, span=ODOM_HISTORY_S)
                        if ObstacleSource.SCAN in sources else None)

    @property
    def scan_stamp(self) -> float | None:
        """The stamp of the latest scan placed and used (s of ROS time; None: none yet)."""
        return self._intake.latest_stamp if self._intake is not None else None

    @property
    def scan_time(self) -> float | None:
        """What scan_timeout is measured from (None: no usable scan yet).

        The latest usable scan's stamp, never later than its arrival (ScanIntake.fresh_time).
        """
        return self._intake.fresh_time if self._intake is not None else None

    @property
    def pending_scans(self) -> int:
        """How many valid scans wait for odometry that covers their stamps."""
        return self._intake.pending if self._intake is not None else 0

    @property
    def tracks(self) -> list[Track] | None:
        """The live tracks of the scans' clusters (None: the node does not track)."""
        memory = self.local.memory
        return memory.tracks if memory is not None else None

    def set_memory_ttl(self, ttl: float) -> None:
        """Apply a new obstacle_memory (seconds) to the scan memory, if there is one."""
        if self.local.memory is not None:
            self.local.memory.ttl = ttl

    def take_scan(self, msg: LaserScan | bytes) -> None:
        """Take a scan: placed now if the odometry covers its stamp, else it waits.

        The robot's pose is its pose in the plan's frame at the scan's stamp (the one the
        controller steers with, so scan and plan agree). A scan stamped more than
        MAX_EXTRAPOLATION_S after the latest odometry waits (with at most PENDING_SCANS - 1
        others, the oldest falling out) until odometry covering its stamp has come
        (place_pending), renewing nothing meanwhile; the older pose would displace what it
        saw by the motion since. A malformed scan is dropped with one throttled error, so the
        scan goes stale if only bad ones come.

        Args:
            msg: the scan, or its CDR bytes as the raw subscription delivers them.

        """
        if self._intake is None:
            return  # 'scan' is not a source
        receipt = self._now()
        try:
            self._intake.add(self._read_scan(msg, receipt), receipt)
        except Exception as err:  # ScanError mostly; never leave a callback
            self._refuse_scan(err)
            return
        self.place_pending()

    def place_pending(self) -> None:
        """Place the waiting scans whose stamps the pose now covers, in arrival order.

        Called on each scan, each odometry message and each control step. A scan still
        without a pose once older than scan_timeout is discarded (it would be stale when
        placed); one whose pose cannot be had (no localizer correction, no transform) is
        dropped.
        """
        if self._intake is None:
            return
        timeout = float(self._parameter('scan_timeout'))
        for event in self._intake.place(self._pose_at, self._now(), timeout):
            if isinstance(event, Placed):
                self._use_scan(event)
            elif isinstance(event, Dropped):
                self._logger.info(f"scan dropped: no pose in the plan's frame to place it "
                                  f'({event.error})', throttle_duration_sec=ERROR_THROTTLE_S)
            elif isinstance(event, Discarded):
                self._logger.info(
                    f'scan discarded: no odometry covered its stamp {event.scan.stamp:.3f} s '
                    f'(more than {MAX_EXTRAPOLATION_S:g} s past the latest) within '
                    f'scan_timeout ({timeout:g} s)', throttle_duration_sec=ERROR_THROTTLE_S)

    def _use_scan(self, placed: Placed) -> None:
        """Remember a placed scan's obstacles; renew scan_timeout if it has a usable reading.

        A blind scan (no beam that is not ignored, see classify_beams) is used but does not
        renew it, so only blind scans go stale as no scans do.
        """
        memory, scan = self.local.memory, placed.scan
        try:
            order = self._intake.order(scan.stamp)
            if order is ScanOrder.LATE:
                return  # out of order: the memory holds a newer view already
            if order is ScanOrder.CLOCK_JUMP:
                memory.clear()
            laser = [float(v) for v in self._parameter('laser_pose')]
            body = self._controller.config.robot_footprint  # returns inside are the robot
            memory.update(scan, placed.pose, laser_pose=laser, body=body)
        except Exception as err:  # never leave a callback
            self._refuse_scan(err)
            return
        self.local.scan_updated()
        if self._problems.resolve('scan'):
            self._logger.info('scans are valid again')
        usable = memory.last_scan_usable  # the memory classified its beams
        self._intake.taken(scan.stamp, placed.receipt, usable=usable)
        if not usable:
            self._logger.warning(
                'scan without a usable reading (every beam NaN, outside [range_min, '
                "range_max] or inside the robot's footprint): it does not renew scan_timeout",
                throttle_duration_sec=ERROR_THROTTLE_S)

    def _refuse_scan(self, err: Exception) -> None:
        """Say (throttled) that a scan was dropped as invalid."""
        problem = str(err) or type(err).__name__
        if self._problems.report('scan'):
            self._logger.error(f'invalid scan: {problem}; scan dropped (cmd_vel is '
                               'zero once the scan is stale)')

    def _read_scan(self, msg: LaserScan | bytes, receipt: float) -> Scan:
        """Return the scan, stamped (its stamp, or its arrival when it has none).

        Its beams are counted before it is decoded; the intake validates the rest.

        Raises:
            ValueError: if it is too large or in another frame.

        """
        if isinstance(msg, (bytes, bytearray)):
            count = scan_beam_count(bytes(msg))
            if count is not None:
                self._intake.check_beam_count(count)
            if len(msg) > MAX_SCAN_BYTES:
                problem = f'{len(msg)} bytes, more than {MAX_SCAN_BYTES} (too many values)'
                raise ValueError(problem)
            msg = deserialize_message(bytes(msg), LaserScan)
        frame = str(self._parameter('robot_base_frame'))
        problem = frame_problem(msg.header.frame_id, frame, SCANS)
        if problem is not None:
            raise ValueError(problem)
        scan = scan_from_message(msg)
        return scan._replace(stamp=scan.stamp if scan.stamp > 0 else receipt)

    def take_map(self, msg: OccupancyGrid) -> None:
        """Keep a valid map (its rectangles near the robot are recomputed); drop a bad one."""
        if not self._take_map:
            return
        try:
            frame = str(self._parameter('global_frame'))
            grid = grid_from_message(msg, frame_id=frame)
        except Exception as err:  # GridError mostly; never leave a callback
            problem = str(err) or type(err).__name__
            if self._problems.report('map'):
                self._logger.error(f'invalid map: {problem}; map dropped (the previous '
                                   'one, if any, stays in force)')
            return
        self.grid = grid
        self.local.occupancy = grid
        self._problems.resolve('map')
        self._logger.info(f'new map: {grid.width} x {grid.height} cells of '
                          f'{grid.resolution:g} m')

    def near(self, state: np.ndarray | None, now: float | None = None) -> list[ConvexPolygon]:
        """Return the sensed obstacles within reach of the robot at state (none without one).

        Reach: MpcConfig.reach (the horizon's travel, the inflation and, for a polygon, the
        circumscribed radius: a polygon's obstacles are not grown by the body, so the
        inflation alone would leave out those its corners can hit) plus SENSING_MARGIN.
        With track_moving, the moving tracks too, where they are at now (the control step's
        time), with their velocity: the MPC predicts them.
        """
        if state is None:
            return []
        config, model = self._controller.config, self._controller.model
        return self.local.near(state[:2], config.reach(float(model.u_max[0])) + SENSING_MARGIN,
                               now)
