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

"""global_planner: OMPL RRT* from the current odometry to the goal; publishes plan.

The goal comes from the ``goal`` parameter ([x, y, theta]) or a PoseStamped on
``goal_pose`` (RViz's "2D Goal Pose"). Each new goal is planned once, from the latest
``odom`` pose, around the world's obstacles inflated by robot_radius + clearance, and
published on ``plan`` (reliable, transient_local: a late controller still gets it). With
``analytic_path`` set the node publishes that path, sampled, instead of planning.

A goal it cannot plan to (inside an inflated obstacle, walled off, out of bounds, not
finite, in another frame), or a start in collision, is logged as an error and nothing is
published on ``plan``: the plan in force stays, and the next valid goal is planned as usual.
The outcome of every goal, planned or not and why, is published on ``planner/diagnostics``
(DiagnosticArray, reliable and transient_local; keys in core/diagnostics.py), so that a
supervisor such as closed_loop learns that no plan will come.
"""

from __future__ import annotations

import math
import sys
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry, Path
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter

from mpc_local_planner.core.diagnostics import PLANNER_DIAGNOSTICS_TOPIC, PlannerDiagnostics
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.paths import analytic_path
from mpc_local_planner.core.planner import path_length, PlannerConfig, RrtStarPlanner
from mpc_local_planner.ros.conversions import (
    odometry_to_state,
    pose_to_array,
    poses_to_path,
)
from mpc_local_planner.ros.node_main import run_node
from mpc_local_planner.ros.parameters import DEFAULT_WORLD_FILE, describe
from mpc_local_planner.ros.qos import GOAL_QOS, ODOM_QOS, PLAN_QOS, PLANNER_DIAGNOSTICS_QOS
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import load_world, World

__all__ = ['GlobalPlannerNode', 'main', 'waypoints_to_poses']


# Poses of a published analytic path (enough for RViz and for a polyline controller).
ANALYTIC_SAMPLES = 101

_PLANNER_FIELDS = ('iterations', 'time_limit', 'seed', 'range', 'robot_radius', 'clearance',
                   'simplify')


def waypoints_to_poses(waypoints: np.ndarray, start_yaw: float, goal_yaw: float) -> np.ndarray:
    """Return (M, 3) poses: each waypoint heads along its outgoing segment.

    The first pose keeps the robot's yaw and the last the goal's, so that a controller
    turns in place at the ends (as `WaypointPath.from_poses` reads them).
    """
    pts = np.asarray(waypoints, dtype=float)
    directions = np.arctan2(np.diff(pts[:, 1]), np.diff(pts[:, 0]))
    yaw = np.concatenate([[start_yaw], directions[1:], [goal_yaw]])
    return np.column_stack([pts, yaw])


def _check_goal(goal: list[float] | None) -> str | None:
    if goal is None or len(goal) == 0:
        return None
    if len(goal) != 3 or not all(math.isfinite(float(v)) for v in goal):
        return f'goal must be [x, y, theta] (3 finite numbers) or empty, got {list(goal)}'
    return None


