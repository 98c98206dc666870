# SPDX-License-Identifier: Apache-2.0
"""mpc_controller with obstacle_sources [scan] or [map]: it avoids what it senses.

The test owns simulated time (it publishes /clock), plays the robot (it integrates the
commands as a unicycle and publishes odometry) and the laser (it ray-casts a scan of the true
world at the robot's pose and publishes it, stamped). Everything is asserted in ROS time.
"""

from __future__ import annotations

import math
import time
from typing import Any, Callable

from conftest import SimClock
from nav_msgs.msg import OccupancyGrid
import numpy as np
import pytest
from rcl_interfaces.msg import Log
from rclpy.exceptions import InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import Marker, MarkerArray

from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.moving_obstacles import MovingPolygon
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.ros.conversions import (
    poses_to_path,
    seconds_to_stamp,
    state_to_odometry,
    u_from_twist,
    yaw_to_quaternion,
)
from mpc_local_planner.ros.mpc_controller_node import MpcControllerNode
from mpc_local_planner.ros.mpc_controller_outputs import OBSTACLES_TOPIC, TRACKS_TOPIC
from mpc_local_planner.ros.node_main import autostart
from mpc_local_planner.ros.qos import LOCAL_PLAN_QOS, MAP_QOS
from mpc_local_planner.sim.laser import SimulatedLaser

pytestmark = pytest.mark.dds  # DDS

U_MAX = Unicycle().u_max
STEP = 0.2  # the controller's control period (s)
SCAN_TIMEOUT = 0.5
# A wall across the straight plan from (0, 0) to (3, 0), 1.2 m ahead of the start.
WALL_X = 1.2
WALL = ConvexPolygon.from_box(WALL_X, -1.0, WALL_X + 0.1, 1.0)
PLAN = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
# A laser with 180 degrees of view in front of the robot.
FOV = math.pi
BEAMS = 181


