# SPDX-License-Identifier: Apache-2.0
"""unicycle_simulator: a robot base and its laser, as ideal or as real as ``reality`` says.

The node simulates what a real robot does with a velocity command and what its sensors give
back, with ONE model shared with the ROS-free rollout of the evaluation suites (sim/:
`Base` for the base and its odometry, `ScanChannel` for the laser), so the suites measure
what the nodes see. ``reality`` names a preset (ideal|mild|real|harsh, their
values and sources in sim/reality.py); with ``ideal`` (the default) a command acts at once
and exactly (saturated), the odometry is the true pose and the laser is exact.
always did. Otherwise:

- a cmd_vel reaches the motors ``command_latency`` s (simulated) after its arrival;
- the wheels follow it through first-order lags (``actuator_lag`` [v, omega], s) and within
  ``acceleration_limits`` [m/s^2, rad/s^2]; the true pose moves with the wheels;
- the published odometry is integrated apart from the true pose (``odom_drift.*``), with
  white noise of ``odom_noise_std`` [m, rad] on each message, and its twist is what the
  wheels measure (not the command);
- scans carry range noise (``scan.noise_std``), beams reading NaN (``scan.nan_fraction``)
  and -inf (``scan.neg_inf_fraction``), and a ``scan.loss_fraction`` of them is never
  published.

Each override replaces one field of the preset, with one marker: -1 (every override's
default; in a pair, per component) takes the preset's value, and 0 means zero (no noise, no
lag, exact odometry), whatever the preset. ``seed`` seeds every draw (the odometry noise
and, on a stream of their own, the laser's): runs are reproducible. An unknown preset or an
invalid value is refused with the reason.

With ``publish_clock`` the node is the clock: each tick of a steady wall timer, fired at
``rate * real_time_factor`` Hz, advances simulated time by exactly ``1 / rate`` s, publishes
``clock`` and ``odom`` stamped with that time. Nodes with ``use_sim_time`` then run at
``real_time_factor`` times real time, and a slow tick slows the simulation down instead of
making it jump. Without it, the node integrates in ROS time (wall or an external clock).

``cmd_vel`` is a geometry_msgs/Twist, or a TwistStamped with ``enable_stamped_cmd_vel``
(Nav2's parameter; give the controller the same value). A cmd_vel older than ``cmd_timeout``
(a controller that died or hangs; the age counts from its arrival, stamped or not) is
replaced by zero (the base's watchdog: the stop acts at once, without the latency), and so is
one with NaN or inf in linear.x or angular.z (its sender is broken: no part of it is
trusted); the saturation bounds every command that is integrated.

The node holds the TRUE world (``world_file``: known and unknown obstacles, disks as disks;
'' = an empty world). Every ``1 / scan.rate`` s of simulated time (counted in ticks, so the
scans are deterministic under ``publish_clock``) it casts a simulated laser from the robot's
pose and publishes ``scan`` (sensor_msgs/LaserScan in ``robot_base_frame``, the laser at the
robot's origin facing forward, stamped like the odometry of the same pose; ``inf`` where a
beam hits nothing, per REP 117). Each tick it checks the robot's TRUE footprint at its pose
(x, y, theta) against the true world and counts contact EPISODES (entering contact counts one;
staying in contact does not): ``simulator/contacts`` (std_msgs/UInt32, latched) carries the
count, published at start with 0 and again at every new contact, and the first contact is
logged as an ERROR. Each episode is also counted as active (the robot's TRUE motion above
sim/moving.py's ACTIVE_SPEED or ACTIVE_TURN_RATE as it began: it drove into something) or
passive (it stood still and a moving obstacle ran into it), on ``simulator/active_contacts``
and ``simulator/passive_contacts`` (latched likewise; their sum is the total).

The world's ``moving_obstacles`` move in simulated time (the ticks' sim_time, closed form in
t: worlds/motion.py): the laser sees them, and the contact check touches them, where they are
at the tick's time; at every scan period they go out on ``simulator/moving_obstacles``
(visualization_msgs/MarkerArray in ``localizer.global_frame``: disks as cylinders, polygons as
outlines) for RViz. No node of the robot's is told of them.

The footprint, first that applies (Nav2's names; a polygon wins over a radius, as in Nav2):

1. the ``footprint`` parameter, a convex polygon ``"[[x, y], ...]"`` (robot frame, x forward);
2. the world file's ``footprint``, when it has a polygon;
3. a circle of ``robot_radius``; -1 (its default) takes the world's ``robot_radius``.

So a world that describes its robot is simulated with that robot unless the parameter says
otherwise, and ``robot_radius`` (which closed_loop sets from the world's covering radius) never
turns a polygon back into its circumscribed circle.

A real robot's odometry drifts, and the controller must follow the plan in ``map`` all the
same (ros/robot_pose.py). With a drift (``odom_drift.position`` or ``odom_drift.heading``
set, or a preset's; none with ideal: the odometry is the true pose, ``odom`` is ``map``) the
published odometry is integrated apart from the true pose, from the same start, with the
speed scaled by (1 + ``odom_drift.position``) and the turn rate biased by
``odom_drift.heading`` rad per metre travelled; scans, contacts and the localizer stand-in
stay with the true pose. With ``localizer.rate`` > 0 a
localizer stands in for AMCL: at that rate (in ticks, as scans) it publishes the TRUE pose
with Gaussian noise of ``localizer.noise_std`` (m, and rad for the heading) on ``amcl_pose``
(geometry_msgs/PoseWithCovarianceStamped in ``localizer.global_frame``, stamped like the
odometry of the same instant).

With ``plant: mujoco`` (the [physics] extra; refused with the reason without it) the robot
is sim/physics/'s rigid body (``physics.robot``): the same calls, but wheels, slip and
the base controller's limits between cmd_vel and the motion, odometry from the wheels, and
the laser cast by the engine; moving obstacles are mocap bodies it moves on the same
simulated time (sim/physics/plant.py).
"""

