# SPDX-License-Identifier: Apache-2.0
"""global_planner: OMPL RRT* from the current odometry to the goal; publishes plan.

A lifecycle (managed) node, as Nav2's navigation servers are: ``configure`` loads the world,
builds the planner and creates the publishers and subscriptions; ``activate`` starts planning
and publishing; ``deactivate`` stops both; ``cleanup`` frees the planner and destroys the
publishers and subscriptions; ``shutdown`` does the same from any state. With ``autostart``
(the default) the executable configures and activates itself, so ``ros2 run`` alone gives a
working planner; with ``autostart:=false`` it waits for a lifecycle manager (or
``ros2 lifecycle set /global_planner configure``, then ``activate``).

The goal comes from the ``goal`` parameter ([x, y, theta]) or a PoseStamped on
``goal_pose`` (RViz's "2D Goal Pose"); by default there is none, and nothing is planned until
one comes. Each new goal is planned once, from the robot's pose in ``global_frame`` (the
latest ``odom`` pose, or composed with a localizer's or taken from tf2: ros/robot_pose.py;
without one the goal waits), around the world's obstacles inflated by robot_radius +
clearance, and published on ``plan`` (reliable, transient_local: a late controller still gets
it). Without ``world_file`` (the default) and without ``use_map`` the
plane is empty and unbounded (but for MAX_COORDINATE, the controller's limit too): every plan
is the straight line to the goal. With ``analytic_path`` set the node publishes that path,
sampled, instead of planning. Nothing is published before activation: a ``goal`` parameter
is planned once the node is active (and odometry has come); a ``goal_pose`` that arrives
while the node is inactive is refused.

With ``use_map`` it plans on an occupancy grid instead of the world's obstacles: the latest
``map`` (nav_msgs/OccupancyGrid, transient_local), unknown cells free, inflated by
robot_radius + clearance with a distance transform; the plane it samples is the map's extent
(``world_file`` may then be ''). Until a map comes a goal waits (planner/diagnostics says
'waiting for map'). A malformed map is refused with one throttled error and the grid in force
stays. With ``use_scan`` too, each ``scan`` (sensor_msgs/LaserScan from the laser at
``laser_pose`` in the robot frame) marks the cells of its returns and clears the cells its
beams pass through, beam by beam as REP 117 says (PlanningGrid.add_scan; a return inside
the robot's footprint, the one the planner plans for, is the robot itself and marks nothing),
placed with the robot's pose in ``global_frame`` at its stamp (ros/robot_pose.py: odometry
within SCAN_POSE_TOLERANCE of it, corrected by the localizer, or tf2); a scan newer than
the latest odometry by at most MAX_EXTRAPOLATION_S is placed with the latest pose moved
along its twist's arc, a newer one waits (the latest PENDING_SCANS) until odometry covering
its stamp has come, never placed with the older pose, and is discarded if none has once it
is SCAN_POSE_TOLERANCE old; a scan that cannot
be interpreted (a beam count its angles do not imply, within one increment, among others) or
one stamped more than MAX_SCAN_FUTURE_S ahead of this node's clock is dropped with one
throttled error.

Re-planning (``replan_check_rate``, 2 Hz by default): the rest of the plan in force, from the
robot's projection onto it, is checked against the grid with the rule plans are made with
(RrtStarPlanner.rest_problem); when an obstacle the map did not have, marked by the laser,
violates its clearance, the goal is planned again from the current odometry, and with
``replan_period`` > 0 also periodically. A new plan replaces the old on ``plan``; the
controller follows it from the robot's projection. ``planner/diagnostics`` says what
triggered each plan and counts the re-plans; a failed re-plan is a warning and the plan in
force stays. While the odometry is stale (older than ``odom_timeout``, the controller's rule)
nothing is checked or re-planned: one warning says so, one line when odometry comes again.
The policy (when to check, consecutive failures moving the seed on) is core/replanning.py's
`Replanner`, which the evaluation's Navigator runs too.

A goal it cannot plan to (inside an inflated obstacle, walled off, out of bounds, not
finite, in another frame), or a start in collision, is logged as an error and nothing is
published on ``plan``: the plan in force stays, and the next valid goal is planned as usual.
The outcome of every goal, planned or not and why, is published on ``planner/diagnostics``
(DiagnosticArray, reliable and transient_local; keys in core/diagnostics.py), so that a
supervisor such as closed_loop learns that no plan will come.
"""