class World(SimClock):
    """The test's robot, laser, clock (conftest's SimClock) and listeners, around one controller.

    Each tick moves the robot on the last command and publishes odometry and a scan.
    """

    def __init__(self, ros, obstacles: list[ConvexPolygon], *, beams: int = BEAMS,
                 **params) -> None:
        overrides = [Parameter('use_sim_time', value=True), Parameter('world_file', value='')]
        overrides += [Parameter(k, value=v) for k, v in params.items()]
        self.node = ros.add(MpcControllerNode(context=ros.context,
                                              parameter_overrides=overrides))
        assert autostart(self.node) is None
        super().__init__(ros, ros.probe(use_sim_time=True))
        self.io = ros.add(Node('sensing_probe', context=ros.context))
        self.scan_pub = self.io.create_publisher(
            LaserScan, 'scan', QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE))
        self.map_pub = self.io.create_publisher(OccupancyGrid, 'map', MAP_QOS)
        self.markers: list[MarkerArray] = []
        self.io.create_subscription(MarkerArray, OBSTACLES_TOPIC, self.markers.append,
                                    LOCAL_PLAN_QOS)
        self.beams = beams
        self.laser = SimulatedLaser(obstacles, fov=FOV, beams=beams, range_max=5.0) \
            if obstacles else None
        self.state = np.zeros(3)
        self.drive = True  # integrate the commands
        self.scanning = True  # publish a scan each tick
        # what the laser driver makes of the true ranges (None: it publishes them as they are)
        self.readings: Callable[[np.ndarray], np.ndarray] | None = None
        self.positions: list[np.ndarray] = []
        assert ros.spin_until(lambda: self.probe.odom_pub.get_subscription_count() > 0
                              and self.probe.plan_pub.get_subscription_count() > 0
                              and self.node.count_publishers('cmd_vel') > 0)

    # ---------------------------------------------------------------- the robot and its laser
    def scan_message(self, pose: np.ndarray, stamp: float) -> LaserScan:
        msg = LaserScan()
        msg.header.frame_id = 'base_link'
        msg.header.stamp = seconds_to_stamp(stamp)
        msg.angle_min = -FOV / 2
        msg.angle_max = FOV / 2
        msg.angle_increment = FOV / (self.beams - 1)
        msg.range_min = 0.05
        msg.range_max = 5.0
        ranges = self.laser.scan(pose).ranges if self.laser is not None \
            else np.full(self.beams, math.inf)
        if self.readings is not None:
            ranges = self.readings(ranges)
        msg.ranges = [float(r) for r in ranges]
        return msg

    def u(self) -> np.ndarray:
        return u_from_twist(self.probe.cmds[-1]) if self.probe.cmds else np.zeros(2)

    def publish(self) -> None:
        """Move the robot on the last command over dt, publish odom and the scan."""
        dt = self.dt
        if self.drive:
            v, omega = self.u()
            x, y, th = self.state
            self.state = np.array([x + dt * v * math.cos(th), y + dt * v * math.sin(th),
                                   th + dt * omega])
        self.positions.append(self.state[:2].copy())
        self.probe.publish_odom(self.state, stamp=self.t)
        if self.scanning:
            self.scan_pub.publish(self.scan_message(self.state, self.t))

    def spin(self) -> None:
        """Spin until the controller has stepped at this instant, then a little more."""
        # lockstep: spin until the controller has stepped at this instant (its diagnostics
        # stamped now), so that a fast-ticking test never runs ahead of the node and leaves
        # its scans queued; a tick the timer skips (clock rounding) ends by the short cap
        deadline = time.monotonic() + 0.5
        while time.monotonic() < deadline and not (
                self.probe.diagnostics and self.probe.diagnostics[-1].stamp >= self.t - 1e-6):
            self.ros.executor.spin_once(timeout_sec=0.002)
        for _ in range(3):
            self.ros.executor.spin_once(timeout_sec=0.002)

    def run_until(self, condition: Callable[[], bool], timeout: float = 60.0) -> bool:
        return super().run_until(condition, timeout)

    # ---------------------------------------------------------------- what the node says
    def steps(self, after: int = 0) -> list:
        return [d.step for d in self.probe.diagnostics[after:]]

    def raw(self) -> list[np.ndarray]:
        """The vertices of the 'raw' markers of the latest mpc/obstacles."""
        if not self.markers:
            return []
        return [np.array([[p.x, p.y] for p in m.points]) for m in self.markers[-1].markers
                if m.ns == 'raw' and m.action == Marker.ADD]

    def errors(self, text: str) -> list[str]:
        return [line for line in self.probe.log_lines('mpc_controller', Log.ERROR)
                if text in line]


def check_commands(probe) -> None:
    raw = np.array([[c.linear.x, c.angular.z] for c in probe.cmds]).reshape(-1, 2)
    assert np.all(np.isfinite(raw)) and np.all(np.abs(raw) <= U_MAX + 1e-12)


def inside(polygon: ConvexPolygon, points: np.ndarray) -> np.ndarray:
    return polygon.contains(np.asarray(points).reshape(-1, 2))


