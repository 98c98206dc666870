# SPDX-License-Identifier: Apache-2.0
"""global_planner with use_map (and use_scan): plans on the map's grid, marked by scans.

A probe publishes ``map`` (transient_local), ``odom``, ``scan`` and ``goal_pose`` over DDS and
reads ``plan``, ``planner/diagnostics`` and /rosout.
"""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import OccupancyGrid
import numpy as np
import pytest
from rcl_interfaces.msg import Log
from rclpy.exceptions import InvalidParameterValueException
from rclpy.parameter import Parameter
from sensor_msgs.msg import LaserScan

from mpc_local_planner.core.diagnostics import (
    Level,
    PLANNER_DIAGNOSTICS_TOPIC,
    PlannerDiagnostics,
    PlanTrigger,
)
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.ros.conversions import (
    path_to_poses,
    seconds_to_stamp,
    state_to_odometry,
    yaw_to_quaternion,
)
from mpc_local_planner.ros.global_planner_node import GlobalPlannerNode
from mpc_local_planner.ros.node_main import autostart
from mpc_local_planner.ros.qos import MAP_QOS, PLANNER_DIAGNOSTICS_QOS, SCAN_QOS
from mpc_local_planner.ros.throttle import ProblemThrottle
from mpc_local_planner.sim.laser import SimulatedLaser

pytestmark = pytest.mark.dds  # topics over DDS

RESOLUTION = 0.05
ROBOT_RADIUS = 0.2
CLEARANCE = 0.1
INFLATION = ROBOT_RADIUS + CLEARANCE
WALL = ConvexPolygon.from_box(4.5, 0.0, 5.0, 4.0)  # cells 90-99, rows 0-79 of the map
# Wall seconds a plan or a message may take before the test fails.
TIMEOUT = 20.0


def grid_message(data: np.ndarray, *, resolution: float = RESOLUTION,
                 width: int | None = None, height: int | None = None) -> OccupancyGrid:
    """Return an OccupancyGrid of data (row 0 at the bottom), origin (0, 0), frame map."""
    msg = OccupancyGrid()
    msg.header.frame_id = 'map'
    msg.info.resolution = resolution
    msg.info.height = data.shape[0] if height is None else height
    msg.info.width = data.shape[1] if width is None else width
    msg.info.origin.orientation.w = 1.0
    msg.data = np.asarray(data, dtype=np.int8).ravel().tolist()
    return msg


def wall_map() -> np.ndarray:
    """10 m x 6 m, free, with WALL occupied (a gap above it) and some unknown cells."""
    data = np.zeros((120, 200), dtype=np.int8)
    data[0:80, 90:100] = 100
    data[110:, 0:20] = -1
    return data


def goal_message(x: float, y: float) -> PoseStamped:
    goal = PoseStamped()
    goal.header.frame_id = 'map'
    goal.pose.position.x, goal.pose.position.y = x, y
    goal.pose.orientation = yaw_to_quaternion(0.0)
    return goal


def scan_message(shapes: list[ConvexPolygon], pose: np.ndarray, stamp: float, *,
                 increment: float | None = None) -> LaserScan:
    """Return a LaserScan that SimulatedLaser takes of shapes from pose (frame base_link)."""
    laser = SimulatedLaser(shapes, beams=720)
    scan = laser.scan(pose, stamp=stamp)
    msg = LaserScan()
    msg.header.frame_id = 'base_link'
    msg.header.stamp = seconds_to_stamp(stamp)
    msg.angle_min = scan.angle_min
    msg.angle_increment = scan.angle_increment if increment is None else increment
    msg.angle_max = scan.angle_min + scan.angle_increment * (len(scan.ranges) - 1)
    msg.range_min, msg.range_max = scan.range_min, scan.range_max
    msg.ranges = [float(r) for r in scan.ranges]
    return msg