from __future__ import annotations

import array
import enum
import math
import sys
from typing import Any

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseWithCovarianceStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import LaserScan
from std_msgs.msg import UInt32
from visualization_msgs.msg import MarkerArray

from mpc_local_planner.core.footprint import Footprint, parse_footprint, resolve
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.scans import Scan
from mpc_local_planner.ros.conversions import (
    cylinder_marker,
    polygon_marker,
    seconds_to_stamp,
    state_to_odometry,
    u_from_twist,
    yaw_to_quaternion,
)
from mpc_local_planner.ros.lockstep import LockstepGate
from mpc_local_planner.ros.node_main import destroy_on_failure, run_node
from mpc_local_planner.ros.parameters import declare_parameters
from mpc_local_planner.ros.qos import (
    CLOCK_QOS,
    CMD_VEL_QOS,
    CONTACTS_QOS,
    LOCALIZER_QOS,
    ODOM_QOS,
)
from mpc_local_planner.ros.throttle import ProblemThrottle
from mpc_local_planner.ros.unicycle_simulator_parameters import (
    ACTIVE_CONTACTS_TOPIC,
    CONTACTS_TOPIC,
    GROUND_TRUTH_TOPIC,
    LOCALIZER_TOPIC,
    LOCKSTEP_STALLS_TOPIC,
    MOVING_OBSTACLES_TOPIC,
    PARAMETERS,
    PASSIVE_CONTACTS_TOPIC,
    reality_from_parameters,
    REALITY_PARAMETERS,
    SCAN_RANGE_MIN,
    SCAN_TOPIC,
    validate_simulator_parameters,
)
from mpc_local_planner.sim.base import Base
from mpc_local_planner.sim.contact import contact
from mpc_local_planner.sim.laser import SimulatedLaser
from mpc_local_planner.sim.moving import ContactCounter, ContactKind, WorldClock
from mpc_local_planner.sim.physics import make_physics_base
from mpc_local_planner.sim.reality import Reality
from mpc_local_planner.sim.scan_channel import ScanChannel
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import load_world, World

__all__ = ['SCAN_PUBLISHER_QOS', 'SUMMARY', 'UnicycleSimulatorNode', 'laser_scan_msg', 'main']