# ----------------------------------------------------------------------------- (a)
def test_a_wall_seen_by_the_laser_is_placed_with_the_pose_at_the_scan_stamp_and_not_driven_into(
        ros) -> None:
    world = World(ros, [WALL], obstacle_sources=['scan'])
    world.drive = world.scanning = False
    world.probe.plan_pub.publish(poses_to_path(PLAN))
    # odometry moves from x = 0 (t = 1.05) to x = 0.3 (t = 1.45); then a scan stamped at
    # 1.25, taken where the robot was then (x = 0.15), comes last
    for k in range(1, 9):
        world.state = np.array([0.3 * (k - 1) / 7, 0.0, 0.0])
        world.tick()
    t_scan = 1.225  # between the odometry of 1.2 (x = 0.129) and 1.25 (x = 0.171)
    pose_then = np.array([0.15, 0.0, 0.0])
    world.scan_pub.publish(world.scan_message(pose_then, t_scan))

    def wall_shown() -> bool:
        return any(len(v) and np.min(v[:, 0]) < 2.0 for v in world.raw())

    assert ros.spin_until(lambda: world.node.scan_time is not None, timeout=10.0)
    assert world.run_until(wall_shown, timeout=20.0)
    pieces = [v for v in world.raw() if len(v)]
    near = np.vstack(pieces)
    # the surface the laser saw is at x = 1.2 in the map frame (the latest pose would put
    # it 0.15 m further, at 1.35); pieces are 4 cm thick, centred on the surface
    assert np.all(np.abs(near[:, 0] - WALL_X) < 0.05), near
    assert np.max(near[:, 1]) > 0.5 and np.min(near[:, 1]) < -0.5  # across the plan

    # now the robot drives (on the commands), scanning as it goes: the plan through the wall
    # is followed, not refused; the robot stops in front of the wall
    world.drive = world.scanning = True
    first = len(world.probe.diagnostics)
    world.run_for(12.0)
    steps = world.steps(first)
    assert all(s.reason is not Reason.INVALID_PLAN for s in steps)
    assert any(s.reason is Reason.TRACKING and s.v > 0.01 for s in steps)
    blocked = [s for s in steps if s.path_blocked]
    assert blocked, steps[-3:]
    last = steps[-1]
    assert last.path_blocked
    # blocked_at: from the robot's projection to the grown wall's face (surface - 2 cm
    # thickness/2 - inflation 3.1 cm)
    assert last.blocked_at == pytest.approx(WALL_X - last.x - 0.051, abs=0.05)
    positions = np.array(world.positions)
    assert not np.any(inside(WALL, positions))
    assert np.max(positions[:, 0]) < WALL_X - 0.02
    assert np.max(positions[:, 0]) > 0.5  # it drove up to the wall
    check_commands(world.probe)