def start(ros, **parameters):
    """Return an active planner on the map (use_map, no world) and a probe with publishers."""
    overrides = [Parameter('world_file', value=''), Parameter('use_map', value=True),
                 Parameter('robot_radius', value=ROBOT_RADIUS),
                 Parameter('clearance', value=CLEARANCE)]
    overrides += [Parameter(name, value=value) for name, value in parameters.items()]
    planner = ros.add(GlobalPlannerNode(context=ros.context, parameter_overrides=overrides))
    assert autostart(planner) is None
    probe = ros.probe()
    probe.map_pub = probe.create_publisher(OccupancyGrid, 'map', MAP_QOS)
    probe.scan_pub = probe.create_publisher(LaserScan, 'scan', SCAN_QOS)
    probe.outcomes = []
    probe.create_subscription(
        DiagnosticArray, PLANNER_DIAGNOSTICS_TOPIC,
        lambda msg: probe.outcomes.extend(
            PlannerDiagnostics.from_values((kv.key, kv.value) for kv in s.values)
            for s in msg.status),
        PLANNER_DIAGNOSTICS_QOS)
    return planner, probe


def locate(ros, planner, probe, pose: np.ndarray, stamp: float | None = None) -> None:
    """Publish odometry until the planner has it."""
    def located() -> bool:
        probe.publish_odom(pose, stamp)
        return planner.robot_pose is not None and np.allclose(planner.robot_pose, pose)

    assert ros.spin_until(located, timeout=TIMEOUT)


def scanning_planner(ros) -> tuple[GlobalPlannerNode, object, np.ndarray, float]:
    """Start a planner that reads scans, on an empty 10 m x 6 m map, located at (1, 3, 0).

    Returns the planner, the probe, the robot's pose and the odometry's stamp (the scans'
    stamp, so that they are placed with that pose).
    """
    planner, probe = start(ros, use_scan=True)
    probe.map_pub.publish(grid_message(np.zeros((120, 200), dtype=np.int8)))
    assert ros.spin_until(lambda: planner.grid is not None, timeout=TIMEOUT)
    pose = np.array([1.0, 3.0, 0.0])
    stamp = probe.now()
    locate(ros, planner, probe, pose, stamp)
    return planner, probe, pose, stamp

def next_plan(ros, planner, probe, goal: PoseStamped) -> np.ndarray:
    """Send a goal and return the (x, y) of the plan it gets."""
    count = len(probe.raw_plans)
    probe.goal_pub.publish(goal)
    assert ros.spin_until(lambda: len(probe.raw_plans) > count, timeout=TIMEOUT), \
        planner.last_outcome
    return path_to_poses(probe.plans[-1])[:, :2]


def samples(waypoints: np.ndarray) -> np.ndarray:
    return np.concatenate([np.linspace(a, b, 400)
                           for a, b in zip(waypoints[:-1], waypoints[1:], strict=True)])


def test_planner_waits_for_the_map_then_plans_around_its_wall_with_the_clearance(ros) -> None:
    planner, probe = start(ros)
    locate(ros, planner, probe, np.array([1.0, 1.0, 0.0]))
    probe.goal_pub.publish(goal_message(9.0, 1.0))

    assert ros.spin_until(lambda: any('waiting for map' in o.detail for o in probe.outcomes),
                          timeout=TIMEOUT), probe.outcomes
    waiting = probe.outcomes[-1]
    assert waiting.waiting and not waiting.planned and not waiting.failed
    assert waiting.level == Level.WARN and not probe.raw_plans and planner.planner is None

    probe.map_pub.publish(grid_message(wall_map()))  # the waiting goal is planned on it
    assert ros.spin_until(lambda: len(probe.raw_plans) == 1, timeout=TIMEOUT), probe.outcomes

    waypoints = path_to_poses(probe.plans[-1])[:, :2]
    np.testing.assert_allclose(waypoints[[0, -1]], [[1.0, 1.0], [9.0, 1.0]])
    assert len(waypoints) > 2
    assert WALL.distance(samples(waypoints)).min() >= INFLATION - 1e-9
    assert ros.spin_until(lambda: probe.outcomes[-1].planned, timeout=TIMEOUT)
    assert planner.grid is not None and planner.grid.map.width == 200