from __future__ import annotations

from dataclasses import replace
import math
import sys
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid, Odometry, Path
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.exceptions import ParameterUninitializedException
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from rclpy.lifecycle.publisher import LifecyclePublisher
from rclpy.parameter import Parameter
from rclpy.subscription import Subscription
from sensor_msgs.msg import LaserScan

from mpc_local_planner.core.controller import MAX_COORDINATE
from mpc_local_planner.core.controller_settings import is_stale
from mpc_local_planner.core.diagnostics import (
    PLANNER_DIAGNOSTICS_TOPIC,
    PlannerDiagnostics,
    PlanTrigger,
)
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.footprint import Footprint, radius_in_force, resolve
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import analytic_path, waypoints_to_poses
from mpc_local_planner.core.planner import path_length, RrtStarPlanner
from mpc_local_planner.core.planner_config import PlannerConfig
from mpc_local_planner.core.replanning import (
    ReplanDecision,
    Replanner,
    ReplanOutcome,
    ReplanSettings,
)
from mpc_local_planner.perception.grids import PlanningGrid
from mpc_local_planner.perception.tracking import Track
from mpc_local_planner.ros.conversions import (
    diagnostic_array,
    frame_problem,
    grid_from_message,
    measured_time,
    odometry_to_state,
    odometry_twist,
    pose_to_array,
    poses_to_path,
    stamp_to_seconds,
)
from mpc_local_planner.ros.global_planner_parameters import (
    parameter_problems,
    PARAMETERS,
    PLANNER_FIELDS,
)
from mpc_local_planner.ros.global_planner_scans import PlannerScans
from mpc_local_planner.ros.lifecycle import ManagedNode
from mpc_local_planner.ros.node_main import destroy_on_failure, run_node
from mpc_local_planner.ros.parameters import (
    declare_parameters,
    range_problems,
)
from mpc_local_planner.ros.qos import (
    GOAL_QOS,
    LOCALIZER_QOS,
    MAP_QOS,
    ODOM_QOS,
    PLAN_QOS,
    PLANNER_DIAGNOSTICS_QOS,
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
from mpc_local_planner.ros.throttle import ProblemThrottle
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import load_world, World

__all__ = ['GlobalPlannerNode', 'SUMMARY', 'main']


# Poses of a published analytic path (enough for RViz and for a polyline controller).
ANALYTIC_SAMPLES = 101
# A re-plan from a robot standing within the planner's clearance of an obstacle starts from
# the nearest clear point no farther than this (m) that it can drive straight to.
ESCAPE_DISTANCE = 1.0
# The plane sampled without a world and without use_map: no obstacles, and no bounds but the
# positions the controller accepts at all.
FREE_PLANE_BOUNDS = (-MAX_COORDINATE, MAX_COORDINATE, -MAX_COORDINATE, MAX_COORDINATE)


SUMMARY = ('OMPL RRT* from the current odometry (odom) to the goal (the goal parameter or '
           "goal_pose), around the world's obstacles or, with use_map, on the map's grid "
           '(plus scan with use_scan); publishes plan (reliable, transient_local) and '
           'planner/diagnostics. A lifecycle node: configure loads the world, activate starts '
           'planning.')


class GlobalPlannerNode(ManagedNode):
    """Plan with RRT* from odom to the goal and publish the plan (a lifecycle node).

    It wires its components: the planner, the re-planning policy (Replanner) and the scan
    intake (PlannerScans), each owning its state.

    Args:
        planner: plan with this instead of the RRT* configure (or a map) builds from the
            parameters (a test's scripted planner); None: the RRT*.
        **kwargs: rclpy Node's (context, parameter_overrides, ...).

    """

    @destroy_on_failure
    def __init__(self, *, planner: RrtStarPlanner | None = None, **kwargs: Any) -> None:
        super().__init__('global_planner', **kwargs)
        self._given_planner = planner
        self.add_on_set_parameters_callback(self.parameters_callback)
        declare_parameters(self, PARAMETERS)
        self.add_post_set_parameters_callback(self.post_parameters_callback)
        # created by on_configure, freed by on_cleanup
        self._configured = False
        self._use_map = False
        self._use_scan = False
        self._world: World | None = None
        self._grid: PlanningGrid | None = None
        self._planner: RrtStarPlanner | None = None
        self._plan_pub: LifecyclePublisher | None = None
        self._diag_pub: LifecyclePublisher | None = None
        self._odom_sub: Subscription | None = None
        self._goal_sub: Subscription | None = None
        self._map_sub: Subscription | None = None
        self._scan_sub: Subscription | None = None
        self._localizer_sub: Subscription | None = None
        self._tf_listener: Any = None
        self._active = False
        self._state: np.ndarray | None = None  # the latest odometry (odom frame)
        self._odom_time: float | None = None  # when it was measured (node clock, s)
        self._odom_stale = False  # said once when it goes stale, once when it comes back
        # the pose in the plan's frame (ros/robot_pose.py): configure chooses the mode
        self._pose_source = RobotPose(PoseMode.ODOMETRY, span=ODOM_HISTORY_S, global_frame='map')
        self._pending_goal: np.ndarray | None = None
        # the scans: waiting for a pose, marking the grid, remembered (with use_scan)
        self._scans = PlannerScans(logger=self.get_logger(), now=self._now,
                                   parameter=lambda name: self.get_parameter(name).value,
                                   body=self._scan_body)
        self._waiting_reported = False
        self._problems = ProblemThrottle()
        self.last_plan: np.ndarray | None = None
        self.plan_count = 0
        # the re-planning policy: the goal and plan in force, failures, counts (node clock, s)
        self.replanner = Replanner(self._replan_settings())
        self._check_timer: Any = None
        self.map_count = 0
        self.last_outcome: PlannerDiagnostics | None = None

    # ------------------------------------------------------------------ lifecycle
    @property
    def planner(self) -> RrtStarPlanner | None:
        """The planner while the node is configured (with use_map: once a map came), or None."""
        return self._planner

    @property
    def grid(self) -> PlanningGrid | None:
        """With use_map, the grid plans are checked on (map plus scans), once a map came."""
        return self._grid

    @property
    def held_obstacles(self) -> tuple[ConvexPolygon, ...]:
        """The convex pieces the scans made (obstacle_memory): re-plans keep clear of them."""
        return self._scans.held_obstacles

    @property
    def tracks(self) -> list[Track] | None:
        """The tracks of the scans' clusters (track_moving; None: the planner does not track)."""
        return self._scans.tracks

    @property
    def pending_scan_count(self) -> int:
        """Valid scans waiting for odometry that covers their stamps."""
        return self._scans.pending

    @property
    def scan_count(self) -> int:
        """Scans added to the grid."""
        return self._scans.count

    @property
    def odom_state(self) -> np.ndarray | None:
        """A copy of the latest valid odometry's state (odom frame); None without one."""
        return None if self._state is None else self._state.copy()

    @property
    def is_active(self) -> bool:
        """Whether the node is active: it plans and publishes."""
        return self._active

    @property
    def replan_count(self) -> int:
        """Re-plans published (blocked or periodic), the re-planner's count."""
        return self.replanner.replans

    def _replan_settings(self) -> ReplanSettings:
        """Return the re-planner's settings: replan_check_rate and replan_period."""
        return ReplanSettings.from_rate(
            float(self.get_parameter('replan_check_rate').value),
            replan_period=float(self.get_parameter('replan_period').value),
            escape_distance=ESCAPE_DISTANCE,
            progress_timeout=float(self.get_parameter('progress_timeout').value),
            progress_radius=float(self.get_parameter('progress_radius').value),
            progress_angle=float(self.get_parameter('progress_angle').value))

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the world, build the planner, create the publishers and subscriptions.

        With use_map the planner is built when the first valid map comes.
        """
        self._use_map = bool(self.get_parameter('use_map').value)
        self._use_scan = bool(self.get_parameter('use_scan').value)
        try:
            if self._use_scan and not self._use_map:
                problem = 'use_scan needs use_map (scans mark the cells of the map)'
                raise ValueError(problem)
            self._scans.reset(float(self.get_parameter('obstacle_memory').value)
                              if self._use_scan else None,
                              track_moving=bool(self.get_parameter('track_moving').value))
            if self.get_parameter('world_file').value:
                self._world = self._read_world()
            self._planner = self._make_planner()
        except Exception as err:  # a world that vanished since it was validated, a bad config
            self.get_logger().error(f'configure failed: {err}')
            self.release()
            return TransitionCallbackReturn.FAILURE
        self._configured = True
        self._pose_source = self._make_pose_source()
        if self._pose_source.mode is PoseMode.LOCALIZER:
            self._localizer_sub = self.create_subscription(
                PoseWithCovarianceStamped, self._pose_source.located.source,
                self.localizer_callback, LOCALIZER_QOS)
        self._plan_pub = self.create_lifecycle_publisher(Path, 'plan', PLAN_QOS)
        self._diag_pub = self.create_lifecycle_publisher(
            DiagnosticArray, PLANNER_DIAGNOSTICS_TOPIC, PLANNER_DIAGNOSTICS_QOS)
        self._odom_sub = self.create_subscription(Odometry, 'odom', self.odom_callback,
                                                  ODOM_QOS)
        self._goal_sub = self.create_subscription(PoseStamped, 'goal_pose', self.goal_callback,
                                                  GOAL_QOS)
        if self._use_map:
            self._map_sub = self.create_subscription(OccupancyGrid, 'map', self.map_callback,
                                                     MAP_QOS)
        if self._use_scan:
            self._scan_sub = self.create_subscription(LaserScan, 'scan', self.scan_callback,
                                                      SCAN_QOS)
        self._set_goal(self._goal_parameter())
        self.get_logger().info('configured' + (
            ' (planning on the map' + (' and scans' if self._use_scan else '') + ')'
            if self._use_map else '') + f'; plans start from {self._pose_source.describe()}')
        return super().on_configure(state)

    def _make_pose_source(self) -> RobotPose:
        """Return the pose source localization_topic and tf2's presence choose (robot_pose)."""
        topic = str(self.get_parameter('localization_topic').value)
        mode = choose_mode(topic)
        buffer = None
        if mode is PoseMode.TF:
            buffer, self._tf_listener = make_buffer(self)
        return RobotPose(mode, span=ODOM_HISTORY_S,
                         global_frame=str(self.get_parameter('global_frame').value), topic=topic,
                         buffer=buffer,
                         robot_base_frame=str(self.get_parameter('robot_base_frame').value),
                         tolerance=float(self.get_parameter('transform_tolerance').value),
                         max_travel=float(self.get_parameter('localization_max_travel').value),
                         max_rotation=float(
                             self.get_parameter('localization_max_rotation').value))

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable the publishers; plan a goal given as a parameter, or publish analytic_path."""
        result = super().on_activate(state)
        if result != TransitionCallbackReturn.SUCCESS:
            return result
        self._active = True
        self.get_logger().info('active')
        self.replanner.settings = self._replan_settings()
        period = self.replanner.settings.check_period
        if period > 0.0:
            self._check_timer = self.create_timer(period, self.check_plan)
        if self.get_parameter('analytic_path').value:
            self._publish_analytic()
        else:
            self._try_plan()
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop planning and publishing (the latched plan stays with its subscribers)."""
        self._active = False
        self._destroy_check_timer()
        self.get_logger().info('inactive: goals are not planned until activated')
        return super().on_deactivate(state)

    def _destroy_check_timer(self) -> None:
        self.destroy_entities(self._check_timer)
        self._check_timer = None

    def release(self) -> None:
        """Stop planning; destroy the publishers and subscriptions; drop planner and world."""
        self._active = False
        self._destroy_check_timer()
        self.replanner.drop_plan()
        self._configured = False
        self.destroy_entities(self._plan_pub, self._diag_pub, self._odom_sub, self._goal_sub,
                              self._map_sub, self._scan_sub, self._localizer_sub)
        self._plan_pub = self._diag_pub = None
        self._odom_sub = self._goal_sub = self._map_sub = self._scan_sub = None
        self._localizer_sub = None
        if self._tf_listener is not None:
            self._tf_listener.unregister()
            self._tf_listener = None
        self._planner = None
        self._grid = None
        self._world = None
        self._state = None
        self._odom_time = None
        self._odom_stale = False
        self._pose_source.clear()
        self._pending_goal = None
        self._scans.reset()

    # ------------------------------------------------------------------ parameters
    def parameters_callback(self, parameters: list[Parameter]) -> SetParametersResult:
        """Refuse a malformed goal, an unknown world or analytic path, bad planner settings."""
        reasons = parameter_problems(parameters)
        reasons += self._check_modes(parameters)
        reasons += range_problems(PARAMETERS, parameters)  # robot_radius's -1 beside its range
        if reasons:
            return SetParametersResult(successful=False, reason='; '.join(reasons))
        return SetParametersResult(successful=True)

    def _check_modes(self, parameters: list[Parameter]) -> list[str]:
        """Refuse use_scan without use_map, track_moving without use_scan (values after the set).

        A parameter not declared yet (during the declarations) is not judged; configure
        judges the combination again.
        """
        given = {p.name: p.value for p in parameters}

        def value(name: str) -> Any:
            if name in given:
                return given[name]
            return self.get_parameter(name).value if self.has_parameter(name) else None

        if not {'use_map', 'use_scan', 'track_moving'} & given.keys():
            return []
        if value('use_scan') and value('use_map') is False:
            return ['use_scan needs use_map (scans mark the cells of the map)']
        if value('track_moving') and value('use_scan') is False:
            return ['track_moving needs use_scan (it tracks what the scans see)']
        return []

    def post_parameters_callback(self, parameters: list[Parameter]) -> None:
        """Rebuild a configured planner after a change; a new goal is planned when active.

        Unconfigured, nothing is built: configure reads the parameters as they then are.
        """
        names = {p.name for p in parameters}
        if names & {'replan_period', 'progress_timeout', 'progress_radius', 'progress_angle'}:
            # at the next check (replan_check_rate: at activate)
            self.replanner.settings = replace(
                self.replanner.settings,
                replan_period=float(self.get_parameter('replan_period').value),
                progress_timeout=float(self.get_parameter('progress_timeout').value),
                progress_radius=float(self.get_parameter('progress_radius').value),
                progress_angle=float(self.get_parameter('progress_angle').value))
        if not self._configured:
            return
        for name in ('use_map', 'use_scan'):
            if name in names and bool(self.get_parameter(name).value) != getattr(
                    self, f'_{name}'):
                self.get_logger().info(f'{name} applies at the next configure (cleanup, then '
                                       'configure)')
        try:
            if 'world_file' in names:
                path = str(self.get_parameter('world_file').value)
                self._world = self._read_world() if path else None
            self._planner = self._make_planner()
        except Exception as err:  # validated above: a bug, but keep running
            self.get_logger().error(f'could not apply {sorted(names)}: {err}')
            return
        if 'goal' in names:
            self._set_goal(self._goal_parameter())
            self._try_plan()
        if ('analytic_path' in names and self._active
                and self.get_parameter('analytic_path').value):
            self._publish_analytic()

    def _read_world(self) -> World:
        return load_world(resolve_data_file(str(self.get_parameter('world_file').value)))

    def _planner_config(self) -> PlannerConfig:
        values = {name: self.get_parameter(name).value for name in PLANNER_FIELDS}
        world_radius = self._world.robot_radius if self._world is not None else 0.0
        values['robot_radius'] = radius_in_force(float(values['robot_radius']), world_radius)
        values['iterations'] = int(values['iterations'])
        values['seed'] = int(values['seed'])
        values['simplify'] = bool(values['simplify'])
        for key in ('time_limit', 'range', 'clearance', 'start_clearance',
                    'drive_on_heading_distance'):
            values[key] = float(values[key])
        footprint = resolve(str(self.get_parameter('footprint').value),
                            world_footprint=self._world.footprint if self._world else None)
        if not footprint.is_circle:
            values['footprint'] = tuple(map(tuple, footprint.vertices.tolist()))
        return PlannerConfig(**values)

    def _make_planner(self) -> RrtStarPlanner | None:
        """Return the planner for the settings in force (None: use_map and no map yet).

        On the grid, a change of robot_radius or clearance re-inflates the map: the scans'
        marks are dropped with the old grid.
        """
        config = self._planner_config()
        if self._given_planner is not None:
            return self._given_planner
        if not self._use_map:
            if self._world is None:
                return RrtStarPlanner([], FREE_PLANE_BOUNDS, config=config)
            return RrtStarPlanner(self._world.obstacles, self._world.bounds, config=config)
        if self._grid is None:
            return None
        if abs(self._grid.inflation - config.inflation) > 1e-12:
            self._grid = PlanningGrid(self._grid.map, inflation=config.inflation)
        return RrtStarPlanner.on_grid(self._grid, config=config)

    def _goal_parameter(self) -> np.ndarray | None:
        try:
            goal = self.get_parameter('goal').value
        except ParameterUninitializedException:
            return None
        if goal is None or len(goal) == 0:
            return None
        return np.array(goal, dtype=float)

    # ------------------------------------------------------------------ callbacks
    @property
    def robot_pose(self) -> np.ndarray | None:
        """The pose in the plan's frame (x, y, yaw) plans start from, or None.

        The latest valid odometry, composed as the pose source says (RobotPose.current);
        None without odometry or while there is no pose in the plan's frame.
        """
        try:
            pose, _ = self._pose_source.current(self._state, None)
        except LocalizationError:
            return None
        return pose

    def _start(self) -> np.ndarray | None:
        """Return the pose plans start from; None (a throttled warning) while there is none."""
        try:
            pose, _ = self._pose_source.current(self._state, None)
        except LocalizationError as err:
            if self._problems.report('localization'):
                self.get_logger().warning(f"no pose in the plan's frame: {err}; goals wait")
            return None
        if pose is not None and self._problems.resolve('localization'):
            self.get_logger().info(f"a pose in the plan's frame again, from "
                                   f'{self._pose_source.describe()}')
        return pose

    def localizer_callback(self, msg: PoseWithCovarianceStamped) -> None:
        """Take the localizer's pose (its correction map <- odom); plan a pending goal.

        One the odometry kept cannot place drops the correction (goals wait); one in another
        frame, or not a pose, is refused with one throttled error.
        """
        try:
            self._pose_source.add_localizer(msg, self._now())
        except LocalizationError:
            return  # said when a plan needs the pose
        except Exception as err:  # ValueError mostly; nothing may escape a callback
            if self._problems.report('localizer'):
                self.get_logger().error(f'localizer pose refused: {err}')
            return
        self._problems.resolve('localizer')
        if self._pending_goal is not None:
            self._try_plan()

    def odom_callback(self, msg: Odometry) -> None:
        """Keep the robot's pose (and recent ones with their twists, for scans).

        Then place the scans waiting for odometry that covers their stamps, and plan a
        pending goal.
        """
        try:
            self._state = odometry_to_state(msg)
        except ValueError as err:
            self.get_logger().warning(f'ignoring odometry: {err}', throttle_duration_sec=1.0)
            return
        self._odom_time = measured_time(stamp_to_seconds(msg.header.stamp), self._now())
        self._pose_source.add_odometry(stamp_to_seconds(msg.header.stamp), self._state,
                                       msg.header.frame_id, odometry_twist(msg))
        self._scans.place_pending(self._grid, self._pose_source)
        if self._pending_goal is not None:
            self._try_plan()

    def scan_callback(self, msg: LaserScan) -> None:
        """Mark and clear the grid with a scan, placed with the pose at its stamp.

        PlannerScans.take: a malformed scan is dropped with one throttled error; one newer
        than the odometry covers waits for it.
        """
        self._scans.take(msg, self._grid, self._pose_source)

    def _scan_body(self) -> Footprint | None:
        """Return the planner's footprint: returns inside it are the robot."""
        return self._planner.footprint if self._planner is not None else None

    def map_callback(self, msg: OccupancyGrid) -> None:
        """Plan on a new map from now on (its grid replaces the old one, scan marks too).

        A malformed map is refused with one throttled error; the grid in force stays.
        """
        frame = str(self.get_parameter('global_frame').value)
        try:
            occupancy = grid_from_message(msg, frame_id=frame)
            config = self._planner_config()
            grid = PlanningGrid(occupancy, inflation=config.inflation)
            planner = (self._given_planner if self._given_planner is not None
                       else RrtStarPlanner.on_grid(grid, config=config))
        except Exception as err:  # GridError (a ValueError); nothing may escape a callback
            if self._problems.report('map'):
                kept = 'the grid in force stays' if self._grid is not None else 'no map yet'
                self.get_logger().error(f'map refused ({kept}): {err}')
            return
        self._problems.resolve('map')
        self._grid, self._planner = grid, planner
        self.map_count += 1
        self.get_logger().info(
            f'map: {occupancy.width} x {occupancy.height} cells of {occupancy.resolution:g} '
            f'm, origin {list(occupancy.origin)}; planning on it, inflated by '
            f'{grid.inflation:g} m')
        if self._pending_goal is not None:
            self._try_plan()

    def goal_callback(self, msg: PoseStamped) -> None:
        """Plan to a goal sent as a PoseStamped (RViz's 2D Goal Pose); refused unless active."""
        if not self._active:
            self.get_logger().warning('goal refused: the planner is inactive (activate it '
                                      'first); no plan published')
            return
        frame = str(self.get_parameter('global_frame').value)
        try:
            problem = frame_problem(msg.header.frame_id, frame, 'goals')
            if problem is not None:
                raise ValueError(problem)
            goal = pose_to_array(msg.pose)
        except ValueError as err:
            self.get_logger().error(f'goal refused, no plan published: {err}')
            self._report(PlannerDiagnostics(planned=False, detail=f'goal refused: {err}'))
            return
        self._set_goal(goal)
        self._try_plan()

    def _set_goal(self, goal: np.ndarray | None) -> None:
        self._pending_goal = goal
        self._waiting_reported = False

    def _try_plan(self) -> None:
        """Plan the pending goal if the node is active, the robot's pose (and map) known."""
        if (not self._active or self._pending_goal is None
                or self.get_parameter('analytic_path').value):
            return
        if self._planner is None:
            if self._use_map and not self._waiting_reported:
                goal = self._pending_goal
                detail = (f'waiting for map: no valid OccupancyGrid on map yet; the goal '
                          f'({goal[0]:g}, {goal[1]:g}) is planned when one comes')
                self.get_logger().info(detail)
                self._report(PlannerDiagnostics(planned=False, detail=detail, waiting=True))
                self._waiting_reported = True
            return
        if self._state is None:
            self.get_logger().info('goal received: waiting for odometry', once=True)
            return
        start = self._start()
        if start is None:
            return
        goal, self._pending_goal = self._pending_goal, None
        self._adopt(self.replanner.plan_goal(self._planner, start, goal, now=self._now()))

    def check_plan(self) -> None:
        """Re-plan the goal in force when the rest of its plan is blocked, or periodically.

        Blocked means that the rest of the plan (from the robot's projection onto it, less
        its first stretch: RrtStarPlanner.rest_problem) no longer passes the check plans are
        made with: an obstacle the map did not have, marked by the laser, now violates the
        clearance. The world file's obstacles do not change, so without use_map only
        replan_period re-plans. The decision is the re-planner's (core/replanning.py).
        Nothing is checked while the odometry is stale (_odometry_stale).
        """
        if (not self._active or self._state is None or self._planner is None
                or self._pending_goal is not None or self.replanner.plan is None
                or self.get_parameter('analytic_path').value):
            return
        if self._odometry_stale():
            return
        start = self._start()
        if start is None:
            return
        # a re-plan's first turn is one the controller's obstacles allow (its pieces, as
        # this node's scans make them)
        held = self._scans.held_obstacles
        self._adopt(self.replanner.check(self._planner, start, now=self._now(),
                                         grid=self._grid, local_obstacles=held))

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _odometry_stale(self) -> bool:
        """Say whether the odometry is stale (odom_timeout, the controller's rule); log once.

        A re-plan from a pose the robot may have left long ago (the odometry's driver or the
        simulator died) is a re-plan blind: re-planning stops, with one warning, and resumes
        with one line when odometry comes again. The no-progress rule's clock then restarts:
        the time without odometry is not time the robot stood.
        """
        timeout = float(self.get_parameter('odom_timeout').value)
        now = self._now()
        age = now - self._odom_time if self._odom_time is not None else math.inf
        if is_stale(age, timeout):
            if not self._odom_stale:
                self._odom_stale = True
                self.get_logger().warning(
                    f'odometry is stale (the latest was measured {age:.2f} s ago; '
                    f'odom_timeout {timeout:g} s): not re-planning until it comes again')
            return True
        if self._odom_stale:
            self._odom_stale = False
            self.replanner.restart_progress(now)
            self.get_logger().info('odometry is fresh again: re-planning resumes')
        return False

    def _adopt(self, decision: ReplanDecision) -> None:
        """Publish the re-planner's new plan, or log and report why there is none."""
        if not decision.attempted:
            return
        assert decision.trigger is not None and decision.goal is not None
        assert decision.start is not None
        trigger, goal = decision.trigger, decision.goal
        if decision.problem is not None:
            self.get_logger().info(f'the rest of the plan is blocked ({decision.problem}): '
                                   're-planning')
        if decision.outcome is ReplanOutcome.FAILED:
            err = decision.error
            cause = str(err) if isinstance(err, PlanningError) else (
                f'planner failed: {type(err).__name__}: {err}')
            detail = f'no plan to ({goal[0]:g}, {goal[1]:g}): {cause}'
            if trigger is PlanTrigger.GOAL:
                self.get_logger().error(f'{detail}; none published')
            elif self._problems.report('replan'):
                self.get_logger().warning(f'{trigger} re-plan failed: {detail}; the plan in '
                                          'force stays')
            self._report(PlannerDiagnostics(planned=False, detail=detail, trigger=trigger,
                                            replans=self.replan_count))
            return
        assert decision.waypoints is not None
        if trigger is not PlanTrigger.GOAL:
            self._problems.resolve('replan')
        poses = waypoints_to_poses(decision.waypoints, float(decision.start[2]), float(goal[2]))
        self._publish(poses, trigger)

    def _publish_analytic(self) -> None:
        _, poses = analytic_path(str(self.get_parameter('analytic_path').value)).sample(
            ANALYTIC_SAMPLES)
        self.replanner.drop_plan()  # an analytic path is not re-planned
        self._publish(poses)

    def _publish(self, poses: np.ndarray, trigger: PlanTrigger = PlanTrigger.GOAL) -> None:
        msg = poses_to_path(poses, frame_id=str(self.get_parameter('global_frame').value),
                            stamp=self.get_clock().now().to_msg())
        assert self._plan_pub is not None  # active
        self._plan_pub.publish(msg)
        self.last_plan = poses
        self.plan_count += 1
        length = path_length(poses)
        detail = f'published a plan ({trigger}): {len(poses)} poses, {length:.2f} m'
        self.get_logger().info(detail)
        self._report(PlannerDiagnostics(planned=True, detail=detail, poses=len(poses),
                                        length=length, trigger=trigger,
                                        replans=self.replan_count))

    def _report(self, outcome: PlannerDiagnostics) -> None:
        """Publish the outcome of the latest goal on planner/diagnostics."""
        self.last_outcome = outcome
        if self._diag_pub is None:
            return
        self._diag_pub.publish(diagnostic_array(
            name=f'{self.get_name()}: RRT*', hardware_id=self.get_fully_qualified_name(),
            level=outcome.level, message=outcome.detail, values=outcome.to_values(),
            stamp=self.get_clock().now().to_msg()))


def main(args: list[str] | None = None) -> int:
    """Run the node until Ctrl-C (exit code 2, with the reason, on invalid parameters).

    ``--help`` prints the parameters and their defaults and starts nothing.
    """
    return run_node(GlobalPlannerNode, 'global_planner', args, summary=SUMMARY,
                    parameters=PARAMETERS)


if __name__ == '__main__':
    sys.exit(main())