# At most this many integration steps catch up a late tick (real-time mode).
MAX_CATCH_UP_STEPS = 10
# Wall seconds between the lockstep clock's own looks (the participants' reports move it
# between them; this starts it and notices a timeout).
LOCKSTEP_POLL = 0.005


class _Phase(enum.Enum):
    """Where the lockstep clock is in a tick."""

    START = 'waiting for the participants'
    SENSED = 'sensors out, waiting for them to be taken'
    CLOCKED = 'clock out, waiting for the due steps'


def _stamp(nanoseconds: int) -> Time:
    """Return a stamp of whole nanoseconds (exact: timers due at that time fire)."""
    return Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)

# The publisher side of ``scan``: reliable, volatile, depth 10 (best-effort readers match).
SCAN_PUBLISHER_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.VOLATILE,
                                history=HistoryPolicy.KEEP_LAST)
# Tolerance when counting scan periods in ticks (rate / scan.rate need not be an integer).
_TICK_EPS = 1e-9
_SCAN_PARAMETERS = frozenset({'scan.fov', 'scan.beams', 'scan.range_max'})
_FOOTPRINT_PARAMETERS = frozenset({'footprint', 'robot_radius'})
# The moving obstacles' markers: colour, and the cylinders' height (m).
_MOVING_RGBA = (0.9, 0.4, 0.1, 0.8)
_MOVING_HEIGHT = 0.5

SUMMARY = ('Simulate a robot base driven by cmd_vel (Twist, or TwistStamped with '
           'enable_stamped_cmd_vel) with saturation, and as real as the reality parameter '
           'says (ideal|mild|real|harsh: latency, lag, acceleration limits, odometry noise '
           'and drift, laser noise, NaN/-inf beams, lost scans); publish odom, and clock '
           'with publish_clock; simulate a laser (scan) and count contacts with the true '
           'world (simulator/contacts).')


def laser_scan_msg(scan: Scan, *, frame_id: str, stamp: Any) -> LaserScan:
    """Return scan as a sensor_msgs/LaserScan (ranges as float32; inf stays inf)."""
    msg = LaserScan()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    msg.angle_min = float(scan.angle_min)
    msg.angle_max = float(scan.angle_min + (len(scan.ranges) - 1) * scan.angle_increment)
    msg.angle_increment = float(scan.angle_increment)
    msg.time_increment = 0.0  # every beam cast at the same instant
    msg.scan_time = 0.0
    msg.range_min = float(scan.range_min)
    msg.range_max = float(scan.range_max)
    ranges = array.array('f')
    ranges.frombytes(np.asarray(scan.ranges, dtype=np.float32).tobytes())
    msg.ranges = ranges
    return msg


def _load_true_world(name: str) -> World | None:
    """Return the world named by world_file ('' = None: an empty world).

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: if it is not a valid world (WorldError).

    """
    if not name:
        return None
    return load_world(resolve_data_file(name))


