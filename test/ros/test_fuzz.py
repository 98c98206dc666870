# SPDX-License-Identifier: Apache-2.0
"""Property-based fuzzing: random, mostly malformed messages never crash or steer the robot.

The conversions either return finite values or raise ValueError. A scan is refused for its
header (angles, limits, lengths), never for its readings: NaN, +-inf, negative and huge
readings are judged beam by beam (REP 117) and give finite points. The controller and the
simulator nodes get random message sequences through their callbacks (called directly, the
way the executor calls them; simulated time is set by the test) and every twist they
publish, as the probe receives it over DDS, is finite and within the unicycle's bounds. A
second controller (namespace ``sensing``, obstacle_sources world, scan and map) gets random
LaserScan and OccupancyGrid messages (and their CDR bytes) among good odometry and scans; a
good scan with random readings is used, one with a broken header refused.
The node tests are marked dds. Hypothesis is derandomized with a bounded number of
examples: the same cases every run.
"""

from __future__ import annotations

import math
from typing import Iterator

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, Quaternion, Twist
from hypothesis import given, HealthCheck, settings
from hypothesis import strategies as st
from nav_msgs.msg import OccupancyGrid, Odometry, Path
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from rclpy.time import Time as RosTime
from sensor_msgs.msg import LaserScan

from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.perception.scans import (
    classify_beams,
    scan_points,
    ScanError,
    validate_scan,
)
from mpc_local_planner.ros.conversions import (
    grid_from_message,
    odometry_to_state,
    path_pose_count,
    path_to_poses,
    pose_to_array,
    poses_to_path,
    quaternion_to_yaw,
    scan_beam_count,
    scan_from_message,
    seconds_to_stamp,
    stamp_to_seconds,
    u_from_twist,
    yaw_to_quaternion,
)
from mpc_local_planner.ros.mpc_controller_node import MpcControllerNode
from mpc_local_planner.ros.node_main import autostart
from mpc_local_planner.ros.qos import CMD_VEL_QOS
from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode
from mpc_local_planner.worlds.world import paper_world

WORLD = paper_world()
U_MAX = Unicycle().u_max
FUZZ = settings(derandomize=True, deadline=None, max_examples=80, database=None,
                suppress_health_check=[HealthCheck.too_slow])

# ----------------------------------------------------------------------------- strategies
SPECIAL = st.sampled_from([0.0, -0.0, math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324,
                           1e-300, 1e6, 1e9])
ANY_FLOAT = st.one_of(SPECIAL, st.floats(allow_nan=True, allow_infinity=True))
NEAR = st.floats(min_value=-3.0, max_value=4.0)  # around the paper's scenario
COORDINATE = st.one_of(NEAR, NEAR, NEAR, ANY_FLOAT)  # mostly plausible
FRAME = st.one_of(st.just('map'), st.just('map'), st.sampled_from(['', 'odom', 'base_link']),
                  st.text(max_size=20))


@st.composite
def quaternions(draw) -> Quaternion:
    if draw(st.booleans()):
        return yaw_to_quaternion(draw(st.floats(-10.0, 10.0)))
    return Quaternion(x=draw(ANY_FLOAT), y=draw(ANY_FLOAT), z=draw(ANY_FLOAT),
                      w=draw(ANY_FLOAT))


@st.composite
def stamps(draw) -> Time:
    return Time(sec=draw(st.integers(-2**31, 2**31 - 1)),
                nanosec=draw(st.integers(0, 2**32 - 1)))


@st.composite
def odometries(draw, stamp: Time | None = None) -> Odometry:
    msg = Odometry()
    msg.header.frame_id = draw(FRAME)
    msg.header.stamp = stamp if stamp is not None else draw(stamps())
    msg.pose.pose.position.x = draw(COORDINATE)
    msg.pose.pose.position.y = draw(COORDINATE)
    msg.pose.pose.position.z = draw(ANY_FLOAT)
    msg.pose.pose.orientation = draw(quaternions())
    msg.twist.twist.linear.x = draw(ANY_FLOAT)
    return msg