# ----------------------------------------------------------------------------- (a')
def test_a_scan_newer_than_the_odometry_is_placed_along_its_twist_or_waits_for_odometry(
        ros) -> None:
    """Odometry in bursts (issue 21): a scan after the latest odometry lands where it is.

    The robot drives at 1 m/s toward the wall. A scan stamped 80 ms after the latest
    odometry, placed with that older pose, would put the wall 8 cm closer than it is (a
    phantom obstacle); extrapolated along the odometry's twist it lands on the wall. A scan
    0.5 s ahead, beyond MAX_EXTRAPOLATION_S, waits, renews nothing, and is placed when the
    odometry's next burst covers its stamp (with the old pose it would be 0.5 m short).
    """
    world = World(ros, [WALL], obstacle_sources=['scan'], scan_timeout=1.0)
    node = world.node
    world.probe.plan_pub.publish(poses_to_path(PLAN))
    v = 1.0
    sent = {'odometry': 0.0, 'clock': 0.0}  # the newest odometry stamp and clock sent

    def x(t: float) -> float:  # the robot is at x = t - 1 m, driving at v along x
        return v * (t - 1.0)

    def odometry(t: float) -> None:
        sent['odometry'] = max(sent['odometry'], t)
        world.probe.odom_pub.publish(state_to_odometry(
            np.array([x(t), 0.0, 0.0]), np.array([v, 0.0]), stamp=seconds_to_stamp(t)))

    def clock(t: float) -> None:
        sent['clock'] = max(sent['clock'], t)
        world.probe.publish_clock(sent['clock'])

    def odometry_received() -> bool:
        return node.odom_state is not None and node.odom_state[0] >= x(
            sent['odometry']) - 1e-9

    def placed(stamp: float, markers_before: int) -> list[np.ndarray]:
        """The raw markers once the scan stamped stamp is used and the markers resent."""
        assert ros.spin_until(lambda: (node.scan_stamp or 0.0) >= stamp - 1e-9,
                              timeout=10.0)
        deadline = time.monotonic() + 30.0
        while not (len(world.markers) > markers_before and any(len(p) for p in world.raw())):
            assert time.monotonic() < deadline, 'no markers'
            clock(sent['clock'] + 0.05)  # control steps, no odometry (none is needed)
            ros.settle()
        return [p for p in world.raw() if len(p)]

    def on_the_wall(pieces: list[np.ndarray]) -> None:
        near = np.vstack(pieces)
        # pieces are 4 cm thick, centred on the surface: within 2 cm of x = 1.2 when
        # placed with the pose at the stamp; 8 cm (0.5 m) short with the older pose
        assert np.all(np.abs(near[:, 0] - WALL_X) < 0.035), near[:, 0]
        assert abs(np.mean(near[:, 0]) - WALL_X) < 0.02, near[:, 0]

    # odometry at 20 Hz up to 1.15 s (x = 0.15), then a scan taken at 1.23 s (x = 0.23)
    for k in range(4):
        odometry(1.0 + 0.05 * k)
        clock(1.0 + 0.05 * k)
    assert ros.spin_until(odometry_received, timeout=10.0)
    t_scan = 1.23
    clock(t_scan)
    world.scan_pub.publish(world.scan_message(np.array([x(t_scan), 0.0, 0.0]), t_scan))
    on_the_wall(placed(t_scan, len(world.markers)))
    scan_time = node.scan_time
    assert scan_time == pytest.approx(t_scan)

    # the odometry catches up with the clock, then a scan 0.5 s after the newest: beyond
    # the bound, it waits
    while sent['odometry'] < sent['clock']:
        odometry(sent['odometry'] + 0.05)
    assert ros.spin_until(odometry_received, timeout=10.0)
    t0 = sent['odometry']
    t_ahead = t0 + 0.5
    clock(t_ahead)
    world.scan_pub.publish(world.scan_message(np.array([x(t_ahead), 0.0, 0.0]), t_ahead))
    assert ros.spin_until(lambda: node.pending_scans == 1
                          or node.scan_stamp > t_scan, timeout=10.0)
    assert node.scan_stamp == pytest.approx(t_scan)  # not placed with the pose at t0
    assert node.scan_time == scan_time  # and it renews nothing while it waits
    # the odometry's burst: 20 Hz from t0 to past the scan, all at once
    for k in range(1, 12):
        odometry(t0 + 0.05 * k)
    clock(sent['odometry'])
    on_the_wall(placed(t_ahead, len(world.markers)))
    assert node.pending_scans == 0
    assert node.scan_time == pytest.approx(t_ahead)


# ----------------------------------------------------------------------------- (b)
def test_a_wall_behind_the_robot_is_remembered_until_obstacle_memory_expires(ros) -> None:
    memory = 2.0
    world = World(ros, [WALL], obstacle_sources=['scan'], obstacle_memory=memory)
    world.drive = False
    # within reach of the wall: obstacles farther than the horizon's reach (v_max N h plus
    # the inflation and a margin, 1.15 m here) are not handed to the MPC, nor shown
    world.state = np.array([0.4, 0.0, 0.0])
    world.probe.plan_pub.publish(poses_to_path(PLAN))
    assert world.run_until(lambda: any(len(v) and np.min(v[:, 0]) < 2.0 for v in world.raw()))
    seen = world.t
    # the robot turns away: its scans no longer see the wall (its field of view is 180 deg)
    world.state = np.array([0.4, 0.0, math.pi])

    def wall_shown() -> bool:
        return any(len(v) and abs(np.mean(v[:, 0]) - WALL_X) < 0.1 for v in world.raw())

    world.run_for(memory - 0.5)
    assert wall_shown(), 'forgotten before obstacle_memory'
    assert world.run_until(lambda: not wall_shown() or world.t > seen + memory + 1.0)
    assert not wall_shown()
    assert seen + memory - 0.1 <= world.t <= seen + memory + STEP + 0.1 + 0.05