def test_planner_avoids_an_obstacle_a_scan_shows_and_the_map_lacks(
        ros, throttle_clock) -> None:
    planner, probe, pose, stamp = scanning_planner(ros)

    assert len(next_plan(ros, planner, probe, goal_message(9.0, 3.0))) == 2  # nothing seen

    # a malformed scan is dropped with an error; the planner keeps running
    bad = scan_message([], pose, stamp, increment=0.0)
    assert ros.spin_until(lambda: probe.scan_pub.publish(bad) or any(
        'scan dropped' in line for line in probe.log_lines('global_planner', Log.ERROR)),
        timeout=TIMEOUT)
    assert planner.scan_count == 0
    # so is a scan in another frame (the planner does not transform scans)
    box = ConvexPolygon.from_box(5.0, 1.5, 5.3, 4.5)  # in the world, not in the map
    elsewhere = scan_message([box], pose, stamp)
    elsewhere.header.frame_id = 'laser'
    # a throttle period passes between two scans: each problem is reported (scans of the
    # case before may still be queued)
    period = ProblemThrottle().period
    assert ros.spin_until(lambda: probe.scan_pub.publish(elsewhere)
                          or throttle_clock.advance(period) or any(
        "frame 'laser' is not 'base_link'" in line
        for line in probe.log_lines('global_planner', Log.ERROR)), timeout=TIMEOUT)
    assert planner.scan_count == 0

    scan = scan_message([box], pose, stamp)
    assert ros.spin_until(lambda: probe.scan_pub.publish(scan) or planner.scan_count > 0,
                          timeout=TIMEOUT)
    # the scan made the controller's convex pieces too (re-plans keep start_clearance)
    assert all(piece.distance(np.array([[5.0, 3.0]]))[0] < 0.1
               for piece in planner.held_obstacles)
    assert planner.held_obstacles

    waypoints = next_plan(ros, planner, probe, goal_message(9.0, 3.1))
    assert len(waypoints) > 2
    face = ConvexPolygon.from_box(5.0, 1.5, 5.0 + RESOLUTION, 4.5)  # what the laser saw
    assert face.distance(samples(waypoints)).min() >= INFLATION - 1e-9


def test_minus_inf_readings_inside_the_robot_mark_nothing_and_outside_it_an_obstacle(
        ros) -> None:
    planner, probe, pose, stamp = scanning_planner(ros)
    box = ConvexPolygon.from_box(5.0, 2.5, 5.3, 3.5)
    # every beam but those on the box -inf: range_min (5 cm) from a laser at the centre of
    # the 0.2 m robot (the planner's robot_radius) is inside it, the robot itself
    scan = scan_message([box], pose, stamp)
    scan.ranges = [r if np.isfinite(r) else -np.inf for r in scan.ranges]

    def marked() -> np.ndarray:
        return planner.grid.map.cell_to_world(*np.nonzero(planner.grid.occupied))

    assert ros.spin_until(lambda: probe.scan_pub.publish(scan) or planner.scan_count > 0,
                          timeout=TIMEOUT)
    assert len(marked()) > 0 and np.all(marked()[:, 0] >= 5.0 - RESOLUTION)  # the box only
    # the same readings from a laser on the robot's front edge: ahead, range_min reaches out
    # of the body, and -inf is an obstacle there
    planner.grid.clear_scans()
    planner.set_parameters([Parameter('laser_pose', value=[ROBOT_RADIUS, 0.0, 0.0])])
    assert ros.spin_until(lambda: probe.scan_pub.publish(scan) or planner.scan_count > 1,
                          timeout=TIMEOUT)
    near = np.hypot(*(marked() - pose[:2]).T) < 0.5
    assert near.any() and not planner.grid.is_free(pose[:2] + [ROBOT_RADIUS + 0.05, 0.0])[0]