@st.composite
def paths(draw, max_poses: int = 12) -> Path:
    msg = Path()
    msg.header.frame_id = draw(FRAME)
    for _ in range(draw(st.integers(0, max_poses))):
        pose = PoseStamped()
        pose.header.frame_id = msg.header.frame_id
        pose.pose.position.x = draw(COORDINATE)
        pose.pose.position.y = draw(COORDINATE)
        pose.pose.orientation = draw(quaternions())
        msg.poses.append(pose)
    return msg


RANGE = st.one_of(st.floats(0.1, 5.0), st.floats(0.1, 5.0), SPECIAL, st.floats(-1.0, 0.0))
INCREMENT = st.one_of(st.just(math.pi / 90), st.just(-math.pi / 90),
                      st.sampled_from([0.0, math.nan, math.inf, 1e-9, 2.0]), ANY_FLOAT)
SCAN_FRAME = st.one_of(st.just('base_link'), st.just('base_link'),
                       st.sampled_from(['', 'laser', 'map']))


@st.composite
def scans(draw, stamp: Time | None = None) -> LaserScan:
    msg = LaserScan()
    msg.header.frame_id = draw(SCAN_FRAME)
    msg.header.stamp = stamp if stamp is not None else draw(stamps())
    msg.angle_min = draw(st.one_of(st.just(-math.pi / 2), ANY_FLOAT))
    msg.angle_increment = draw(INCREMENT)
    msg.range_min = draw(st.one_of(st.just(0.05), ANY_FLOAT))
    msg.range_max = draw(st.one_of(st.just(5.0), ANY_FLOAT))
    msg.ranges = draw(st.lists(RANGE, max_size=91))
    if draw(st.booleans()):
        msg.intensities = draw(st.lists(st.floats(0.0, 1.0), max_size=91))
    return msg


# a good scan's beam count (good_scan below), with any readings
READINGS = st.lists(RANGE, min_size=91, max_size=91)
# what makes a scan impossible to interpret, whatever its readings
BROKEN_HEADERS = st.sampled_from([
    ('angle_increment', 0.0), ('angle_increment', math.nan), ('angle_min', math.inf),
    ('range_min', math.nan), ('range_min', -0.1), ('range_max', 0.05), ('range_max', 0.01),
    ('range_max', math.inf), ('angle_max', 0.0), ('intensities', [1.0] * 3),
])


@st.composite
def grids(draw) -> OccupancyGrid:
    msg = OccupancyGrid()
    msg.header.frame_id = draw(st.one_of(st.just('map'), st.just('map'), FRAME))
    width, height = draw(st.integers(0, 12)), draw(st.integers(0, 12))
    msg.info.width, msg.info.height = width, height
    msg.info.resolution = draw(st.one_of(st.sampled_from([0.05, 0.1, 0.2]), ANY_FLOAT))
    msg.info.origin.position.x = draw(COORDINATE)
    msg.info.origin.position.y = draw(COORDINATE)
    msg.info.origin.orientation = draw(quaternions())
    count = width * height if draw(st.booleans()) else draw(st.integers(0, 200))
    msg.data = draw(st.lists(st.one_of(st.sampled_from([-1, 0, 100]), st.integers(-128, 127)),
                             min_size=count, max_size=count))
    return msg


@st.composite
def twists(draw) -> Twist:
    msg = Twist()
    msg.linear.x = draw(st.one_of(st.floats(-1.0, 1.0), ANY_FLOAT))
    msg.angular.z = draw(st.one_of(st.floats(-3.0, 3.0), ANY_FLOAT))
    msg.linear.y, msg.angular.x = draw(ANY_FLOAT), draw(ANY_FLOAT)
    return msg


# ----------------------------------------------------------------------------- conversions
@FUZZ
@given(q=quaternions())
def test_quaternion_to_yaw_gives_a_finite_angle_or_value_error(q: Quaternion) -> None:
    try:
        yaw = quaternion_to_yaw(q)
    except ValueError:
        return
    assert math.isfinite(yaw) and -math.pi <= yaw <= math.pi