def goes_stale(world: World, last_usable: float) -> Any:
    """Run until a step stops for a stale scan; check it came within one period, with zero.

    Returns that step's diagnostics.
    """
    first = len(world.probe.diagnostics)
    assert world.run_until(lambda: any(s.reason is Reason.STALE_SCAN
                                       for s in world.steps(first)))
    stale = next(d for d in world.probe.diagnostics[first:]
                 if d.step.reason is Reason.STALE_SCAN)
    assert stale.stamp <= last_usable + SCAN_TIMEOUT + STEP + 1e-6
    assert stale.step.v == 0 and stale.step.omega == 0
    return stale

# ----------------------------------------------------------------------------- (c)
def test_a_stale_scan_stops_the_robot_within_one_period_and_fresh_scans_resume(ros) -> None:
    world = World(ros, [], obstacle_sources=['scan'], scan_timeout=SCAN_TIMEOUT)
    world.scanning = False
    world.probe.plan_pub.publish(poses_to_path(PLAN))
    # before the first scan: no scan yet, zero
    assert world.run_until(lambda: any(s.reason is Reason.NO_SCAN for s in world.steps()))
    assert all(s.v == 0 and s.omega == 0 for s in world.steps())
    world.scanning = True
    assert world.run_until(lambda: any(s.reason is Reason.TRACKING and s.v > 0.01
                                       for s in world.steps()))
    world.scanning = False
    last_scan = world.t
    stale = goes_stale(world, last_scan)
    assert world.probe.diagnostics[-1].message == 'scan is stale'
    after = world.probe.diagnostics.index(stale)
    world.run_for(0.5)
    assert all(d.step.v == 0 and d.step.omega == 0 for d in world.probe.diagnostics[after:])
    world.scanning = True
    resume = len(world.probe.diagnostics)
    assert world.run_until(lambda: any(s.reason is Reason.TRACKING and s.v > 0.01
                                       for s in world.steps(resume)))
    check_commands(world.probe)


# ----------------------------------------------------------------------------- (d)
def bad_scans(world: World) -> dict[str, tuple[Callable[[], LaserScan], str]]:
    def changed(**fields) -> Callable[[], LaserScan]:
        def make() -> LaserScan:
            msg = world.scan_message(world.state, world.t)
            for name, value in fields.items():
                if name == 'frame_id':
                    msg.header.frame_id = value
                else:
                    setattr(msg, name, value)
            return msg
        return make

    return {
        'nan range_max': (changed(range_max=math.nan), 'range_max must be finite'),
        'range_max below range_min': (changed(range_min=2.0, range_max=1.0),
                                      'range_min < range_max'),
        'zero increment': (changed(angle_increment=0.0), 'angle_increment must not be 0'),
        'nan increment': (changed(angle_increment=math.nan), 'angle_increment must be finite'),
        'intensities': (changed(intensities=[1.0] * 3), 'intensities'),
        '100,000 beams': (changed(ranges=[1.0] * 100_000), '100000 beams'),
        'other frame': (changed(frame_id='laser'), "frame 'laser' is not 'base_link'"),
    }


def grid(width: int = 40, height: int = 40, resolution: float = 0.05,
         origin: tuple[float, float] = (-1.0, -1.0), cells=None) -> OccupancyGrid:
    msg = OccupancyGrid()
    msg.header.frame_id = 'map'
    msg.info.width, msg.info.height, msg.info.resolution = width, height, resolution
    msg.info.origin.position.x, msg.info.origin.position.y = origin
    msg.info.origin.orientation = yaw_to_quaternion(0.0)
    msg.data = [0] * (width * height) if cells is None else cells
    return msg


BAD_GRIDS = {
    'data length': (lambda: grid(cells=[0] * 7), 'data has 7'),
    'zero resolution': (lambda: grid(resolution=0.0), 'resolution must be > 0'),
    'nan origin': (lambda: grid(origin=(math.nan, 0.0)), 'origin'),
    'other frame': (lambda: _framed(grid(), 'odom'), "frame 'odom' is not 'map'"),
}


def _framed(msg: OccupancyGrid, frame: str) -> OccupancyGrid:
    msg.header.frame_id = frame
    return msg