def test_with_track_moving_the_planner_tells_a_walker_moving_and_still_marks_it(ros) -> None:
    """A walker crossing 2 m ahead at 1 m/s, a post beside its path, the robot standing.

    The planner's memory (start_clearance's pieces) tracks the clusters as the controller's
    does: the walker is told moving, the post static. The grid marks the walker where it
    is now, as without tracking (later beams clear where it was): a re-plan goes round a
    walker where the laser shows it (the dynamic suite measured worse without it).
    """
    planner, probe = start(ros, use_scan=True, track_moving=True)
    probe.map_pub.publish(grid_message(np.zeros((120, 200), dtype=np.int8)))
    assert ros.spin_until(lambda: planner.grid is not None, timeout=TIMEOUT)
    pose = np.array([1.0, 3.0, 0.0])
    post = ConvexPolygon.from_box(3.4, 4.0, 3.5, 4.1)
    first = probe.now()
    locate(ros, planner, probe, pose, first)
    period = 0.1
    for k in range(31):  # 3 s: the walker from y = 1.5 to y = 4.5 (past the post)
        stamp = first + k * period
        y = 1.5 + k * period
        walker = ConvexPolygon.from_box(2.85, y - 0.15, 3.15, y + 0.15)
        probe.publish_odom(pose, stamp)
        scan = scan_message([post, walker], pose, stamp)
        assert ros.spin_until(lambda k=k, scan=scan: probe.scan_pub.publish(scan)
                              or planner.scan_count > k, timeout=TIMEOUT)
    moving = [t for t in planner.tracks if t.moving]
    assert len(moving) == 1
    assert np.hypot(*(moving[0].position - [3.0, 4.5])) < 0.3
    assert moving[0].velocity[1] > 0.5
    assert any(not t.moving and np.hypot(*(t.position - [3.45, 4.05])) < 0.15
               for t in planner.tracks)
    assert not planner.grid.is_free(np.array([[3.0, 4.5], [3.45, 4.05]])).any()


def test_a_planner_without_track_moving_tracks_nothing(ros) -> None:
    planner, _ = start(ros, use_scan=True)
    assert planner.tracks is None


def test_a_malformed_map_is_refused_with_an_error_and_the_grid_in_force_stays(ros) -> None:
    planner, probe = start(ros)
    errors = lambda: probe.log_lines('global_planner', Log.ERROR)  # noqa: E731

    bad_length = grid_message(wall_map(), width=150)  # 150 x 120 cells, 24000 values
    probe.map_pub.publish(bad_length)
    assert ros.spin_until(lambda: any('map refused (no map yet)' in e and '18000 cells' in e
                                      for e in errors()), timeout=TIMEOUT), errors()
    assert planner.grid is None and planner.planner is None

    probe.map_pub.publish(grid_message(wall_map()))
    assert ros.spin_until(lambda: planner.grid is not None, timeout=TIMEOUT)
    grid = planner.grid

    probe.map_pub.publish(grid_message(wall_map(), resolution=0.0))
    assert ros.spin_until(lambda: any('map refused (the grid in force stays)' in e
                                      and 'resolution must be > 0' in e for e in errors()),
                          timeout=TIMEOUT), errors()
    assert planner.grid is grid and planner.map_count == 1

    locate(ros, planner, probe, np.array([1.0, 1.0, 0.0]))
    waypoints = next_plan(ros, planner, probe, goal_message(9.0, 1.0))
    assert WALL.distance(samples(waypoints)).min() >= INFLATION - 1e-9


@pytest.mark.parametrize(
    ('overrides', 'match'),
    [
        ({'use_scan': True}, 'use_scan needs use_map'),
        ({'use_map': True, 'track_moving': True}, 'track_moving needs use_scan'),
        ({'use_map': True, 'laser_pose': [0.0, float('nan'), 0.0]}, 'laser_pose must be'),
    ],
)
def test_planner_refuses_scans_without_the_map_and_a_malformed_laser_pose(
        ros, overrides: dict, match: str) -> None:
    with pytest.raises(InvalidParameterValueException, match=match):
        GlobalPlannerNode(context=ros.context, parameter_overrides=[
            Parameter(name, value=value) for name, value in overrides.items()])