@FUZZ
@given(msg=odometries())
def test_odometry_to_state_gives_a_finite_state_or_value_error(msg: Odometry) -> None:
    try:
        state = odometry_to_state(msg)
    except ValueError:
        return
    assert state.shape == (3,) and np.all(np.isfinite(state))
    np.testing.assert_array_equal(pose_to_array(msg.pose.pose), state)


@FUZZ
@given(msg=paths())
def test_path_to_poses_gives_finite_poses_or_value_error_and_the_cdr_count_is_exact(
        msg: Path) -> None:
    assert path_pose_count(serialize_message(msg)) == len(msg.poses)
    try:
        poses = path_to_poses(msg)
    except ValueError:
        return
    assert poses.shape == (len(msg.poses), 3) and np.all(np.isfinite(poses))


@FUZZ
@given(msg=paths(), garbage=st.binary(max_size=64), cut=st.integers(0, 400))
def test_path_pose_count_reads_the_count_or_none_from_cut_or_padded_messages_and_garbage(
        msg: Path, garbage: bytes, cut: int) -> None:
    data = serialize_message(msg)
    # bytes after the count do not change it; a cut message gives the count or "don't know"
    assert path_pose_count(data + garbage) == len(msg.poses)
    assert path_pose_count(data[:cut]) in (None, len(msg.poses))
    # garbage does not raise, and too few bytes for a header and a count mean None
    count = path_pose_count(garbage)
    if len(garbage) < 16:
        assert count is None


@FUZZ
@given(poses=st.lists(st.tuples(ANY_FLOAT, ANY_FLOAT, ANY_FLOAT), max_size=6),
       seconds=ANY_FLOAT)
def test_poses_to_path_and_stamps_refuse_non_finite_values_with_value_error(
        poses: list, seconds: float) -> None:
    arr = np.array(poses, dtype=float).reshape(-1, 3)
    try:
        msg = poses_to_path(arr, stamp=seconds_to_stamp(seconds))
    except ValueError:
        assert not (np.all(np.isfinite(arr)) and 0 <= seconds < 2**31)
        return
    assert stamp_to_seconds(msg.header.stamp) == pytest.approx(seconds, abs=1e-6, rel=1e-12)
    np.testing.assert_allclose(path_to_poses(msg)[:, :2], arr[:, :2])


@FUZZ
@given(msg=scans(), garbage=st.binary(max_size=64), cut=st.integers(0, 200))
def test_scans_convert_and_their_cdr_beam_count_is_exact_or_none(
        msg: LaserScan, garbage: bytes, cut: int) -> None:
    data = serialize_message(msg)
    assert scan_beam_count(data) == len(msg.ranges)
    assert scan_beam_count(data + garbage) == len(msg.ranges)
    assert scan_beam_count(data[:cut]) in (None, len(msg.ranges))
    if len(garbage) < 16:
        assert scan_beam_count(garbage) is None
    scan = scan_from_message(msg)
    assert len(scan.ranges) == len(msg.ranges)


@FUZZ
@given(msg=scans(), readings=READINGS)
def test_a_scan_is_refused_for_its_header_never_for_its_readings_and_gives_finite_points(
        msg: LaserScan, readings: list[float]) -> None:
    scan = scan_from_message(msg)
    calm = scan._replace(ranges=np.ones_like(scan.ranges))  # the same header, plain readings

    def refusal(s) -> str | None:
        try:
            validate_scan(s)
        except ScanError as err:
            return str(err)
        return None

    verdict = refusal(scan)
    assert verdict == refusal(calm)
    header_ok = (all(math.isfinite(v) for v in (msg.angle_min, msg.angle_increment,
                                                 msg.range_min, msg.range_max))
                 and msg.angle_increment != 0.0 and 0.0 <= msg.range_min < msg.range_max)
    if not header_ok:
        assert verdict is not None
    if verdict is not None:
        return
    noisy = scan._replace(ranges=np.asarray(readings[:len(scan.ranges)], dtype=np.float32))
    validate_scan(noisy)
    beams = classify_beams(noisy)
    assert np.all(np.isfinite(beams.free)) and np.all(beams.free >= 0.0)
    assert np.all(beams.free <= scan.range_max)
    ranges = np.asarray(noisy.ranges, dtype=float)
    in_range = (ranges >= scan.range_min) & (ranges <= scan.range_max)
    np.testing.assert_array_equal(beams.hit, in_range | (ranges == -math.inf))
    assert not np.any(beams.free[np.isnan(ranges)])  # a NaN beam clears nothing
    points, _ = scan_points(noisy, (0.5, -0.2, 0.3))
    assert len(points) == int(beams.hit.sum())
    assert np.all(np.isfinite(points))