def test_malformed_scans_and_grids_get_one_error_each_and_never_a_bad_command(
        ros, throttle_clock) -> None:
    world = World(ros, [], obstacle_sources=['scan', 'map'], scan_timeout=SCAN_TIMEOUT)
    world.drive = False
    world.probe.plan_pub.publish(poses_to_path(PLAN))
    world.map_pub.publish(grid())  # with 'map' a source, the robot waits for a valid one
    assert world.run_until(lambda: any(s.reason is Reason.TRACKING for s in world.steps()))
    for case, (make, text) in bad_scans(world).items():
        world.scanning = False
        for _ in range(3):  # the same problem, again and again: one error (throttled)
            world.scan_pub.publish(make())
            world.tick()
        assert world.run_until(lambda: world.errors(text), timeout=10.0), case  # noqa: B023
        lines = world.errors(text)
        assert len(lines) == 1, lines  # the throttle's clock is held
        assert lines[0].startswith('invalid scan')
        # only bad scans: the scan goes stale and the robot stops
        assert world.run_until(lambda: world.steps()[-1].reason is Reason.STALE_SCAN), case
        world.scanning = True  # good scans again: the channel recovers (and reports anew)
        assert world.run_until(lambda: world.steps()[-1].reason is Reason.TRACKING), case
    for case, (make, text) in BAD_GRIDS.items():
        for _ in range(3):
            world.map_pub.publish(make())
            world.tick()
        assert world.run_until(lambda: world.errors(text), timeout=10.0), case  # noqa: B023
        lines = world.errors(text)
        assert len(lines) == 1, lines  # the throttle's clock is held
        assert lines[0].startswith('invalid map')
        world.map_pub.publish(grid())  # a valid map resolves the channel
        world.run_for(0.2)
    assert world.steps()[-1].reason is Reason.TRACKING
    check_commands(world.probe)


# ----------------------------------------------------------------------------- (e)
def test_an_occupied_block_in_the_map_becomes_rectangles_and_the_plan_is_followed_up_to_it(
        ros) -> None:
    world = World(ros, [], obstacle_sources=['map'])
    # 5 cm cells from (-1, -1); a block of cells over x in [1.0, 1.3], y in [-0.5, 0.5]
    width = height = 80
    cells = np.zeros((height, width), dtype=np.int8)
    cells[10:30, 40:46] = 100
    world.map_pub.publish(grid(width, height, 0.05, (-1.0, -1.0), cells.ravel().tolist()))
    world.probe.plan_pub.publish(poses_to_path(PLAN))
    assert world.run_until(lambda: world.raw(), timeout=20.0)
    block = ConvexPolygon.from_box(1.0, -0.5, 1.3, 0.5)
    shown = np.vstack(world.raw())
    assert np.all(block.contains(shown, margin=1e-6))
    # the cells within the window (the reach plus a margin, 1.15 m from the robot) count
    np.testing.assert_allclose([shown[:, 0].min(), shown[:, 1].min(), shown[:, 1].max()],
                               [1.0, -0.5, 0.5], atol=1e-6)
    assert shown[:, 0].max() >= 1.15
    world.run_for(10.0)
    steps = world.steps()
    assert all(s.reason is not Reason.INVALID_PLAN for s in steps)
    assert steps[-1].path_blocked
    assert steps[-1].blocked_at == pytest.approx(1.0 - 0.031 - steps[-1].x, abs=0.05)
    positions = np.array(world.positions)
    assert np.max(positions[:, 0]) > 0.5
    assert not np.any(inside(block, positions))
    check_commands(world.probe)


# ----------------------------------------------------------------------------- (f)
# A real laser (REP 117): about 1 % of its readings are NaN (erroneous) and 0.2 % -inf (an
# object too close to measure), at random beams; 720 beams over the front half-plane, so
# that hardly a scan comes without them.
REAL_BEAMS = 720
NAN_SHARE = 0.01
TOO_CLOSE_SHARE = 0.002
BODY_RADIUS = 0.2  # the robot's radius (m), its laser at the centre