def test_planner_replans_by_itself_when_a_scan_shows_an_obstacle_on_the_plan(ros) -> None:
    planner, probe = start(ros, use_scan=True, replan_check_rate=20.0)
    probe.map_pub.publish(grid_message(np.zeros((120, 200), dtype=np.int8)))
    assert ros.spin_until(lambda: planner.grid is not None, timeout=TIMEOUT)
    pose = np.array([1.0, 3.0, 0.0])
    stamp = probe.now()
    locate(ros, planner, probe, pose, stamp)
    first = next_plan(ros, planner, probe, goal_message(9.0, 3.0))
    assert len(first) == 2 and planner.replan_count == 0

    # the laser shows a wall across the plan: the next check re-plans, with no new goal
    box = ConvexPolygon.from_box(5.0, 1.5, 5.3, 4.5)
    count = len(probe.raw_plans)
    scan = scan_message([box], pose, stamp)
    assert ros.spin_until(lambda: probe.scan_pub.publish(scan) or len(probe.raw_plans) > count,
                          timeout=TIMEOUT), planner.last_outcome
    replanned = path_to_poses(probe.plans[-1])[:, :2]
    assert len(replanned) > 2
    face = ConvexPolygon.from_box(5.0, 1.5, 5.0 + RESOLUTION, 4.5)  # what the laser saw
    assert face.distance(samples(replanned)).min() >= INFLATION - 1e-9
    assert planner.replan_count == 1
    assert ros.spin_until(lambda: probe.outcomes and probe.outcomes[-1].replans == 1,
                          timeout=TIMEOUT)
    outcome = probe.outcomes[-1]
    assert outcome.planned and outcome.trigger is PlanTrigger.BLOCKED

    # the new plan is clear: further checks leave it alone
    for _ in range(5):
        planner.check_plan()
    assert planner.replan_count == 1


def test_a_robot_within_the_clearance_replans_from_the_nearest_clear_point(ros) -> None:
    planner, probe = start(ros, use_scan=True, replan_check_rate=20.0)
    probe.map_pub.publish(grid_message(np.zeros((120, 200), dtype=np.int8)))
    assert ros.spin_until(lambda: planner.grid is not None, timeout=TIMEOUT)
    locate(ros, planner, probe, np.array([1.0, 3.0, 0.0]))
    next_plan(ros, planner, probe, goal_message(9.0, 3.0))

    # the robot stopped 0.25 m in front of a box it has just seen (clearance 0.3 m)
    pose = np.array([4.75, 3.0, 0.0])
    stamp = probe.now()
    locate(ros, planner, probe, pose, stamp)
    box = ConvexPolygon.from_box(5.0, 1.5, 5.3, 4.5)
    count = len(probe.raw_plans)
    scan = scan_message([box], pose, stamp)
    assert ros.spin_until(lambda: probe.scan_pub.publish(scan) or len(probe.raw_plans) > count,
                          timeout=TIMEOUT), planner.last_outcome
    replanned = path_to_poses(probe.plans[-1])[:, :2]
    np.testing.assert_allclose(replanned[0], pose[:2])
    face = ConvexPolygon.from_box(5.0, 1.5, 5.0 + RESOLUTION, 4.5)
    # the first, short segment keeps the robot's radius; the rest the full inflation
    assert face.distance(samples(replanned[:2])).min() > ROBOT_RADIUS
    assert face.distance(samples(replanned[1:])).min() >= INFLATION - 1e-9