@FUZZ
@given(msg=grids())
def test_grids_convert_to_a_map_or_raise_value_error(msg: OccupancyGrid) -> None:
    try:
        grid = grid_from_message(msg)
    except ValueError:
        return
    assert grid.data.shape == (msg.info.height, msg.info.width)
    assert grid.resolution > 0 and all(math.isfinite(v) for v in grid.origin)


@FUZZ
@given(twist=twists(), stamp=stamps())
def test_twists_convert_to_finite_numbers_and_stamps_round_trip_to_a_microsecond(
        twist: Twist, stamp: Time) -> None:
    assert np.all(np.isfinite(u_from_twist(twist)))
    seconds = stamp_to_seconds(stamp)
    nanoseconds = stamp.sec * 10**9 + stamp.nanosec  # exact; nanosec may exceed a second
    if not 0.0 <= seconds < 2.0**31:
        with pytest.raises(ValueError, match='a stamp must be'):
            seconds_to_stamp(seconds)
        assert nanoseconds < 0 or nanoseconds >= 2**31 * 10**9 - 10**3
        return
    back = seconds_to_stamp(seconds)
    assert 0 <= back.nanosec < 10**9
    assert abs(back.sec * 10**9 + back.nanosec - nanoseconds) <= 10**3


# ----------------------------------------------------------------------------- nodes
class Nodes:
    """A controller and a simulator in simulated time set by the test, and a probe."""

    def __init__(self, ros) -> None:
        sim_time = [Parameter('use_sim_time', value=True)]
        # the paper's world, named: the controller's default is no world
        controller = [*sim_time, Parameter('world_file', value='paper_obstacle.yaml')]
        self.ros = ros
        # no node is spun: the test calls their callbacks, the executor the probe's
        self.idle = SingleThreadedExecutor(context=ros.context)
        self.controller = MpcControllerNode(context=ros.context, parameter_overrides=controller)
        assert autostart(self.controller) is None  # configured and active, as run_node does
        self.sensing = MpcControllerNode(
            context=ros.context, namespace='sensing', parameter_overrides=controller + [
                Parameter('obstacle_sources', value=['world', 'scan', 'map'])])
        assert autostart(self.sensing) is None
        self.simulator = UnicycleSimulatorNode(context=ros.context,
                                               parameter_overrides=sim_time)
        for node in (self.controller, self.sensing, self.simulator):
            self.idle.add_node(node)
        self.probe = ros.probe()
        self.sensing_cmds: list[Twist] = []
        self.sensing_steps = 0
        self.probe.create_subscription(Twist, 'sensing/cmd_vel', self.sensing_cmds.append,
                                       CMD_VEL_QOS)
        self.t = 1.0
        self.steps = 0
        self.ticks = 0
        assert ros.spin_until(lambda: self.controller.count_subscribers('cmd_vel') > 0
                              and self.sensing.count_subscribers('/sensing/cmd_vel') > 0
                              and self.simulator.count_subscribers('odom') > 0)

    def advance(self, seconds: float) -> None:
        self.t += seconds
        for node in (self.controller, self.sensing, self.simulator):
            node.get_clock().set_ros_time_override(RosTime(nanoseconds=int(self.t * 1e9)))

    def close(self) -> None:
        self.idle.shutdown()
        for node in (self.simulator, self.sensing, self.controller):
            node.destroy_node()


@pytest.fixture(scope='module')
def nodes(ros_module) -> Iterator[Nodes]:
    harness = Nodes(ros_module)
    try:
        yield harness
    finally:
        harness.close()


