# SPDX-License-Identifier: Apache-2.0
"""global_planner's parameters: their table and the checks of single values.

The node (ros/global_planner_node.py) declares PARAMETERS and refuses a set for which
`parameter_problems` names a problem; combinations (use_scan without use_map) are the
node's to judge, with the values in force.
"""

from __future__ import annotations

import math

from rclpy.parameter import Parameter

from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.footprint import FROM_WORLD, parse_footprint
from mpc_local_planner.core.paths import analytic_path
from mpc_local_planner.core.planner_config import PlannerConfig
from mpc_local_planner.core.replanning import (
    PROGRESS_ANGLE,
    PROGRESS_RADIUS,
    PROGRESS_TIMEOUT,
)
from mpc_local_planner.ros.lockstep import LOCKSTEP_PARAMETER
from mpc_local_planner.ros.parameters import ParameterSpec
from mpc_local_planner.ros.robot_pose import pose_parameters
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import load_world

__all__ = ['PARAMETERS', 'PLANNER_FIELDS', 'parameter_problems']

PLANNER_FIELDS = ('iterations', 'time_limit', 'seed', 'range', 'robot_radius', 'clearance',
                   'simplify', 'start_clearance', 'drive_on_heading_distance')
_DEFAULTS = PlannerConfig()  # the single source of the planner's defaults
_CONTROLLER = ControllerSettings()  # odom_timeout: the controller's, one rule for both


PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('world_file', '',
                  "world YAML/JSON: obstacles and bounds (a path, or a name in the package's "
                  "config/ or config/worlds/); used at the next plan; '' = none: an empty "
                  'plane without bounds (every plan the straight line), or with use_map the '
                  'map alone; with use_map a world gives only its robot_radius and footprint'),
    ParameterSpec('use_map', False,
                  "plan on the occupancy grid from `map` (unknown cells free) instead of the "
                  "world's obstacles; applies at the next configure"),
    ParameterSpec('use_scan', False,
                  'mark the grid with `scan` returns and clear it along the beams (needs '
                  'use_map); applies at the next configure'),
    ParameterSpec('laser_pose', [0.0, 0.0, 0.0],
                  'pose [x, y, yaw] of the laser in the robot frame (base_link)'),
    ParameterSpec('robot_base_frame', 'base_link',
                  'the robot frame: scans must be in it (laser_pose says where the laser '
                  'sits); read when a scan comes'),
    ParameterSpec('goal', Parameter.Type.DOUBLE_ARRAY,
                  'goal [x, y, theta]; setting it plans from the current odometry once the '
                  'node is active (optional: goal_pose messages do the same)'),
    ParameterSpec('iterations', _DEFAULTS.iterations, 'RRT* iterations per plan',
                  int_range=(1, 10_000_000)),
    ParameterSpec('time_limit', _DEFAULTS.time_limit, 'upper bound on planning time (s)',
                  float_range=(0.001, 600.0)),
    ParameterSpec('seed', _DEFAULTS.seed, "seed of OMPL's random numbers (reproducible plans)",
                  int_range=(0, 2**31 - 1)),
    ParameterSpec('range', _DEFAULTS.range, 'RRT* extension length (m); 0 = OMPL chooses',
                  float_range=(0.0, 1e3)),
    ParameterSpec('robot_radius', FROM_WORLD,
                  "the round robot's radius (m), when no polygon footprint applies; -1 = the "
                  "world file's robot_radius (0 without one); a radius >= 0 is the robot's, "
                  "smaller than the world's too", float_range=(0.0, 10.0), special=FROM_WORLD),
    ParameterSpec('footprint', '',
                  "the robot's convex polygon in base_link, Nav2's form \"[[x, y], ...]\"; '' = "
                  "the world file's footprint, or a circle of robot_radius"),
    ParameterSpec('clearance', _DEFAULTS.clearance,
                  'extra obstacle inflation beyond the radius (m)', float_range=(0.0, 10.0)),
    ParameterSpec('simplify', _DEFAULTS.simplify, "shortcut the path with OMPL's simplifier"),
    ParameterSpec('start_clearance', _DEFAULTS.start_clearance,
                  'with a footprint and use_scan, the distance (m) a re-plan keeps from the '
                  "convex pieces the laser's returns make (the controller's obstacles, "
                  'remembered for obstacle_memory s): a turn the grid allows but they forbid '
                  'is one the controller cannot make; a start already closer keeps what it has',
                  float_range=(0.0, 1.0)),
    ParameterSpec('drive_on_heading_distance', _DEFAULTS.drive_on_heading_distance,
                  "with a footprint and use_scan, how far (m) a re-plan kept clear of the "
                  "convex pieces (start_clearance) may first drive straight on a heading the "
                  "start's turns allow, to where the robot can turn, when no plan leaves the "
                  "start otherwise (Nav2's DriveOnHeading); 0 = never",
                  float_range=(0.0, 10.0)),
    ParameterSpec('obstacle_memory', 5.0,
                  'with use_scan, seconds a convex piece seen by the laser is remembered for '
                  "start_clearance (the controller's obstacle_memory); read at configure",
                  float_range=(0.01, 3600.0)),
    ParameterSpec('track_moving', False,
                  "with use_scan, follow the scan's small clusters over time and forget the "
                  'convex pieces a moving one built (start_clearance), as the controller with '
                  'its track_moving does (perception/tracking.py); the grid still marks every '
                  'return where it is now; read at configure'),
    ParameterSpec('analytic_path', '',
                  "publish this analytic path (e.g. 'paper_sinusoid') instead of planning; '' "
                  '= plan with RRT*'),
    ParameterSpec('global_frame', 'map', 'frame of the plan'),
    ParameterSpec('replan_check_rate', 2.0,
                  'how often (Hz) the rest of the plan is checked against the grid (map plus '
                  'scans) with the rule plans are made with; a blocked plan is re-planned from '
                  'the current odometry; 0 = never (read at activate)',
                  float_range=(0.0, 100.0)),
    ParameterSpec('replan_period', 0.0,
                  're-plan the goal in force this often (s) even when the plan is clear; 0 = '
                  'only when blocked or for a new goal', float_range=(0.0, 3600.0)),
    ParameterSpec('progress_timeout', PROGRESS_TIMEOUT,
                  "Nav2's progress checker: when the robot, away from the goal, has neither "
                  'moved progress_radius nor turned progress_angle in this many seconds, the '
                  'goal is re-planned from where it '
                  "stands (a forward-only robot that coasted past a new plan's start may have "
                  'no way back onto it); 0 = never', float_range=(0.0, 3600.0)),
    ParameterSpec('progress_radius', PROGRESS_RADIUS,
                  'metres that count as progress for progress_timeout, and the distance to '
                  'the goal within which standing still is arriving',
                  float_range=(0.0, 100.0)),
    ParameterSpec('progress_angle', PROGRESS_ANGLE,
                  "radians of turn that count as progress (Nav2's PoseProgressChecker "
                  'required_movement_angle): a robot that turned in place and then stood is '
                  'stuck; 0 = only the position counts', float_range=(0.0, 6.3)),
    ParameterSpec('odom_timeout', _CONTROLLER.odom_timeout,
                  "odometry older than this (s of ROS time) is stale, by the controller's rule "
                  'and default: re-planning (blocked, periodic, no_progress) stops with one '
                  'warning until odometry comes again; a new goal is still planned from the '
                  'latest pose', float_range=(0.001, 3600.0)),
    *pose_parameters('the planner plans nothing (a goal waits, nothing is re-planned)'),
    LOCKSTEP_PARAMETER,
    ParameterSpec('autostart', True,
                  'configure and activate at start; false = wait for a lifecycle manager (or '
                  '`ros2 lifecycle set`)', read_only=True),
)