def test_planner_places_a_scan_newer_than_the_odometry_once_odometry_covers_its_stamp(
        ros) -> None:
    """A scan 0.15 s after the latest odometry (beyond MAX_EXTRAPOLATION_S) waits for it.

    Placed with that older pose it would mark the box's face 0.15 m short of where it is;
    it waits, marks nothing, and is placed when odometry covering its stamp comes. The
    callbacks are called directly: no DDS timing between the scan and the odometry.
    """
    planner, _probe, pose, _ = scanning_planner(ros)
    box = ConvexPolygon.from_box(5.0, 1.5, 5.3, 4.5)
    t0, v = planner.get_clock().now().nanoseconds * 1e-9, 1.0

    def odometry(t: float) -> None:  # driving along +x at v from pose at t0
        planner.odom_callback(state_to_odometry(pose + [v * (t - t0), 0.0, 0.0],
                                                np.array([v, 0.0]), stamp=seconds_to_stamp(t)))

    odometry(t0)
    count = planner.scan_count
    t_scan = t0 + 0.15
    planner.scan_callback(scan_message([box], pose + [v * (t_scan - t0), 0.0, 0.0], t_scan))
    assert planner.scan_count == count and planner.pending_scan_count == 1
    assert not planner.grid.occupied.any()
    odometry(t0 + 0.1)  # covers up to t0 + 0.1 + MAX_EXTRAPOLATION_S
    assert planner.scan_count == count + 1 and planner.pending_scan_count == 0
    columns = np.nonzero(planner.grid.occupied.any(axis=0))[0]
    assert columns.min() * RESOLUTION == pytest.approx(5.0, abs=RESOLUTION)


def test_planner_refuses_scans_whose_beams_do_not_match_their_angles_or_from_the_future(
        ros, throttle_clock) -> None:
    planner, probe, pose, stamp = scanning_planner(ros)
    box = ConvexPolygon.from_box(5.0, 1.5, 5.3, 4.5)

    def cut(msg: LaserScan, count: int) -> LaserScan:
        msg.ranges = (list(msg.ranges) * 2)[:count]
        return msg

    def backwards(msg: LaserScan) -> LaserScan:
        msg.angle_increment = -msg.angle_increment
        return msg

    def ahead(msg: LaserScan) -> LaserScan:
        msg.header.stamp = seconds_to_stamp(stamp + 30.0)
        return msg

    cases = [(cut(scan_message([box], pose, stamp), 800), 'scan has 800 ranges'),
             (cut(scan_message([box], pose, stamp), 60), 'scan has 60 ranges'),
             (backwards(scan_message([box], pose, stamp)), "increment's sign leads away"),
             (ahead(scan_message([box], pose, stamp)), 'in the future')]
    # a throttle period passes between two scans: each problem is reported (scans of the
    # case before may still be queued)
    period = ProblemThrottle().period
    for bad, text in cases:

        def said(text: str = text) -> bool:
            return any('scan dropped' in line and text in line
                       for line in probe.log_lines('global_planner', Log.ERROR))

        assert ros.spin_until(lambda bad=bad, said=said: probe.scan_pub.publish(bad)
                              or throttle_clock.advance(period) or said(),
                              timeout=TIMEOUT), probe.log_lines('global_planner')
        assert planner.scan_count == 0
    # the same scan, right: taken
    assert ros.spin_until(lambda: probe.scan_pub.publish(scan_message([box], pose, stamp))
                          or planner.scan_count > 0, timeout=TIMEOUT)


def test_planner_takes_scans_again_after_the_clock_jumped_back(ros) -> None:
    """A restarted simulation, or a bag played again: stamps start over, 10 s earlier.

    The odometry history and the obstacle memory (the controller's pieces, for re-plans)
    start anew; scans are placed and counted as before, none is refused as older than the
    last one. The callbacks are called directly: nothing else arrives in between.
    """
    planner, _probe, pose, stamp = scanning_planner(ros)
    box = ConvexPolygon.from_box(5.0, 1.5, 5.3, 4.5)
    for t in (stamp + 0.1, stamp - 10.0, stamp - 9.9):
        count = planner.scan_count
        planner.odom_callback(state_to_odometry(pose, np.zeros(2), stamp=seconds_to_stamp(t)))
        planner.scan_callback(scan_message([box], pose, t))
        assert planner.scan_count == count + 1, t