def valid_plan() -> Path:
    return poses_to_path(np.array([[0.0, 0.0, WORLD.start[2]], [0.8, 1.3, 0.0],
                                   [1.7, 1.3, -0.96], [2.5, 0.0, WORLD.goal[2]]]))


# valid odometry near the plan (stamped up to 2 s late or 1 s early) and the valid plan come
# often enough that the solver runs between the malformed messages
GOOD_ODOM = st.tuples(st.just('good odom'), st.floats(-0.5, 2.5), st.floats(-0.5, 1.5),
                      st.floats(-4.0, 4.0), st.floats(-2.0, 1.0))
EVENTS = st.lists(st.one_of(
    st.tuples(st.just('odom'), odometries()),
    GOOD_ODOM, GOOD_ODOM, GOOD_ODOM,
    st.tuples(st.sampled_from(['plan', 'plan bytes']), paths()),
    st.tuples(st.just('garbage bytes'), st.binary(max_size=40)),
    st.tuples(st.just('good plan')), st.tuples(st.just('good plan')),
    st.tuples(st.just('tick')), st.tuples(st.just('tick')), st.tuples(st.just('tick')),
), min_size=1, max_size=12)


@pytest.mark.dds
@FUZZ
@given(events=EVENTS)
def test_controller_callbacks_survive_random_messages_and_publish_bounded_twists(
        nodes: Nodes, events: list) -> None:
    node = nodes.controller
    for event in events + [('tick',)]:
        kind = event[0]
        if kind == 'odom':
            node.odom_callback(event[1])
        elif kind == 'good odom':
            msg = Odometry()
            msg.header.frame_id = 'odom'
            msg.header.stamp = seconds_to_stamp(max(nodes.t + event[4], 0.0))
            msg.pose.pose.position.x, msg.pose.pose.position.y = event[1], event[2]
            msg.pose.pose.orientation = yaw_to_quaternion(event[3])
            node.odom_callback(msg)
        elif kind == 'plan':
            node.plan_callback(event[1])
        elif kind == 'plan bytes':
            node.plan_callback(serialize_message(event[1]))
        elif kind == 'garbage bytes':
            node.plan_callback(event[1])
        elif kind == 'good plan':
            node.plan_callback(serialize_message(valid_plan()))
        else:
            nodes.advance(0.2)
            node.timer_callback()
            nodes.steps += 1
            u = node.last_output.u
            assert np.all(np.isfinite(u)) and np.all(np.abs(u) <= U_MAX + 1e-12), u
    # what went over DDS: every twist so far, finite and within the bounds
    probe = nodes.probe
    assert nodes.ros.spin_until(lambda: len(probe.cmds) >= nodes.steps, timeout=5.0)
    raw = np.array([[c.linear.x, c.angular.z] for c in probe.cmds])
    assert np.all(np.isfinite(raw)) and np.all(np.abs(raw) <= U_MAX + 1e-12)


@pytest.mark.dds
@FUZZ
@given(commands=st.lists(twists(), min_size=1, max_size=6))
def test_simulator_callbacks_survive_random_twists_and_stay_finite_and_saturated(
        nodes: Nodes, commands: list[Twist]) -> None:
    sim = nodes.simulator
    for twist in commands:
        sim.cmd_vel_callback(twist)
        nodes.advance(0.02)
        sim.timer_callback()
        nodes.ticks += 1
        assert np.all(np.isfinite(sim.state))
    probe = nodes.probe
    assert nodes.ros.spin_until(lambda: len(probe.odoms) >= nodes.ticks, timeout=5.0)
    moving = np.array([u_from_twist(m.twist.twist) for m in probe.odoms])
    raw = np.array([[m.twist.twist.linear.x, m.twist.twist.angular.z] for m in probe.odoms])
    np.testing.assert_array_equal(moving, raw)  # nothing non-finite was published
    assert np.all(np.abs(raw) <= U_MAX + 1e-12)
    assert all(np.all(np.isfinite(odometry_to_state(m))) for m in probe.odoms)


