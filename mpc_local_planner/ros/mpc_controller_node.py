# SPDX-License-Identifier: Apache-2.0
"""mpc_controller: the paper's MPC on odom and plan, cmd_vel at ``control_frequency``.

A lifecycle node, as Nav2's servers are. Unconfigured after construction (parameters
declared, nothing else); ``configure`` loads the world, builds the MPC and creates the
publishers and subscriptions (odom and plan are taken in from then on); ``activate`` starts
the control timer, and only then is anything published; ``deactivate`` publishes one zero
cmd_vel and stops the timer; ``cleanup`` frees the NLP and every publisher and
subscription; ``shutdown`` does the same (with a zero cmd_vel first when active). With
``autostart`` (the default) ``run_node`` configures and activates at start.

The control timer runs at ``control_frequency`` (Hz of ROS time, 20 by default, Nav2's
controller_server name), independent of the MPC's step h (``step``, 0.2 s): a real base
wants commands at 10-20 Hz, while the MPC predicts in steps of h. The MPC solves once per
step; the ticks between publish the input the last verified plan gives for now, after every
safety check (stale or invalid input stops the robot at the next tick, not the next solve),
and ``mpc/diagnostics`` says ``solved`` false for them. A ``control_frequency`` of 1 / step
or less solves at every tick. Changing ``control_frequency`` or ``step`` restarts the timer.

The base's limits, Nav2 velocity_smoother's names ([v, omega]; [0.0, 0.0] = none, the
default): with ``max_accel`` the NLP bounds each input change by max_accel h, starting from
the input commanded before (or the measured twist of the latest odometry after a stop), so
the plan is one the base can follow; with ``max_decel`` every stop of a moving robot (stale,
invalid or missing input, a failure) brakes along the last verified plan within those
limits (core/braking.py) instead of commanding zero at once, which a base with finite
deceleration could not follow anyway: it would coast into space no plan checked. With
``input_hold`` 'first_order' the velocity ramps between the plan's knots and cmd_vel is the
ramp ``actuation_delay`` ahead (the base's latency plus lag), so the base moves as predicted.

The robot's pose in the plan's frame (``global_frame``) comes from a localizer's pose topic
(``localization_topic``) composed with odometry, from tf2 when importable, or else is the
odometry itself (ros/robot_pose.py); while there is none the command is zero (reason
no_localization). ``local_plan``, ``mpc/obstacles`` and ``mpc/footprint`` are in ``global_frame``.

Subscribes ``odom`` and ``plan`` (reliable, transient_local), ``scan`` (sensor_msgs/LaserScan,
best effort) when ``obstacle_sources`` lists 'scan' and ``map`` (nav_msgs/OccupancyGrid,
transient_local) when it lists 'map'; publishes ``cmd_vel`` (Twist, or
TwistStamped with ``enable_stamped_cmd_vel``), ``local_plan`` (the prediction),
``mpc/diagnostics``, ``mpc/obstacles`` (what it avoids, as MarkerArray), ``mpc/footprint``
and, with ``track_moving``, ``mpc/tracks`` (the laser's tracks, as MarkerArray). All
decisions live in `MpcController`; this node converts messages, keeps the latest inputs and
publishes.

What the controller avoids (the world's obstacles, the map's, what the laser saw) and how
scans are placed: ros/mpc_controller_sensing.py. A plan through an obstacle is followed: the
MPC stops in front of it or goes around, and the diagnostics say ``path_blocked``.

The robot's shape, Nav2's precedence (as the simulator and the planner apply it): the
``footprint`` parameter's convex polygon (``"[[x, y], ...]"``, base_link), else the world
file's footprint if it is a polygon, else a circle of ``robot_radius`` (-1, its default:
the world's robot_radius). A circle grows the obstacles by its radius; a polygon is kept
apart from each obstacle exactly by the NLP. ``mpc/footprint`` shows that shape at the
robot's pose in ``global_frame``, and sensed obstacles are handed over within
``MpcConfig.reach`` (which counts a polygon's circumscribed radius) plus SENSING_MARGIN.

Refused input (odometry with NaN, inf or a zero quaternion; a plan that is empty, too short,
too long, not finite or in another frame) makes the command zero until valid input comes,
with one error per problem in the log (throttled) and the problem in the diagnostics. What
is done with scans and grids that cannot be interpreted: ros/mpc_controller_sensing.py.

A wrong lifecycle request (activate while unconfigured, an unknown transition id) is
refused with ``success: false`` and the node stays as it is (ManagedNode). When the process
ends for any reason it can still act on (Ctrl-C, SIGTERM, an exception), an active
controller publishes a zero cmd_vel first (``on_exit``); a process killed outright sends
nothing, and the base's own cmd_vel timeout must stop the robot.
Invalid parameters are refused with a reason; at start, the process exits with code 2 and the
reason on stderr (so does a configure that fails, with autostart).
"""