class GlobalPlannerNode(Node):
    """Plan with RRT* from odom to the goal and publish the plan."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('global_planner', **kwargs)
        self.add_on_set_parameters_callback(self.parameters_callback)
        self._declare_parameters()
        self.add_post_set_parameters_callback(self.post_parameters_callback)
        self._world = self._read_world()
        self._planner = self._make_planner()
        self._state: np.ndarray | None = None
        self._pending_goal: np.ndarray | None = self._goal_parameter()
        self.last_plan: np.ndarray | None = None
        self.plan_count = 0
        self._plan_pub = self.create_publisher(Path, 'plan', PLAN_QOS)
        self._diag_pub = self.create_publisher(DiagnosticArray, PLANNER_DIAGNOSTICS_TOPIC,
                                               PLANNER_DIAGNOSTICS_QOS)
        self.last_outcome: PlannerDiagnostics | None = None
        self._odom_sub = self.create_subscription(Odometry, 'odom', self.odom_callback,
                                                  ODOM_QOS)
        self._goal_sub = self.create_subscription(PoseStamped, 'goal_pose', self.goal_callback,
                                                  GOAL_QOS)
        if self.get_parameter('analytic_path').value:
            self._publish_analytic()

    # ------------------------------------------------------------------ parameters
    def _declare_parameters(self) -> None:
        defaults = PlannerConfig()
        self.declare_parameter('world_file', DEFAULT_WORLD_FILE, describe(
            "world YAML/JSON: obstacles and bounds (a path, or a name in the package's "
            'config/ or config/worlds/); used at the next plan'))
        self.declare_parameter('goal', Parameter.Type.DOUBLE_ARRAY, describe(
            'goal [x, y, theta]; setting it plans from the current odometry (optional: '
            'goal_pose messages do the same)'))
        self.declare_parameter('iterations', defaults.iterations, describe(
            'RRT* iterations per plan', int_range=(1, 10_000_000)))
        self.declare_parameter('time_limit', defaults.time_limit, describe(
            'upper bound on planning time (s)', float_range=(0.001, 600.0)))
        self.declare_parameter('seed', defaults.seed, describe(
            "seed of OMPL's random numbers (reproducible plans)", int_range=(0, 2**31 - 1)))
        self.declare_parameter('range', defaults.range, describe(
            'RRT* extension length (m); 0 = OMPL chooses', float_range=(0.0, 1e3)))
        self.declare_parameter('robot_radius', defaults.robot_radius, describe(
            "robot radius (m); the larger of this and the world's is used",
            float_range=(0.0, 10.0)))
        self.declare_parameter('clearance', defaults.clearance, describe(
            'extra obstacle inflation beyond the radius (m)', float_range=(0.0, 10.0)))
        self.declare_parameter('simplify', defaults.simplify, describe(
            "shortcut the path with OMPL's simplifier"))
        self.declare_parameter('analytic_path', '', describe(
            "publish this analytic path (e.g. 'paper_sinusoid') instead of planning; '' = "
            'plan with RRT*'))
        self.declare_parameter('frame_id', 'map', describe('frame of the plan'))

    def parameters_callback(self, parameters: list[Parameter]) -> SetParametersResult:
        """Refuse a malformed goal, an unknown world or analytic path, bad planner settings."""
        reasons = []
        for parameter in parameters:
            if parameter.name == 'goal':
                reason = _check_goal(parameter.value)
                if reason:
                    reasons.append(reason)
            elif parameter.name == 'world_file':
                try:
                    load_world(resolve_data_file(str(parameter.value)))
                except Exception as err:  # any failure to load refuses it
                    reasons.append(str(err) or type(err).__name__)
            elif parameter.name == 'analytic_path' and parameter.value:
                try:
                    analytic_path(str(parameter.value))
                except ValueError as err:
                    reasons.append(str(err))
        if reasons:
            return SetParametersResult(successful=False, reason='; '.join(reasons))
        return SetParametersResult(successful=True)

    def post_parameters_callback(self, parameters: list[Parameter]) -> None:
        """Rebuild the planner after a change; a new goal is planned at once."""
        names = {p.name for p in parameters}
        try:
            if 'world_file' in names:
                self._world = self._read_world()
            self._planner = self._make_planner()
        except Exception as err:  # validated above: a bug, but keep running
            self.get_logger().error(f'could not apply {sorted(names)}: {err}')
            return
        if 'goal' in names:
            self._pending_goal = self._goal_parameter()
            self._try_plan()
        if 'analytic_path' in names and self.get_parameter('analytic_path').value:
            self._publish_analytic()

    def _read_world(self) -> World:
        return load_world(resolve_data_file(str(self.get_parameter('world_file').value)))

    def _make_planner(self) -> RrtStarPlanner:
        values = {name: self.get_parameter(name).value for name in _PLANNER_FIELDS}
        values['robot_radius'] = max(float(values['robot_radius']), self._world.robot_radius)
        values['iterations'] = int(values['iterations'])
        values['seed'] = int(values['seed'])
        values['simplify'] = bool(values['simplify'])
        for key in ('time_limit', 'range', 'clearance'):
            values[key] = float(values[key])
        return RrtStarPlanner(self._world.obstacles, self._world.bounds,
                              config=PlannerConfig(**values))

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
        """The latest valid odometry pose (x, y, yaw) plans start from, or None."""
        return None if self._state is None else self._state.copy()

    def odom_callback(self, msg: Odometry) -> None:
        """Keep the robot's pose; plan a pending goal once the pose is known."""
        try:
            self._state = odometry_to_state(msg)
        except ValueError as err:
            self.get_logger().warning(f'ignoring odometry: {err}', throttle_duration_sec=1.0)
            return
        if self._pending_goal is not None:
            self._try_plan()

    def goal_callback(self, msg: PoseStamped) -> None:
        """Plan to a goal sent as a PoseStamped (RViz's 2D Goal Pose)."""
        frame = str(self.get_parameter('frame_id').value)
        try:
            if msg.header.frame_id != frame:
                problem = (f'frame {msg.header.frame_id!r} is not {frame!r} (this node does '
                           'not transform goals)')
                raise ValueError(problem)
            goal = pose_to_array(msg.pose)
        except ValueError as err:
            self.get_logger().error(f'goal refused, no plan published: {err}')
            self._report(PlannerDiagnostics(planned=False, detail=f'goal refused: {err}'))
            return
        self._pending_goal = goal
        self._try_plan()

    def _try_plan(self) -> None:
        if self._pending_goal is None or self.get_parameter('analytic_path').value:
            return
        if self._state is None:
            self.get_logger().info('goal received: waiting for odometry', once=True)
            return
        goal, self._pending_goal = self._pending_goal, None
        start = self._state.copy()
        try:
            waypoints = self._planner.plan(start, goal)
        except Exception as err:  # PlanningError; anything else must not kill the executor
            cause = str(err) if isinstance(err, PlanningError) else (
                f'planner failed: {type(err).__name__}: {err}')
            detail = f'no plan to ({goal[0]:g}, {goal[1]:g}): {cause}'
            self.get_logger().error(f'{detail}; none published')
            self._report(PlannerDiagnostics(planned=False, detail=detail))
            return
        poses = waypoints_to_poses(waypoints, float(start[2]), float(goal[2]))
        self._publish(poses)

    def _publish_analytic(self) -> None:
        _, poses = analytic_path(str(self.get_parameter('analytic_path').value)).sample(
            ANALYTIC_SAMPLES)
        self._publish(poses)

    def _publish(self, poses: np.ndarray) -> None:
        msg = poses_to_path(poses, frame_id=str(self.get_parameter('frame_id').value),
                            stamp=self.get_clock().now().to_msg())
        self._plan_pub.publish(msg)
        self.last_plan = poses
        self.plan_count += 1
        length = path_length(poses)
        detail = f'published a plan: {len(poses)} poses, {length:.2f} m'
        self.get_logger().info(detail)
        self._report(PlannerDiagnostics(planned=True, detail=detail, poses=len(poses),
                                        length=length))

    def _report(self, outcome: PlannerDiagnostics) -> None:
        """Publish the outcome of the latest goal on planner/diagnostics."""
        self.last_outcome = outcome
        status = DiagnosticStatus()
        status.name = f'{self.get_name()}: RRT*'
        status.hardware_id = self.get_fully_qualified_name()
        status.level = bytes([int(outcome.level)])
        status.message = outcome.detail
        status.values = [KeyValue(key=k, value=v) for k, v in outcome.to_values()]
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [status]
        self._diag_pub.publish(array)


def main(args: list[str] | None = None) -> int:
    """Run the node until Ctrl-C (exit code 2, with the reason, on invalid parameters)."""
    return run_node(GlobalPlannerNode, 'global_planner', args)


if __name__ == '__main__':
    sys.exit(main())