def good_scan(t: float) -> LaserScan:
    """A scan of a wall 1.2 m ahead of a robot at the start, stamped t."""
    msg = LaserScan()
    msg.header.frame_id = 'base_link'
    msg.header.stamp = seconds_to_stamp(max(t, 0.0))
    msg.angle_min, msg.angle_increment = -math.pi / 2, math.pi / 90
    msg.angle_max = math.pi / 2
    msg.range_min, msg.range_max = 0.05, 5.0
    angles = msg.angle_min + np.arange(91) * msg.angle_increment
    ranges = 1.2 / np.cos(angles)
    msg.ranges = [float(r) if abs(1.2 * math.tan(a)) <= 1.0 else math.inf
                  for r, a in zip(ranges, angles, strict=True)]
    return msg


SENSING_EVENTS = st.lists(st.one_of(
    st.tuples(st.sampled_from(['scan', 'scan bytes']), scans()),
    st.tuples(st.just('scan now'), scans(stamp=Time(sec=0, nanosec=0))),
    st.tuples(st.just('grid'), grids()),
    st.tuples(st.just('garbage bytes'), st.binary(max_size=80)),
    st.tuples(st.just('good scan'), st.floats(-1.0, 0.3)), st.tuples(st.just('good scan'),
                                                                      st.floats(-1.0, 0.3)),
    # a good header with any readings is used; a broken header is refused, whatever the
    # readings (stamped within the clock skew accepted, so that only the scan decides)
    st.tuples(st.just('noisy scan'), st.floats(-0.9, 0.1), READINGS),
    st.tuples(st.just('broken scan'), st.floats(-0.9, 0.1), READINGS, BROKEN_HEADERS),
    GOOD_ODOM, GOOD_ODOM,
    st.tuples(st.just('good plan')),
    st.tuples(st.just('tick')), st.tuples(st.just('tick')), st.tuples(st.just('tick')),
), min_size=1, max_size=12)


@pytest.mark.dds
@FUZZ
@given(events=SENSING_EVENTS)
def test_controller_survives_random_scans_and_grids_and_publishes_bounded_twists(
        nodes: Nodes, events: list) -> None:
    node = nodes.sensing
    for event in events + [('tick',)]:
        kind = event[0]
        if kind in ('scan', 'scan now'):
            node.scan_callback(event[1])
        elif kind == 'scan bytes':
            node.scan_callback(serialize_message(event[1]))
        elif kind == 'garbage bytes':
            node.scan_callback(event[1])
        elif kind == 'grid':
            node.map_callback(event[1])
        elif kind == 'good scan':
            node.scan_callback(serialize_message(good_scan(nodes.t + event[1])))
        elif kind in ('noisy scan', 'broken scan'):
            msg = good_scan(nodes.t + event[1])
            msg.ranges = event[2]
            if kind == 'broken scan':
                setattr(msg, *event[3])
            stamp, before = stamp_to_seconds(msg.header.stamp), node.scan_stamp
            node.scan_callback(serialize_message(msg))
            if kind == 'broken scan':
                assert node.scan_stamp == before, event[3]  # refused
            elif node.pose_at(stamp) is not None and (before is None or stamp >= before):
                assert node.scan_stamp == stamp  # used (only an older scan is skipped)
        elif kind == 'good odom':
            msg = Odometry()
            msg.header.frame_id = 'odom'
            msg.header.stamp = seconds_to_stamp(max(nodes.t + event[4], 0.0))
            msg.pose.pose.position.x, msg.pose.pose.position.y = event[1], event[2]
            msg.pose.pose.orientation = yaw_to_quaternion(event[3])
            node.odom_callback(msg)
        elif kind == 'good plan':
            node.plan_callback(serialize_message(valid_plan()))
        else:
            nodes.advance(0.2)
            node.timer_callback()
            nodes.sensing_steps += 1
            u = node.last_output.u
            assert np.all(np.isfinite(u)) and np.all(np.abs(u) <= U_MAX + 1e-12), u
    assert nodes.ros.spin_until(lambda: len(nodes.sensing_cmds) >= nodes.sensing_steps,
                                timeout=5.0)
    raw = np.array([[c.linear.x, c.angular.z] for c in nodes.sensing_cmds])
    assert np.all(np.isfinite(raw)) and np.all(np.abs(raw) <= U_MAX + 1e-12)