from __future__ import annotations

import sys
from typing import Any

from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid, Odometry, Path
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import LaserScan

from mpc_local_planner.core.config import ObstacleSource
from mpc_local_planner.core.control_output import Blockage, ControlOutput, Reason
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.input_freshness import InputFreshness
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import analytic_path
from mpc_local_planner.core.recoveries import Recoveries
from mpc_local_planner.ros.conversions import (
    frame_problem,
    measured_time,
    odometry_to_state,
    odometry_twist,
    path_pose_count,
    path_to_poses,
    stamp_to_seconds,
)
from mpc_local_planner.ros.lifecycle import ManagedNode
from mpc_local_planner.ros.mpc_controller_outputs import ControllerOutputs, FOOTPRINT_TOPIC
from mpc_local_planner.ros.mpc_controller_parameters import (
    build_recoveries,
    build_settings,
    check_obstacles,
    check_sensing,
    DEFAULTS,
    load_robot,
    PARAMETERS,
    RECOVERY_PARAMETERS,
)
from mpc_local_planner.ros.mpc_controller_sensing import ControllerSensing
from mpc_local_planner.ros.node_main import destroy_on_failure, EXIT_INVALID_PARAMETERS, run_node
from mpc_local_planner.ros.parameters import (
    declare_parameters,
    range_problems,
)
from mpc_local_planner.ros.qos import (
    LOCALIZER_QOS,
    MAP_QOS,
    ODOM_QOS,
    PLAN_QOS,
    SCAN_QOS,
)
from mpc_local_planner.ros.robot_pose import (
    choose_mode,
    LocalizationError,
    make_buffer,
    ODOM_HISTORY_S,
    PoseMode,
    RobotPose,
)
from mpc_local_planner.ros.throttle import ERROR_THROTTLE_S, ProblemThrottle

__all__ = ['ERROR_THROTTLE_S', 'EXIT_INVALID_PARAMETERS', 'FOOTPRINT_TOPIC', 'MpcControllerNode',
           'main']

# Wall seconds the exiting process waits for subscribers to acknowledge its zero cmd_vel.
EXIT_ACK_TIMEOUT_S = 1.0

SUMMARY = """\
The MPC of Lorenzen et al. (a lifecycle node): while active it solves once per `step` seconds
of ROS time for the latest odom (nav_msgs/Odometry) along the latest plan (nav_msgs/Path,
transient_local; or an analytic path), and control_frequency times a second it publishes
cmd_vel (geometry_msgs/Twist, or TwistStamped with enable_stamped_cmd_vel: the last verified
plan's input between solves), local_plan (the prediction), mpc/diagnostics,
mpc/obstacles (visualization_msgs/MarkerArray: the obstacles raw, grown, and those active in
the NLP), mpc/footprint (geometry_msgs/PolygonStamped: the footprint parameter's polygon,
else the world's, else the circle of robot_radius) and, with track_moving, mpc/tracks (the
laser's tracks: static, moving, and where a mover goes in 1 s). Obstacles come from the world file,
scan (sensor_msgs/LaserScan) and map (nav_msgs/OccupancyGrid), as obstacle_sources says.
Invalid input, and a stale scan when the laser is a source, stops the robot (zero cmd_vel)
until valid input comes (braking along the last verified plan within max_decel, if set).
With autostart false it waits unconfigured for a
lifecycle manager; deactivate publishes one zero cmd_vel."""