class RealLaserReadings:
    """Turn a random NaN_SHARE of the beams into NaN and TOO_CLOSE_SHARE into -inf."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.nan = self.too_close = 0

    def __call__(self, ranges: np.ndarray) -> np.ndarray:
        draw = self.rng.random(len(ranges))
        nan = draw < NAN_SHARE
        too_close = (draw >= NAN_SHARE) & (draw < NAN_SHARE + TOO_CLOSE_SHARE)
        self.nan += int(nan.sum())
        self.too_close += int(too_close.sum())
        return np.where(nan, math.nan, np.where(too_close, -math.inf, ranges))


def test_a_laser_with_nan_and_minus_inf_readings_is_used_beam_by_beam_to_the_goal(ros) -> None:
    # a round robot of 0.2 m with the laser at its centre: a -inf reading's point at
    # range_min (5 cm) is inside the robot, the robot itself (a mount, a cable) or a spurious
    # reading, never an obstacle; taken for one, it would stop the robot (no input keeps it
    # clear of an obstacle inside it)
    world = World(ros, [WALL], beams=REAL_BEAMS, obstacle_sources=['scan'],
                  scan_timeout=SCAN_TIMEOUT, robot_radius=BODY_RADIUS)
    readings = world.readings = RealLaserReadings(seed=117)
    world.probe.plan_pub.publish(poses_to_path(PLAN))

    def stopped_at_the_wall() -> bool:
        steps = world.steps()
        return (world.state[0] > WALL_X - 0.5 and len(steps) > 5
                and all(s.path_blocked and abs(s.v) < 0.01 for s in steps[-5:]))

    # the wall across the plan is seen through the bad readings: the robot drives up to it
    # and stops in front of it
    assert world.run_until(stopped_at_the_wall, timeout=60.0)
    assert not np.any(inside(WALL, np.array(world.positions)))
    # the wall is taken away: the beams that now pass where it was clear it from the memory
    # (NaN and -inf ones clear nothing), and the robot drives on to the goal
    world.laser = None

    def at_goal() -> bool:
        return bool(np.hypot(*(world.state[:2] - PLAN[-1, :2])) < 0.1)

    assert world.run_until(at_goal, timeout=90.0), world.steps()[-3:]
    assert readings.nan > 0 and readings.too_close > 0
    # every scan was used: none refused, the scan never went stale once it came, and the
    # robot drove most of the time: it stopped only at the wall (the -inf readings, inside
    # it, stop nothing: taken for obstacles, they held it still nine steps in ten)
    assert not world.errors('invalid scan')
    steps = world.steps()
    first_scan = next(i for i, s in enumerate(steps) if s.reason is not Reason.NO_SCAN)
    assert not [s for s in steps[first_scan:] if s.reason is Reason.STALE_SCAN]
    assert sum(s.v > 0.01 for s in steps) >= len(steps) / 2
    check_commands(world.probe)


# ----------------------------------------------------------------------------- (g)
def test_scans_without_a_usable_reading_renew_nothing_and_only_blind_scans_go_stale(
        ros) -> None:
    world = World(ros, [], obstacle_sources=['scan'], scan_timeout=SCAN_TIMEOUT)
    world.probe.plan_pub.publish(poses_to_path(PLAN))
    assert world.run_until(lambda: any(s.reason is Reason.TRACKING and s.v > 0.01
                                       for s in world.steps()))

    def blind(ranges: np.ndarray) -> np.ndarray:
        return np.full_like(ranges, math.nan)

    # every other scan blind: the others keep the scan fresh, the robot drives on
    count = [0]

    def every_other(ranges: np.ndarray) -> np.ndarray:
        count[0] += 1
        return blind(ranges) if count[0] % 2 else ranges

    world.readings = every_other
    first = len(world.probe.diagnostics)
    world.run_for(1.0)
    assert all(s.reason is Reason.TRACKING for s in world.steps(first))
    # only blind scans: valid (no error), but they renew nothing: stale as without scans
    world.readings = blind
    goes_stale(world, world.t)
    assert not world.errors('invalid scan')
    assert any('without a usable reading' in line
               for line in world.probe.log_lines('mpc_controller', Log.WARN))
    # readings again: it drives on
    world.readings = None
    resume = len(world.probe.diagnostics)
    assert world.run_until(lambda: any(s.reason is Reason.TRACKING and s.v > 0.01
                                       for s in world.steps(resume)))
    check_commands(world.probe)


# ----------------------------------------------------------------------------- track_moving
class Walking(World):
    """The test's world with a walker crossing in front of the robot and a post standing by."""

    POST = ConvexPolygon.from_box(1.6, 1.0, 1.7, 1.1)
    WALKER_X = 1.5
    WALKER_SPEED = 0.8  # m/s, along +y
    WALKER_HALF = 0.15

    def walker_y(self, t: float) -> float:
        return -1.5 + self.WALKER_SPEED * (t - 1.0)

    def publish(self) -> None:
        y, half = self.walker_y(self.t), self.WALKER_HALF
        walker = ConvexPolygon.from_box(self.WALKER_X - half, y - half, self.WALKER_X + half,
                                        y + half)
        self.laser = SimulatedLaser([self.POST, walker], fov=FOV, beams=self.beams,
                                    range_max=5.0)
        super().publish()