class UnicycleSimulatorNode(Node):
    """Integrate a unicycle driven by cmd_vel; publish odom and optionally clock."""

    @destroy_on_failure
    def __init__(self, **kwargs: Any) -> None:
        super().__init__('unicycle_simulator', **kwargs)
        self.add_on_set_parameters_callback(self.parameters_callback)
        declare_parameters(self, PARAMETERS)
        self.add_post_set_parameters_callback(self.post_parameters_callback)
        pose = np.array(self.get_parameter('initial_pose').value, dtype=float)
        self._model = self._read_model()
        reality = self._read_reality()
        # the robot: its true pose, its wheels and its odometry, on the simulation's time
        # axis (sim_time); the rollout drives the same Base
        self._base = Base(self._model, reality, pose,
                          dt=1.0 / float(self.get_parameter('rate').value))
        self._scan_channel = ScanChannel(reality)
        if not reality.ideal:
            self.get_logger().info(f'reality: {self.get_parameter("reality").value} '
                                   f'{reality.as_dict()}')
        self._sim_time = 0.0
        self._last_cmd_time: float | None = None
        self._timed_out = False  # cmd_timeout has stopped the base since the last cmd_vel
        self._last_tick: float | None = None
        self._problems = ProblemThrottle(2.0)
        self._world = _load_true_world(str(self.get_parameter('world_file').value))
        # the true world at each tick's time (moving obstacles where they are then)
        self._world_clock = WorldClock.from_world(self._world)
        self._footprint = self._read_footprint()
        if self.get_parameter('plant').value == 'mujoco':  # validated: MuJoCo is installed
            self._base = make_physics_base(
                self._model, reality, pose, robot=str(self.get_parameter('physics.robot').value),
                footprint=self._footprint,
                shapes=self._world.physical_shapes() if self._world else (), dt=self._base.dt,
                odometry=str(self.get_parameter('physics.odometry').value),
                moving=self._world_clock.moving)
        # scan periods elapsed since the last scan, advanced by scan.rate / rate per tick:
        # scans follow the simulation's steps, not the wall clock
        self._scan_phase = 0.0
        self._localizer_phase = 0.0
        self._localizer_rng = np.random.default_rng(
            int(self.get_parameter('localizer.seed').value))
        self._contact_counter = ContactCounter()
        self._laser = self._make_laser()
        self._odom_pub = self.create_publisher(Odometry, 'odom', ODOM_QOS)
        self._scan_pub = self.create_publisher(LaserScan, SCAN_TOPIC, SCAN_PUBLISHER_QOS)
        self._contacts_pub = self.create_publisher(UInt32, CONTACTS_TOPIC, CONTACTS_QOS)
        self._truth_pub = self.create_publisher(Odometry, GROUND_TRUTH_TOPIC, ODOM_QOS)
        self._localizer_pub = self.create_publisher(PoseWithCovarianceStamped, LOCALIZER_TOPIC,
                                                    LOCALIZER_QOS)
        self._active_pub = self.create_publisher(UInt32, ACTIVE_CONTACTS_TOPIC, CONTACTS_QOS)
        self._passive_pub = self.create_publisher(UInt32, PASSIVE_CONTACTS_TOPIC, CONTACTS_QOS)
        # always there (RViz's display finds its publisher); silent when nothing moves
        self._moving_pub = self.create_publisher(MarkerArray, MOVING_OBSTACLES_TOPIC,
                                                 SCAN_PUBLISHER_QOS)
        for publisher in (self._contacts_pub, self._active_pub, self._passive_pub):
            publisher.publish(UInt32(data=0))
        self._clock_pub = self.create_publisher(ClockMsg, 'clock', CLOCK_QOS)
        cmd_type = TwistStamped if self.get_parameter('enable_stamped_cmd_vel').value else Twist
        self._cmd_sub = self.create_subscription(cmd_type, 'cmd_vel', self.cmd_vel_callback,
                                                 CMD_VEL_QOS)
        self._steady_clock = Clock(clock_type=ClockType.STEADY_TIME)
        self._gate: LockstepGate | None = None
        self._lockstep_busy = False
        self._stalls_published = 0
        if self.get_parameter('lockstep').value:
            self._start_lockstep()
        self._timer = None
        self._make_timer()

    # ------------------------------------------------------------------ parameters
    def parameters_callback(self, parameters: list[Parameter]) -> SetParametersResult:
        """Refuse invalid values with the reason (validate_simulator_parameters).

        Reality parameters are also checked together with the current values of the others
        (e.g. scan.nan_fraction + scan.neg_inf_fraction < 1 with the preset's filled in).
        """
        values = {p.name: p.value for p in parameters}
        try:
            reason = validate_simulator_parameters(values)
            if reason is None and REALITY_PARAMETERS & set(values):
                reality_from_parameters({**self._reality_values(), **values})
        except (TypeError, ValueError) as err:
            reason = str(err) if REALITY_PARAMETERS & set(values) else f'invalid value: {err}'
        if reason is not None:
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def post_parameters_callback(self, parameters: list[Parameter]) -> None:
        """Apply new bounds and rates (rate changes restart the timer)."""
        names = {p.name for p in parameters}
        if names & {'v_max', 'omega_max'}:
            self._model = self._read_model()
            self._base.model = self._model  # saturates the commands sent from now on
        if names & {'rate', 'real_time_factor'}:
            self._make_timer()
        if names & _SCAN_PARAMETERS:
            self._laser = self._make_laser()
        if names & REALITY_PARAMETERS:
            # the base keeps its state (pose, wheels, commands on their way, odometry's
            # noise stream); the laser's draws restart from the seed
            reality = self._read_reality()
            self._base.reality = reality
            self._scan_channel = ScanChannel(reality)
        if names & _FOOTPRINT_PARAMETERS:
            self._footprint = self._read_footprint()

    def _read_model(self) -> Unicycle:
        return Unicycle(v_max=float(self.get_parameter('v_max').value),
                        omega_max=float(self.get_parameter('omega_max').value))

    def _read_footprint(self) -> Footprint:
        """Return the footprint contacts are counted with (precedence: module docstring)."""
        # validated by parameters_callback: parsing cannot fail here
        parameter = str(self.get_parameter('footprint').value)
        world = self._world
        footprint = resolve(parameter, float(self.get_parameter('robot_radius').value),
                            world.footprint if world else None,
                            world.robot_radius if world else 0.0)
        if not footprint.is_circle:
            source = ('the footprint parameter' if not parse_footprint(parameter).is_circle
                      else f'the world {world.name!r}')
            self.get_logger().info(
                f'contacts counted with the polygon {footprint.vertices.tolist()} from '
                f'{source}')
        return footprint

    def _reality_values(self) -> dict[str, Any]:
        """Return the reality parameters' values, of the declared ones.

        During the declaration the rest are missing: reality_from_parameters then takes the
        preset's for them, and the last declaration checks the whole.
        """
        return {name: self.get_parameter(name).value for name in REALITY_PARAMETERS
                if self.has_parameter(name)}

    def _read_reality(self) -> Reality:
        # validated by parameters_callback: cannot fail here
        return reality_from_parameters(self._reality_values())

    def _make_laser(self) -> SimulatedLaser:
        """Return the exact laser: its noise is the ScanChannel's (applied once, there).

        On the mujoco plant the engine casts it (the same Scan).
        """
        if hasattr(self._base, 'laser'):
            return self._base.laser(fov=float(self.get_parameter('scan.fov').value),
                                    beams=int(self.get_parameter('scan.beams').value),
                                    range_min=SCAN_RANGE_MIN,
                                    range_max=float(self.get_parameter('scan.range_max').value))
        return SimulatedLaser(self._world_clock, fov=float(self.get_parameter('scan.fov').value),
                              beams=int(self.get_parameter('scan.beams').value),
                              range_min=SCAN_RANGE_MIN,
                              range_max=float(self.get_parameter('scan.range_max').value))

    def _start_lockstep(self) -> None:
        """Hold the clock for the participants (ros/lockstep.py), in whole nanosecond ticks.

        Raises:
            ValueError: without publish_clock (a lockstep clock must be the clock).

        """
        if not self.get_parameter('publish_clock').value:
            msg = 'lockstep needs publish_clock: true (the simulator must be the clock)'
            raise ValueError(msg)
        participants = [str(name) for name in
                        self.get_parameter('lockstep.participants').value if str(name)]
        self._gate = LockstepGate(self, participants,
                                  float(self.get_parameter('lockstep.timeout').value),
                                  on_status=self._lockstep_progress)
        self._stalls_pub = self.create_publisher(UInt32, LOCKSTEP_STALLS_TOPIC, CONTACTS_QOS)
        self._stalls_pub.publish(UInt32(data=0))
        self._gate.own.attach()  # counts odom, scan, amcl_pose out and cmd_vel in
        self._phase = _Phase.START
        self._ticks = 0
        self.get_logger().info(f'lockstep: the clock waits for {participants}')

    def _make_timer(self) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
        rate = float(self.get_parameter('rate').value)
        self._dt = 1.0 / rate
        self._base.dt = self._dt  # the base's sub-step is the tick
        if self._gate is not None:
            # the participants' reports move the clock; this poll starts it and times out
            self._tick_ns = int(round(1e9 / rate))
            self._timer = self.create_timer(LOCKSTEP_POLL, self._lockstep_progress,
                                            clock=self._steady_clock)
        elif self.get_parameter('publish_clock').value:
            rtf = float(self.get_parameter('real_time_factor').value)
            self._timer = self.create_timer(self._dt / rtf, self.timer_callback,
                                            clock=self._steady_clock)
        else:
            self._timer = self.create_timer(self._dt, self.timer_callback)

    # ------------------------------------------------------------------ callbacks
    @property
    def state(self) -> np.ndarray:
        """The TRUE pose (x, y, theta), theta unwrapped."""
        return self._base.pose.copy()

    @property
    def odometry(self) -> np.ndarray:
        """The pose odometry integrates (x, y, theta): the true one unless it drifts.

        Without the white noise each published message adds (odom_noise_std).
        """
        return self._base.odom_pose.copy()

    @property
    def reality(self) -> Reality:
        """How real the simulated robot and laser are."""
        return self._base.reality

    @property
    def sim_time(self) -> float:
        """Simulated seconds so far (publish_clock mode)."""
        return self._sim_time

    @property
    def contacts(self) -> int:
        """Contact episodes with the true world so far (active + passive)."""
        return self._contact_counter.total

    @property
    def active_contacts(self) -> int:
        """Contact episodes that began with the robot moving."""
        return self._contact_counter.active

    @property
    def passive_contacts(self) -> int:
        """Contact episodes that began with the robot standing still (it was run into)."""
        return self._contact_counter.passive

    @property
    def robot_radius(self) -> float:
        """The radius of the disk checked for contacts (m); a polygon's covering radius."""
        return self._footprint.radius

    @property
    def footprint(self) -> Footprint:
        """The robot's shape checked for contacts (a circle or a convex polygon)."""
        return self._footprint

    def _now(self) -> float:
        if self.get_parameter('publish_clock').value:
            return self._sim_time
        return self.get_clock().now().nanoseconds * 1e-9

    def cmd_vel_callback(self, msg: Twist | TwistStamped) -> None:
        """Send the command to the base (it acts after command_latency, saturated).

        A non-finite command means stop. Its time is the simulation's (sim_time): the base
        takes it from the next tick on.
        """
        if isinstance(msg, TwistStamped):
            msg = msg.twist  # the same checks and timeout as a Twist
        raw = (msg.linear.x, msg.angular.z)
        if not all(math.isfinite(value) for value in raw):
            u = np.zeros(2)
            if self._problems.report('cmd_vel'):
                self.get_logger().error(
                    f'invalid cmd_vel: linear.x = {raw[0]}, angular.z = {raw[1]}; stopping')
        else:
            u = u_from_twist(msg)
            if self._problems.resolve('cmd_vel'):
                self.get_logger().info('cmd_vel is valid again')
        self._base.command(u, self._sim_time)
        self._last_cmd_time = self._now()
        self._timed_out = False

    def timer_callback(self) -> None:
        """Advance the simulation and publish clock and odom."""
        try:
            if self.get_parameter('publish_clock').value:
                steps = 1
            else:
                now = self._now()
                last = self._last_tick if self._last_tick is not None else now - self._dt
                steps = min(max(int(round((now - last) / self._dt)), 0), MAX_CATCH_UP_STEPS)
                self._last_tick = last + steps * self._dt if steps else last
                if now - self._last_tick > MAX_CATCH_UP_STEPS * self._dt:
                    self._last_tick = now  # far behind (a clock jump): do not catch up
            self._watchdog()
            for _ in range(steps):
                self._advance(self._sim_time + self._dt)
            publish_clock = self.get_parameter('publish_clock').value
            if publish_clock:
                stamp = seconds_to_stamp(self._sim_time)
            else:
                stamp = self.get_clock().now().to_msg()
            # odom before clock: a controller woken by the new time already has the state
            self._publish_sensors(stamp)
            if publish_clock:
                self._clock_pub.publish(ClockMsg(clock=stamp))
        except Exception as err:  # never let a callback kill the executor
            if not self.context.ok():
                return  # Ctrl-C shut the context down during the step: not a failure
            self.get_logger().error(f'simulation step failed: {err}',
                                    throttle_duration_sec=1.0)

    def _lockstep_progress(self) -> None:
        """Make the next lockstep move if the participants allow it (at most one tick).

        A tick: the robot moves one 1 / rate and its odometry, scan and localizer pose go
        out; once every participant has taken them, the clock moves to the new time; once
        every step due by then is done and its messages (cmd_vel, plans) are taken, the
        next tick. So no participant computes on stale inputs, and none sees time move
        while it computes.
        """
        gate = self._gate
        if gate is None or self._lockstep_busy:
            return
        self._lockstep_busy = True
        try:
            now_ns = self._ticks * self._tick_ns
            if self._phase is _Phase.START:
                if gate.passes(gate.awaited_start(), 'start the clock'):
                    self._publish_sensors(_stamp(now_ns))
                    self._phase = _Phase.SENSED
            elif self._phase is _Phase.CLOCKED:
                if gate.passes(gate.awaited_steps(now_ns), f'move past {now_ns * 1e-9:.3f} s'):
                    self._watchdog()
                    self._ticks += 1
                    now_ns = self._ticks * self._tick_ns
                    self._advance(now_ns * 1e-9)
                    self._publish_sensors(_stamp(now_ns))
                    self._phase = _Phase.SENSED
            # the new time wakes only the participants due by then: they must have the new
            # sensor messages first; a tick nobody is due at needs no wait (its messages
            # are taken before the next tick all the same)
            if self._phase is _Phase.SENSED and gate.passes(
                    gate.awaited_messages() if gate.due(now_ns) else [],
                    f'publish the clock at {now_ns * 1e-9:.3f} s'):
                self._clock_pub.publish(ClockMsg(clock=_stamp(now_ns)))
                self._phase = _Phase.CLOCKED
            if gate.stalls != self._stalls_published:
                self._stalls_published = gate.stalls
                self._stalls_pub.publish(UInt32(data=gate.stalls))
        except Exception as err:  # never let a callback kill the executor
            if self.context.ok():
                self.get_logger().error(f'lockstep step failed: {err}',
                                        throttle_duration_sec=1.0)
        finally:
            self._lockstep_busy = False

    @property
    def lockstep_stalls(self) -> int:
        """How often the lockstep clock gave up waiting (0 without lockstep)."""
        return self._gate.stalls if self._gate is not None else 0

    def _watchdog(self) -> None:
        """Stop the base when the latest cmd_vel is older than cmd_timeout (simulated s)."""
        timeout = float(self.get_parameter('cmd_timeout').value)
        if (timeout > 0 and not self._timed_out and self._last_cmd_time is not None
                and self._now() - self._last_cmd_time > timeout):
            # the driver's watchdog: the stop needs no trip over the network, it acts
            # now, not command_latency later (before any cmd_vel the base is at rest)
            self._base.stop(self._sim_time - self._base.reality.latency)
            self._timed_out = True

    def _advance(self, until: float) -> None:
        """Integrate one tick up to until; count scan and localizer periods and contacts."""
        self._base.advance(until)
        self._sim_time = until
        self._scan_phase += float(self.get_parameter('scan.rate').value) * self._dt
        self._localizer_phase += float(self.get_parameter('localizer.rate').value) * self._dt
        self._check_contact()

    def _publish_sensors(self, stamp: Any) -> None:
        """Publish odometry, and the scan and localizer pose if due, stamped alike.

        Odometry as the wheels report it (noise, drift, their measured twist).
        """
        pose, twist = self._base.odometry()
        self._odom_pub.publish(state_to_odometry(
            pose, twist, stamp=stamp,
            frame_id=str(self.get_parameter('odom_frame').value),
            child_frame_id=str(self.get_parameter('robot_base_frame').value)))
        self._publish_scan(stamp)
        self._publish_localizer(stamp)
        self._truth_pub.publish(state_to_odometry(
            self._base.pose, self._base.velocity, stamp=stamp,
            frame_id=str(self.get_parameter('localizer.global_frame').value),
            child_frame_id=str(self.get_parameter('robot_base_frame').value)))

    def _publish_localizer(self, stamp: Any) -> None:
        """Publish the true pose with noise if a localizer period ended during this tick."""
        if self._localizer_phase < 1.0 - _TICK_EPS:
            return
        self._localizer_phase = max(
            0.0, self._localizer_phase - math.floor(self._localizer_phase + _TICK_EPS))
        std = float(self.get_parameter('localizer.noise_std').value)
        x, y, theta = self._base.pose[:3] + self._localizer_rng.normal(0.0, std, 3)
        msg = PoseWithCovarianceStamped()
        msg.header.stamp = stamp
        msg.header.frame_id = str(self.get_parameter('localizer.global_frame').value)
        msg.pose.pose.position.x, msg.pose.pose.position.y = float(x), float(y)
        msg.pose.pose.orientation = yaw_to_quaternion(float(theta))
        covariance = np.zeros(36)
        covariance[[0, 7, 35]] = std * std
        msg.pose.covariance = covariance.tolist()
        self._localizer_pub.publish(msg)

    def _check_contact(self) -> None:
        """Count a contact episode when the robot's footprint starts touching the true world."""
        x, y, theta = (float(v) for v in self._base.pose[:3])
        touching = contact(self._world_clock.at(self._sim_time), x, y, self._footprint, theta)
        v, omega = (float(c) for c in self._base.velocity[:2])
        counter = self._contact_counter
        kind = counter.update(touching, v, omega)
        if kind is not None:
            self._contacts_pub.publish(UInt32(data=counter.total))
            if kind is ContactKind.ACTIVE:
                self._active_pub.publish(UInt32(data=counter.active))
            else:
                self._passive_pub.publish(UInt32(data=counter.passive))
            where = f'({x:.3f}, {y:.3f}, heading {theta:.3f} rad)'
            if counter.total == 1:
                robot = (f'radius {self._footprint.radius:g} m' if self._footprint.is_circle
                         else f'footprint {self._footprint.vertices.tolist()}')
                self.get_logger().error(
                    f'contact ({kind.value}): the robot ({robot}) touches an obstacle at '
                    f'{where}, {self._sim_time:.2f} s simulated')
            else:
                self.get_logger().warning(
                    f'contact episode {counter.total} ({kind.value}) at {where}, '
                    f'{self._sim_time:.2f} s simulated')

    def _publish_scan(self, stamp: Any) -> None:
        """Cast and publish a scan if a scan period ended during this tick.

        The reality's laser: a lost scan (scan.loss_fraction) is not published; the others
        carry its range noise and NaN / -inf beams (ScanChannel, as in the rollout).
        """
        if self._scan_phase < 1.0 - _TICK_EPS:
            return
        self._scan_phase = max(0.0, self._scan_phase - math.floor(self._scan_phase + _TICK_EPS))
        self._publish_moving_obstacles(stamp)
        if self._scan_channel.lost():
            return
        scan = self._laser.scan(self._base.pose, stamp=self._sim_time)
        scan = scan._replace(ranges=self._scan_channel.corrupt(scan.ranges, scan.range_max))
        self._scan_pub.publish(laser_scan_msg(
            scan, frame_id=str(self.get_parameter('robot_base_frame').value), stamp=stamp))

    def _publish_moving_obstacles(self, stamp: Any) -> None:
        """Publish the moving obstacles where they are now (disks as cylinders)."""
        if not self._world_clock.moving:
            return
        frame = str(self.get_parameter('localizer.global_frame').value)
        markers = []
        for index, shape in enumerate(self._world_clock.moving_at(self._sim_time)):
            if isinstance(shape, ConvexPolygon):
                markers.append(polygon_marker(shape.vertices, ns='moving', marker_id=index,
                                              frame_id=frame, stamp=stamp,
                                              rgba=_MOVING_RGBA, width=0.05))
            else:
                markers.append(cylinder_marker(shape.x, shape.y, shape.radius, ns='moving',
                                               marker_id=index, frame_id=frame, stamp=stamp,
                                               rgba=_MOVING_RGBA, height=_MOVING_HEIGHT))
        self._moving_pub.publish(MarkerArray(markers=markers))


def main(args: list[str] | None = None) -> int:
    """Run the node until Ctrl-C (exit code 2, with the reason, on invalid parameters).

    ``--help`` prints the parameters and their defaults and starts nothing.
    """
    return run_node(UnicycleSimulatorNode, 'unicycle_simulator', args, summary=SUMMARY,
                    parameters=PARAMETERS)


if __name__ == '__main__':
    sys.exit(main())