class MpcControllerNode(ManagedNode):
    """Run the MPC on the latest odom and plan; publish cmd_vel, local_plan, diagnostics.

    Configure wires the components, each owning its state: the MpcController (the
    decision), ControllerSensing (scans and map into obstacles, ros/mpc_controller_sensing.py)
    and ControllerOutputs (the publishers, ros/mpc_controller_outputs.py); this class keeps
    the latest odometry, plan verdicts and pose, and runs the control step.

    Attributes:
        controller: the MpcController (and its NLPs) while configured, else None.
        last_output: the latest control step's output (None before the first).
        control_steps: control steps since configure (each published one cmd_vel).
        goal_reached: whether the latest step said the goal is reached.

    """

    @destroy_on_failure
    def __init__(self, **kwargs: Any) -> None:
        super().__init__('mpc_controller', **kwargs)
        self._world_cache: dict[str, tuple[list[ConvexPolygon], Footprint]] = {}
        self.controller: MpcController | None = None
        self.recoveries: Recoveries | None = None  # around the MPC (core/recoveries.py)
        self._sensing: ControllerSensing | None = None
        self._outputs: ControllerOutputs | None = None
        self._odom_sub = None
        self._plan_sub = None
        self._scan_sub = None
        self._map_sub = None
        self._localizer_sub = None
        self._tf_listener = None
        self._timer = None
        self._sources: frozenset[ObstacleSource] = frozenset()
        self._world_obstacles: list[ConvexPolygon] = []
        # where the pose in the plan's frame comes from (ros/robot_pose.py); configure
        # chooses the mode, odometry until then
        self._pose_source = RobotPose(PoseMode.ODOMETRY, span=ODOM_HISTORY_S, global_frame='map')
        self._forget_inputs()
        self.add_on_set_parameters_callback(self.parameters_callback)
        declare_parameters(self, PARAMETERS)
        self.add_post_set_parameters_callback(self.post_parameters_callback)

    def _forget_inputs(self) -> None:
        """Drop the latest odometry, plan verdicts and step bookkeeping (as at construction)."""
        # the latest odometry (odom frame) and when it was measured; the pose in the plan's
        # frame made of it at the latest control step (RobotPose.current) and its time
        self._odom_state: np.ndarray | None = None
        self._odom_time: float | None = None
        # the latest odometry's measured twist (v, omega), None when unknown or not finite:
        # the MPC's rate bounds (max_accel) start from it after a stop, as the base may
        # still be moving
        self._odom_twist: np.ndarray | None = None
        self._state: np.ndarray | None = None
        self._state_time: float | None = None
        # what is wrong with the latest odometry / plan / pose in the plan's frame (None when
        # valid): the command is zero while one is set, and the diagnostics carry it
        self._odom_problem: str | None = None
        self._plan_problem: str | None = None
        self._pose_problem: str | None = None
        self._problems = ProblemThrottle(ERROR_THROTTLE_S)
        self._last_step_time: float | None = None
        # the last ODOM_HISTORY_S seconds of odometry, to place each scan where it was taken
        # (and the localizer's correction)
        self._pose_source.clear()
        self.blockage = Blockage()
        self.last_output: ControlOutput | None = None
        self.control_steps = 0
        self.goal_reached = False

    # ------------------------------------------------------------------ lifecycle
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the world, build the MPC, create the publishers and subscriptions.

        Returns:
            FAILURE (back to unconfigured, with the reason in the log) if the world file
            cannot be read or the parameters do not make a controller.

        """
        try:
            values = self._values()
            world_file = str(values['world_file'])
            self._world_cache.pop(world_file, None)  # read it again: it may have changed
            check_sensing(values)
            sources = frozenset(ObstacleSource(s) for s in values['obstacle_sources'])
            world_obstacles, world_footprint = self._load_world(world_file)
            obstacles = world_obstacles if ObstacleSource.WORLD in sources else []
            config, model, settings = build_settings(
                values, world_radius=world_footprint.radius, world_footprint=world_footprint)
            check_obstacles(obstacles, config)
            controller = MpcController(model, config, obstacles=obstacles, settings=settings)
            recoveries = build_recoveries(values, config, model)
            if values['analytic_path']:
                controller.set_path(analytic_path(values['analytic_path']))
        except Exception as err:  # a bad world file mostly; refuse with a reason
            self.get_logger().error(f'configure failed: {err}')
            return TransitionCallbackReturn.FAILURE
        self.controller = controller
        self.recoveries = recoveries
        self._sources = sources
        self._world_obstacles = list(obstacles)
        self._pose_source = self._make_robot_pose(values)
        self._forget_inputs()
        self._sensing = ControllerSensing(
            controller, sources=sources, memory_ttl=float(values['obstacle_memory']),
            track_moving=bool(values['track_moving']),
            logger=self.get_logger(), now=self._now, parameter=self._parameter,
            pose_at=self.pose_at)
        if values['analytic_path']:
            self._prepare()
        self._outputs = ControllerOutputs(self, controller,
                                          stamped=bool(values['enable_stamped_cmd_vel']),
                                          parameter=self._parameter)
        self._odom_sub = self.create_subscription(Odometry, 'odom', self.odom_callback,
                                                  ODOM_QOS)
        # raw: the size of a plan is checked before rclpy spends ~15 us per pose on it
        self._plan_sub = self.create_subscription(Path, 'plan', self.plan_callback, PLAN_QOS,
                                                  raw=True)
        if ObstacleSource.SCAN in sources:
            # raw: the beam count is checked before rclpy decodes the ranges (ScanIntake)
            self._scan_sub = self.create_subscription(LaserScan, 'scan', self.scan_callback,
                                                      SCAN_QOS, raw=True)
        if ObstacleSource.MAP in sources:
            self._map_sub = self.create_subscription(OccupancyGrid, 'map', self.map_callback,
                                                     MAP_QOS)
        if self._pose_source.mode is PoseMode.LOCALIZER:
            self._localizer_sub = self.create_subscription(
                PoseWithCovarianceStamped, str(values['localization_topic']),
                self.localizer_callback, LOCALIZER_QOS)
        shape = config.robot_footprint
        robot = (f'a circle of radius {shape.radius:g} m' if shape.is_circle
                 else f'the footprint {shape.vertices.tolist()}')
        self.get_logger().info(f'configured: {len(obstacles)} obstacles from the world, '
                               f'sources {sorted(sources)}, horizon {config.horizon}, step '
                               f'{config.step:g} s, cmd_vel at {settings.control_frequency:g} '
                               f'Hz, the robot {robot}; the pose in '
                               f'{values["global_frame"]!r} from {self._pose_source.describe()}')
        return super().on_configure(state)

    def _make_robot_pose(self, values: dict[str, Any]) -> RobotPose:
        """Return the pose source localization_topic and tf2's presence choose (robot_pose)."""
        mode = choose_mode(str(values['localization_topic']))
        buffer = None
        if mode is PoseMode.TF:
            buffer, self._tf_listener = make_buffer(self)
        return RobotPose(mode, span=ODOM_HISTORY_S, global_frame=str(values['global_frame']),
                         topic=str(values['localization_topic']), buffer=buffer,
                         robot_base_frame=str(values['robot_base_frame']),
                         tolerance=float(values['transform_tolerance']),
                         max_travel=float(values['localization_max_travel']),
                         max_rotation=float(values['localization_max_rotation']))

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable the publishers and start the control timer."""
        result = super().on_activate(state)
        if result == TransitionCallbackReturn.SUCCESS:
            self._make_timer()
            self.get_logger().info('active: controlling')
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Publish one zero cmd_vel, stop the control timer, disable the publishers."""
        self._stop_robot()
        self._destroy_timer()
        self.get_logger().info('inactive: cmd_vel zero once, then silent')
        return super().on_deactivate(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop the robot if active, then release everything (ManagedNode)."""
        if self._timer is not None:
            self._stop_robot()
        return super().on_shutdown(state)

    def on_exit(self) -> None:
        """Publish a zero cmd_vel if active: the process ends, the robot must not drive on.

        Most bases hold the last command for a while (until their cmd_vel timeout).
        """
        if self._timer is None:
            return
        self._stop_robot()
        # the process ends next: give reliable subscribers time to take the zero before the
        # writer goes (an acknowledgement can wait for DDS's next heartbeat)
        acked = self._outputs.wait_for_cmd_acked(EXIT_ACK_TIMEOUT_S)
        self.get_logger().info('exiting: cmd_vel zero' + (
            '' if acked else f' (not acknowledged by every subscriber in '
                             f'{EXIT_ACK_TIMEOUT_S:g} s)'))

    def destroy_node(self) -> None:
        """Drop the controller (and its NLP) with the node."""
        self.controller = None
        self._sensing = self._outputs = None
        super().destroy_node()

    def _stop_robot(self) -> None:
        """Publish one zero cmd_vel (while the publisher is still enabled)."""
        if self._outputs is None:
            return
        try:
            self._outputs.publish_stop(self._now())
        except Exception as err:  # the command must not fail a transition
            self.get_logger().warning(f'could not publish a zero cmd_vel: {err}')

    def _destroy_timer(self) -> None:
        self.destroy_entities(self._timer)
        self._timer = None

    def release(self) -> None:
        """Destroy the timer, subscriptions and publishers, and drop the controller (its NLPs)."""
        publishers = self._outputs.publishers if self._outputs is not None else ()
        self.destroy_entities(self._timer, self._odom_sub, self._plan_sub, self._scan_sub,
                              self._map_sub, self._localizer_sub, *publishers)
        self._timer = None
        self._odom_sub = self._plan_sub = self._scan_sub = self._map_sub = None
        self._localizer_sub = None
        if self._tf_listener is not None:
            self._tf_listener.unregister()
            self._tf_listener = None
        self._outputs = self._sensing = None
        self.controller = None  # the MPC and its NLPs go with it
        self.recoveries = None
        self._forget_inputs()

    # ------------------------------------------------------------------ parameters
    def _values(self, overrides: list[Parameter] = ()) -> dict[str, Any]:
        values = dict(DEFAULTS)
        for name in DEFAULTS:
            if self.has_parameter(name):
                values[name] = self.get_parameter(name).value
        for parameter in overrides:
            values[parameter.name] = parameter.value
        return values

    def _load_world(self, world_file: str) -> tuple[list[ConvexPolygon], Footprint]:
        """Return a world file's obstacles and footprint (cached; configure reads it anew)."""
        if world_file not in self._world_cache:
            self._world_cache[world_file] = load_robot(world_file)
        return self._world_cache[world_file]

    def parameters_callback(self, parameters: list[Parameter]) -> SetParametersResult:
        """Accept the new values only if the whole configuration stays valid."""
        try:
            values = self._values(parameters)
            check_sensing(values)
            obstacles, footprint = self._load_world(str(values['world_file']))
            config, _, _ = build_settings(values, world_radius=footprint.radius,
                                          world_footprint=footprint)
            if ObstacleSource.WORLD in values['obstacle_sources']:
                check_obstacles(obstacles, config)
            if values['analytic_path']:
                analytic_path(str(values['analytic_path']))
        except Exception as err:  # whatever the cause, refuse with a reason
            reason = str(err) or type(err).__name__
            return SetParametersResult(successful=False, reason=reason)
        problems = range_problems(PARAMETERS, parameters)  # the arrays' ranges, among others
        if problems:
            return SetParametersResult(successful=False, reason='; '.join(problems))
        return SetParametersResult(successful=True)

    def post_parameters_callback(self, parameters: list[Parameter]) -> None:
        """Apply accepted changes; the MPC picks them up at its next solve.

        Unconfigured, there is nothing to apply: configure reads every value.
        """
        names = {p.name for p in parameters}
        if self.controller is None:
            return
        try:
            values = self._values()
            obstacles, footprint = self._load_world(values['world_file'])
            config, model, settings = build_settings(values, world_radius=footprint.radius,
                                                     world_footprint=footprint)
            # one thread runs every callback: never between two halves of a solve; the
            # obstacles in force are handed over at the next control step
            if 'world_file' in names:
                self._world_obstacles = (list(obstacles) if ObstacleSource.WORLD in self._sources
                                         else [])
            self.controller.update_config(config)
            if model != self.controller.model:
                self.controller.set_model(model)
            self.controller.settings = settings
            if names & (RECOVERY_PARAMETERS | {'allow_reversing', 'v_max', 'omega_max',
                                               'footprint', 'robot_radius'}):
                self.recoveries = build_recoveries(values, config, model)
            if 'analytic_path' in names and values['analytic_path']:
                self.controller.set_path(analytic_path(values['analytic_path']))
                self._plan_problem = None  # the plan topic is ignored from now on
            if names & {'step', 'control_frequency'} and self._timer is not None:
                self._make_timer()
            if 'obstacle_memory' in names and self._sensing is not None:
                self._sensing.set_memory_ttl(float(values['obstacle_memory']))
        except Exception as err:  # validated above: a bug, but keep running
            self.get_logger().error(f'could not apply {sorted(names)}: {err}')
            return
        self.get_logger().info(f'parameters changed: {sorted(names)}')

    def _control_period(self) -> float:
        """Return the control timer's period (s of ROS time): 1 / control_frequency."""
        return 1.0 / float(self.get_parameter('control_frequency').value)

    @property
    def control_period_ns(self) -> int | None:
        """The running control timer's period in nanoseconds (None while there is none)."""
        return None if self._timer is None else int(self._timer.timer_period_ns)

    @property
    def odom_state(self) -> np.ndarray | None:
        """A copy of the latest valid odometry's state (odom frame); None without one."""
        return None if self._odom_state is None else self._odom_state.copy()

    @property
    def scan_stamp(self) -> float | None:
        """The stamp of the latest scan placed and used (s of ROS time; None: none yet)."""
        return self._sensing.scan_stamp if self._sensing is not None else None

    @property
    def scan_time(self) -> float | None:
        """What scan_timeout is measured from: the latest usable scan's time (None: none)."""
        return self._sensing.scan_time if self._sensing is not None else None

    @property
    def pending_scans(self) -> int:
        """How many valid scans wait for odometry that covers their stamps."""
        return self._sensing.pending_scans if self._sensing is not None else 0

    def _make_timer(self) -> None:
        """(Re)start the control timer at control_frequency (the MPC's step is apart)."""
        self._destroy_timer()
        self._timer = self.create_timer(self._control_period(), self.timer_callback)

    # ------------------------------------------------------------------ callbacks
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _parameter(self, name: str) -> Any:
        """Return a parameter's current value (what the components read when they use it)."""
        return self.get_parameter(name).value

    def _place_pending(self) -> None:
        """Place the scans that wait for odometry, if scans are taken (ControllerSensing)."""
        if self._sensing is not None:
            self._sensing.place_pending()

    def scan_callback(self, msg: LaserScan | bytes) -> None:
        """Take a scan (ControllerSensing.take_scan); nothing before configure.

        Args:
            msg: the scan, or its CDR bytes as the raw subscription delivers them.

        """
        if self._sensing is not None:
            self._sensing.take_scan(msg)

    def map_callback(self, msg: OccupancyGrid) -> None:
        """Take a map (ControllerSensing.take_map); nothing before configure."""
        if self._sensing is not None:
            self._sensing.take_map(msg)

    def odom_callback(self, msg: Odometry) -> None:
        """Keep the latest state and when it was measured; a bad one stops the robot.

        The measurement time is the stamp, but never later than the arrival: a stamp from
        the future must not keep the state fresh after the odometry stops. The pose and its
        twist go to the history (to place scans), and the scans waiting for odometry that
        covers their stamps are placed if this one does.
        """
        receipt = self._now()
        try:
            state = self.controller.check_state(odometry_to_state(msg))
        except Exception as err:  # ValueError, or a message gone wrong
            self._odom_state, self._odom_time = None, None
            self._odom_twist = None
            self._state, self._state_time = None, None
            self._odom_problem = str(err) or type(err).__name__
            if self._problems.report('odom'):
                self.get_logger().error(
                    f'{Reason.INVALID_ODOM.text}: {self._odom_problem}; cmd_vel is zero until '
                    'valid odometry comes')
            return
        stamp = stamp_to_seconds(msg.header.stamp)
        twist = odometry_twist(msg)
        self._odom_state = state
        self._odom_time = measured_time(stamp, receipt)
        self._odom_twist = twist if np.all(np.isfinite(twist)) else None
        self._odom_problem = None
        self._pose_source.add_odometry(stamp if stamp > 0 else receipt, state,
                                       msg.header.frame_id, twist)
        if self._problems.resolve('odom'):
            self.get_logger().info('odometry is valid again')
        self._place_pending()

    def pose_at(self, time: float) -> np.ndarray | None:
        """Return the pose in the plan's frame at time (RobotPose.at; None: not yet).

        None before any odometry and for a time more than MAX_EXTRAPOLATION_S past the
        latest odometry (with tf2, past the latest transform): the scan waits.

        Raises:
            LocalizationError: if there is odometry but no pose in the plan's frame.

        """
        return self._pose_source.at(time)

    def localizer_callback(self, msg: PoseWithCovarianceStamped) -> None:
        """Take the localizer's pose: its correction map <- odom applies from now on.

        One older than the odometry kept drops the correction (the robot stops until a
        usable one comes; the control step says why). One in another frame, or not a pose,
        is refused with one throttled error, and the correction in force stays.
        """
        try:
            self._pose_source.add_localizer(msg, self._now())
        except LocalizationError:
            return  # the next control step stops and says why
        except Exception as err:  # ValueError mostly; never leave a callback
            if self._problems.report('localizer'):
                self.get_logger().error(f'localizer pose refused: {err}')
            return
        self._problems.resolve('localizer')

    def _locate(self) -> None:
        """Set this step's pose in the plan's frame (RobotPose.current); say once if none."""
        try:
            self._state, self._state_time = self._pose_source.current(self._odom_state,
                                                                     self._odom_time)
        except LocalizationError as err:
            self._state, self._state_time = None, None
            self._pose_problem = str(err)
            if self._problems.report('localization'):
                self.get_logger().error(f'{Reason.NO_LOCALIZATION.text}: {err}; cmd_vel is '
                                        'zero until there is one')
            return
        self._pose_problem = None
        if self._problems.resolve('localization'):
            self.get_logger().info(f"a pose in the plan's frame again, from "
                                   f'{self._pose_source.describe()}')

    def plan_callback(self, msg: Path | bytes) -> None:
        """Follow a new global plan (s restarts at the robot's projection onto it).

        A refused plan also drops the plan in force: whoever sent it wanted the robot to do
        something else, so the robot stops until a valid plan comes.

        Args:
            msg: the plan, or its CDR bytes as the raw subscription delivers them.

        """
        if self.get_parameter('analytic_path').value:
            self.get_logger().info('following the analytic path: plan ignored', once=True)
            return
        try:
            plan = self._read_plan(msg)
            poses = path_to_poses(plan)
            path = self.controller.set_plan(poses)
            if self.recoveries is not None:
                self.recoveries.plan_changed(poses)
            self._prepare()
        except Exception as err:  # ValueError mostly; never leave a callback
            problem = str(err) or type(err).__name__
            self.controller.clear_path()
            self._plan_problem = problem
            if self._problems.report('plan'):
                self.get_logger().error(f'{Reason.INVALID_PLAN.text}: {problem}; cmd_vel is '
                                        'zero until a valid plan comes')
            return
        self._plan_problem = None
        self._problems.resolve('plan')
        self.goal_reached = False
        self.get_logger().info(f'new plan: {len(poses)} poses, {path.length():.2f} m')

    def _read_plan(self, msg: Path | bytes) -> Path:
        """Return the plan message after the checks that need no conversion of its poses.

        Raises:
            ValueError: if its serialised form counts more than max_plan_poses (refused before
                rclpy decodes it; MpcController.set_plan refuses a decoded one), or it is
                in another frame.

        """
        if isinstance(msg, (bytes, bytearray)):
            count = path_pose_count(bytes(msg))
            limit = self.controller.settings.max_plan_poses
            if count is not None and count > limit:
                problem = f'{count} poses, more than max_plan_poses ({limit})'
                raise ValueError(problem)
            msg = deserialize_message(bytes(msg), Path)
        frame = str(self.get_parameter('global_frame').value)
        problem = frame_problem(msg.header.frame_id, frame, 'plans')
        if problem is not None:
            raise ValueError(problem)
        return msg

    def _prepare(self) -> None:
        try:
            self.controller.prepare()
        except Exception as err:  # the first solve builds instead
            self.get_logger().warning(f'could not prepare the NLPs: {err}')

    def timer_callback(self) -> None:
        """Control (solve or hold), then publish cmd_vel, local_plan and diagnostics.

        A stop (refused input, no pose) goes through the controller with now, so that a
        moving robot brakes within max_decel rather than getting zero at once.
        """
        now = self._now()
        if (self._last_step_time is not None
                and 0 <= now - self._last_step_time < 0.5 * self._control_period()):
            return  # a timer fired twice for one instant (ROS-time timers can): one tick
        self._last_step_time = now
        self.control_steps += 1
        try:
            self._place_pending()  # odometry may have come since a scan began to wait
            self._locate()
            if self._odom_problem is not None:
                output = self.controller.stop(Reason.INVALID_ODOM, self._odom_problem, now=now)
            elif self._plan_problem is not None:
                output = self.controller.stop(Reason.INVALID_PLAN, self._plan_problem, now=now)
            elif self._pose_problem is not None:
                output = self.controller.stop(Reason.NO_LOCALIZATION, self._pose_problem,
                                              now=now)
            else:
                held = self._world_obstacles + self._sensing.near(self._state, now)
                self.controller.set_obstacles(held)
                refused = None if self._state is None else InputFreshness.of(
                    self.controller.settings).check(
                    now, pose_time=self._state_time,
                    scan_required=ObstacleSource.SCAN in self._sources,
                    scan_time=self._sensing.scan_time,
                    map_missing=ObstacleSource.MAP in self._sources and self._sensing.grid is None)
                if refused is None:
                    output = self._compute(held, now)
                else:
                    output = self.controller.refuse_inputs(refused, now)
        except Exception as err:  # compute never raises; belt and braces
            output = ControlOutput(np.zeros(2), None, Reason.ERROR, str(err))
        try:
            self.blockage = self.controller.path_blockage(self._state)
        except Exception:  # a report, not a decision: never let it stop the step
            self.blockage = Blockage()
        self.last_output = output
        self.goal_reached = output.reason is Reason.GOAL_REACHED
        self._outputs.publish(output, now, state=self._state, state_time=self._state_time,
                              blockage=self.blockage,
                              tracks=self._sensing.tracks if self._sensing is not None else None)

    def _compute(self, held: list[ConvexPolygon], now: float) -> ControlOutput:
        """Return the MPC's answer, or a recovery's where the robot makes no progress."""
        assert self.controller is not None

        def compute() -> ControlOutput:
            return self.controller.compute(self._state, self._odom_twist, now)

        if self.recoveries is None:
            return compute()
        self.recoveries.set_obstacles(held)
        started, logged = self.recoveries.started, len(self.recoveries.log)
        exhausted = self.recoveries.exhausted
        output = self.recoveries.step(self._state, self._odom_twist, now, compute)
        if self.recoveries.started > started:
            self.get_logger().warning(
                f'no progress for {self.recoveries.settings.stuck_timeout:g} s: recovery '
                f'{self.recoveries.tries} of {self.recoveries.settings.max_tries}')
        if len(self.recoveries.log) > logged:
            for record in self.recoveries.log[logged:]:
                self.get_logger().info(
                    f'recovery {record.kind}: {record.end - record.start:.1f} s'
                    + (f', {record.distance:.2f} m' if record.distance else '')
                    + f', ended: {record.ended}')
        if self.recoveries.exhausted and not exhausted:
            self.get_logger().error(
                f'no progress, and the {self.recoveries.settings.max_tries} recoveries for '
                'this goal are spent: the MPC answers alone until a new goal')
        return output


def main(args: list[str] | None = None) -> int:
    """Run the node until Ctrl-C (exit code 2, with the reason, on invalid parameters).

    ``--help`` prints the parameters with their defaults and starts nothing.
    """
    return run_node(MpcControllerNode, 'mpc_controller', args, summary=SUMMARY,
                    parameters=PARAMETERS)


if __name__ == '__main__':
    sys.exit(main())