def _check_laser_pose(pose: list[float]) -> str | None:
    if len(pose) != 3 or not all(math.isfinite(float(v)) for v in pose):
        return f'laser_pose must be [x, y, yaw] (3 finite numbers), got {list(pose)}'
    return None


def _check_goal(goal: list[float] | None) -> str | None:
    if goal is None or len(goal) == 0:
        return None
    if len(goal) != 3 or not all(math.isfinite(float(v)) for v in goal):
        return f'goal must be [x, y, theta] (3 finite numbers) or empty, got {list(goal)}'
    return None


def parameter_problems(parameters: list[Parameter]) -> list[str]:
    """Return why each parameter's value is refused on its own (empty: none is).

    A malformed goal or laser_pose, a world file that does not load, a footprint that does
    not parse, an unknown analytic path.
    """
    reasons = []
    for parameter in parameters:
        if parameter.name == 'goal':
            reason = _check_goal(parameter.value)
            if reason:
                reasons.append(reason)
        elif parameter.name == 'laser_pose':
            reason = _check_laser_pose(parameter.value)
            if reason:
                reasons.append(reason)
        elif parameter.name == 'world_file' and parameter.value:
            try:
                load_world(resolve_data_file(str(parameter.value)))
            except Exception as err:  # any failure to load refuses it
                reasons.append(str(err) or type(err).__name__)
        elif parameter.name == 'footprint':
            try:
                parse_footprint(str(parameter.value))
            except ValueError as err:
                reasons.append(str(err))
        elif parameter.name == 'analytic_path' and parameter.value:
            try:
                analytic_path(str(parameter.value))
            except ValueError as err:
                reasons.append(str(err))
    return reasons