def test_with_track_moving_the_node_shows_a_walker_as_a_moving_track_on_mpc_tracks(
        ros) -> None:
    world = Walking(ros, [], obstacle_sources=['scan'], track_moving=True)
    world.drive = False
    shown: list[MarkerArray] = []
    world.io.create_subscription(MarkerArray, TRACKS_TOPIC, shown.append, LOCAL_PLAN_QOS)
    world.probe.plan_pub.publish(poses_to_path(PLAN))

    def markers(ns: str) -> list[Marker]:
        return [m for m in shown[-1].markers if m.ns == ns and m.action == Marker.ADD] \
            if shown else []

    # told moving within a second or so of being tracked (free-space evidence, 4 hits)
    assert world.run_until(lambda: len(markers('moving')) == 1, timeout=30.0)
    assert world.t - 1.0 < 2.5
    world.run_for(0.5)
    (walker,) = markers('moving')
    y = world.walker_y(world.t)
    assert abs(walker.pose.position.x - world.WALKER_X) < 0.3
    assert abs(walker.pose.position.y - y) < 0.3
    (arrow,) = markers('velocity')
    assert arrow.id == walker.id
    heading = np.array([arrow.points[1].x - arrow.points[0].x,
                        arrow.points[1].y - arrow.points[0].y])
    assert heading[1] > 0.5 * world.WALKER_SPEED and abs(heading[0]) < 0.3  # along +y, 1 s
    # the post is tracked too, and static
    assert any(abs(m.pose.position.x - 1.65) < 0.15 and abs(m.pose.position.y - 1.05) < 0.15
               for m in markers('static'))
    # the MPC is given the walker as one moving polygon, with its velocity, where it is now
    (moving,) = [o for o in world.node.controller.obstacles if isinstance(o, MovingPolygon)]
    assert moving.velocity[1] > 0.5 * world.WALKER_SPEED and abs(moving.velocity[0]) < 0.3
    assert moving.contains(np.array([[world.WALKER_X, world.walker_y(world.t)]]),
                           margin=0.1)[0]


def test_track_moving_without_the_scan_is_refused_not_silently_ignored(ros) -> None:
    with pytest.raises(InvalidParameterValueException, match="track_moving needs 'scan'"):
        MpcControllerNode(context=ros.context, parameter_overrides=[
            Parameter('world_file', value=''), Parameter('track_moving', value=True)])
    node = ros.add(MpcControllerNode(context=ros.context, parameter_overrides=[
        Parameter('world_file', value=''), Parameter('obstacle_sources', value=['scan'])]))
    result = node.set_parameters([Parameter('track_moving', value=True)])[0]
    assert result.successful
    refused = node.set_parameters([Parameter('obstacle_sources', value=['world'])])[0]
    assert not refused.successful and "track_moving needs 'scan'" in refused.reason
