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

"""closed_loop: planner, controller, simulator and recorder over DDS, to the goal.

By default the four nodes share one process and a SingleThreadedExecutor; with
``--separate-processes`` the planner, the controller and the simulator run as three OS
processes (``python -m mpc_local_planner.<module> --ros-args -p ...``, so no ros2cli is
needed) and this process records and watches. The simulator drives ``/clock`` at ``--rtf``
times real time and every node uses sim time. The run stops when the controller reports
the goal reached, at the world's (or ``--time-limit``) simulated time limit, or at the
``--timeout`` in wall seconds. Then the bag (which records the world in its metadata) is
analysed: ``--out`` receives ``bag/``, ``trajectory.csv``, ``metrics.json`` and
``trajectory.png``. Exit code 0 iff the target was reached without collision.

With ``--path rrt`` no plan may come: a start or goal inside the obstacles as the planner
inflates them (robot radius + clearance) is refused before anything starts, and a goal the
planner cannot reach (walled off) ends the run as soon as the planner says so on
``planner/diagnostics``. Either way the reason is one line on stderr and the exit code is 2,
as for an invalid option.

With ``--respawn`` (separate processes only) a node process that exits is started again, as
launch's ``respawn``, instead of ending the run: kill the controller mid-run and the
simulator stops the robot after ``cmd_timeout``, then the new controller gets ``/plan``
(transient_local) and drives on. A process that refuses its parameters (exit code 2) is not
started again, and at most MAX_RESPAWNS restarts happen per run.

The simulator always holds the TRUE world (the world file's known and unknown obstacles) and
counts contact episodes on ``simulator/contacts``; ``metrics.json`` reports ``contacts`` and a
run with a contact fails (exit code 1). With ``--sensing`` no node but the simulator reads the
world's obstacles: a ``map_server`` serves a map of the KNOWN obstacles (rasterised at
MAP_RESOLUTION into ``--out``/map/), the planner plans on that map and the scans
(``use_map``, ``use_scan``, ``world_file: ''``), the controller avoids what the map and the
laser show (``obstacle_sources: [map, scan]``), and the bag records ``scan`` too. The figure
draws unknown obstacles apart from known ones and, with ``--sensing``, what the controller
avoided (``mpc/obstacles``, namespace ``raw``) at a few instants.

Re-planning is the planner's own: with ``--sensing`` it checks the rest of its plan against
the map and the scans (``replan_check_rate``) and plans anew from the robot's pose when an
obstacle the map did not have blocks it. ``metrics.json`` reports the planner's count of
re-plans in ``replans``.

The robot is the world's (its ``footprint`` polygon, or its ``robot_radius`` circle), or the
one ``--footprint`` (Nav2's "[[x, y], ...]") or ``--robot-radius`` says. That one robot
reaches every node, with or without ``--sensing``: each of simulator, planner and controller
gets it as its ``footprint`` parameter (and ``robot_radius``), so that the simulator counts
contacts of the true shape, the planner plans for it and the MPC keeps it clear. An option
that changes the robot writes the run's world (the world file with that robot) to
``--out``/world/, which the nodes read and the bag records, so that ``analyze_bag`` later
measures the same robot; ``metrics.json`` says which footprint was used (``footprint``,
``footprint_source``), and the figure draws it at a few poses.

For a polygon the planner's clearance is POLYGON_CLEARANCE (0.05 m) instead of its default
(0.1 m): the planner checks the polygon at every pose of the path, turns included, so the
clearance is room for the MPC, not for the shape; 0.05 m exceeds the MPC's own motion
clearance on a straight segment at full speed (h v_max / 2 = 0.031 m), and leaves a 0.60 m
gap open to the 0.43 m wide Jackal (narrow_gap). ``--param global_planner.clearance:=X``
(any node's parameter, as ``-p`` would give it) overrides it.

With ``--drift [RATE]`` the simulated odometry drifts (the real case: ``odom`` is not
``map``): RATE (0.05 = 5 %, the default) of the distance travelled in position and RATE rad
per metre in heading; the simulator's localizer stand-in publishes the true pose with
LOCALIZER_NOISE noise at LOCALIZER_RATE Hz on ``amcl_pose``, and the planner and the
controller compose it with odometry (``localization_topic``). Contacts are the true pose's;
``metrics.json`` has the run's ``drift`` and, in one process, the simulator's true final
pose and its distance to the goal (``true_final_pose``, ``true_goal_error``), which must then
be within reality.true_goal_tolerance of the arrival tolerance for the run to succeed
(0.05 + POSE_ERROR = 0.1 m: what the drifted odometry, or the controller, believes is not
enough).

With ``--reality {ideal,mild,real,harsh}`` (default ideal) the simulator's robot and laser
are that preset of core/reality.py (the simulator's ``reality`` parameter: command latency,
actuator lag, acceleration limits, odometry noise and drift, laser noise, NaN/-inf beams,
lost scans), the same model the ROS-free rollout uses. A preset whose odometry is not exact
(all but ideal) is run as ``--drift`` is: odometry in ``odom``, the localizer stand-in on
``amcl_pose`` followed by the planner and the controller, and the true final pose within
true_goal_tolerance of the controller's arrival tolerance for success (the node's default
0.1 m: 0.15 m) (``--drift RATE`` then overrides the preset's drift).
``metrics.json`` records the preset in ``reality`` (and its values in ``reality_values``);
``--param unicycle_simulator.NAME:=VALUE`` overrides single fields (``scan.seed`` seeds it).

The controller arrives within PAPER_GOAL_TOLERANCES (the paper's scenario's 0.02 m and
0.05 rad, which the reported metrics were measured with) instead of the node's defaults, which
are for a real robot's noisy odometry: the simulated odometry is exact.
``--param mpc_controller.xy_goal_tolerance:=0.1`` runs with a real robot's tolerance.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import math
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import time
from typing import Any, Sequence

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import UInt32
from visualization_msgs.msg import Marker, MarkerArray
import yaml

from mpc_local_planner.core.controller import ControllerSettings
from mpc_local_planner.core.diagnostics import (
    CONTROLLER_DIAGNOSTICS_TOPIC,
    ControllerDiagnostics,
    PLANNER_DIAGNOSTICS_TOPIC,
    PlannerDiagnostics,
)
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.footprint import Footprint, parse_footprint, resolve
from mpc_local_planner.core.planner import PlannerConfig, RrtStarPlanner
from mpc_local_planner.core.reality import (
    LOCALIZER_NOISE,
    LOCALIZER_RATE,
    reality_preset,
    REALITY_PRESETS,
    true_goal_tolerance,
)
from mpc_local_planner.evaluation.analyze_bag import analyze, read_run, summary
from mpc_local_planner.evaluation.plotting import plot_runs
from mpc_local_planner.ros.bag_recorder_node import (
    BagRecorderNode,
    DEFAULT_LATCHED,
    DEFAULT_TOPICS,
    DEFAULT_TYPES,
)
from mpc_local_planner.ros.executors import spin_until
from mpc_local_planner.ros.node_main import autostart, EXIT_INVALID_PARAMETERS
from mpc_local_planner.ros.parameters import DEFAULT_WORLD_FILE
from mpc_local_planner.ros.qos import (
    CONTACTS_QOS,
    DIAGNOSTICS_QOS,
    LOCAL_PLAN_QOS,
    PLANNER_DIAGNOSTICS_QOS,
)
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.map_files import rasterize_world, save_map
from mpc_local_planner.worlds.world import load_world, World

__all__ = ['EXIT_NO_PLAN', 'LoopOptions', 'LoopResult', 'MAP_RESOLUTION',
           'PAPER_GOAL_TOLERANCES', 'POLYGON_CLEARANCE', 'check_plannable', 'flush_recording',
           'footprint_parameter', 'main', 'node_command', 'node_parameters', 'parse_parameter',
           'recorder_topics', 'run_closed_loop', 'run_world', 'spawn_node', 'write_known_map']

DEFAULT_WORLD = DEFAULT_WORLD_FILE
# Exit code when no plan can come (as for invalid options: the run was misconfigured).
EXIT_NO_PLAN = 2
# Wall seconds the recorder gets, after the run stops, to write what the monitor has seen.
FLUSH_TIMEOUT = 5.0
# Simulated seconds allowed when the world sets no time_limit.
DEFAULT_TIME_LIMIT = 60.0
# Wall seconds a child process gets to exit after SIGINT before it is killed.
CHILD_EXIT_TIMEOUT = 5.0
# Restarts of node processes per run with --respawn (a crash loop ends the run instead).
MAX_RESPAWNS = 10
# Cell side (m) of the map of the known obstacles that --sensing serves.
MAP_RESOLUTION = 0.05
# Topics the simulator publishes (unicycle_simulator_node's names; not imported, so that
# this module does not load the nodes before they are needed).
SCAN_TOPIC = 'scan'
CONTACTS_TOPIC = 'simulator/contacts'
LOCALIZER_TOPIC = 'amcl_pose'
# What the controller avoids (mpc_controller_node's OBSTACLES_TOPIC) and the namespace of
# the obstacles as it takes them in (from the map and the scans with --sensing).
OBSTACLES_TOPIC = 'mpc/obstacles'
RAW_NAMESPACE = 'raw'
# With --sensing, the monitor keeps what the controller avoids at most once per this many
# simulated seconds; the figure shows SENSED_SNAPSHOTS of them, spread over the run.
SNAPSHOT_PERIOD = 2.0
SENSED_SNAPSHOTS = 4
# The planner's clearance (m) for a polygon robot (see the module docstring).
POLYGON_CLEARANCE = 0.05
# The controller's arrival on the paper's scenario (see the module docstring).
PAPER_GOAL_TOLERANCES = {'xy_goal_tolerance': 0.02, 'yaw_goal_tolerance': 0.05}
# --drift: the odometry's drift when the option comes without a rate. The localizer
# stand-in's rate and noise are core/reality.py's LOCALIZER_RATE and LOCALIZER_NOISE, which
# the suites' rollout uses too.
DEFAULT_DRIFT = 0.05

MODULES = {
    'map_server': 'mpc_local_planner.ros.map_server_node',
    'global_planner': 'mpc_local_planner.ros.global_planner_node',
    'mpc_controller': 'mpc_local_planner.ros.mpc_controller_node',
    'unicycle_simulator': 'mpc_local_planner.ros.unicycle_simulator_node',
}


@dataclass
class LoopOptions:
    """What to run (the command-line options)."""

    world: str = DEFAULT_WORLD
    out: str = 'out/closed_loop'
    path: str = 'analytic'
    rtf: float = 4.0
    timeout: float = 120.0
    time_limit: float | None = None
    separate_processes: bool = False
    respawn: bool = False
    seed: int = 0
    sensing: bool = False
    # odometry drift (fraction of the distance, and rad/m), with the localizer; 0 = exact
    drift: float = 0.0
    # the simulator's reality preset (core/reality.py): how real the robot and laser are
    reality: str = 'ideal'
    # the robot, instead of the world's: a polygon (Nav2's "[[x, y], ...]") or a circle
    footprint: str | None = None
    robot_radius: float | None = None
    # node -> parameter -> value, applied last (over what closed_loop chooses)
    extra_parameters: dict[str, dict[str, Any]] = field(default_factory=dict)


@dataclass
class LoopResult:
    """How the run ended and what it produced."""

    metrics: dict[str, Any]
    stop_reason: str
    wall_time: float
    sim_time: float
    out: Path
    success: bool


def footprint_parameter(footprint: Footprint) -> str:
    """Return the footprint parameter for a robot: Nav2's "[[x, y], ...]", '' for a circle."""
    if footprint.is_circle:
        return ''
    return '[' + ', '.join(f'[{x!r}, {y!r}]' for x, y in footprint.vertices.tolist()) + ']'


def localized(options: LoopOptions) -> bool:
    """Whether the run's odometry is not the true pose (--drift, or a non-ideal reality).

    Raises:
        ValueError: for an unknown --reality (the message lists the presets).

    """
    return bool(options.drift) or not reality_preset(options.reality).ideal_base


def _controller_for_reality(reality: str) -> dict[str, Any]:
    """Return the controller's arrival and braking settings for the simulated robot.

    The ideal robot arrives within the paper's tolerances (PAPER_GOAL_TOLERANCES: its
    odometry is exact). A real one keeps the node's defaults, sized for noisy odometry and a
    lagging base, and brakes within the base's deceleration limits, as a user configures a
    real robot (docs/real_robot.md).
    """
    if reality == 'ideal':
        return dict(PAPER_GOAL_TOLERANCES)
    accel = reality_preset(reality).acceleration_limits
    return {'max_decel': [float(a) for a in accel]} if accel is not None else {}


def node_parameters(options: LoopOptions, world_file: Path, world: World, *,
                    map_file: Path | None = None) -> dict[str, dict[str, Any]]:
    """Return each node's parameter values for a run (use_sim_time included).

    The simulator always gets the true world (for the laser and the contacts). With
    options.sensing the planner and the controller get no world file: they see the map
    (map_file, which map_server serves) and the scans. The robot (world.footprint: pass the
    run's world, see run_world) reaches all three as ``footprint`` and ``robot_radius``, in
    every mode; for a polygon the planner's clearance is POLYGON_CLEARANCE; the controller
    arrives within PAPER_GOAL_TOLERANCES on an ideal robot, with the node's defaults and
    braking on a real one (_controller_for_reality). options.extra_parameters come last.

    Raises:
        ValueError: if --path analytic names no path of the world, sensing lacks map_file,
            extra parameters name a node that does not run, or the reality is unknown.

    """
    analytic = world.path if options.path == 'analytic' else ''
    if options.path == 'analytic' and not world.path:
        msg = f'--path analytic: the world {world.name} names no analytic path (use --path rrt)'
        raise ValueError(msg)
    # the robot, said to every node: the simulator counts its contacts, the planner plans
    # for it and the MPC keeps it clear; never left to each node's reading of the world
    robot = {'footprint': footprint_parameter(world.footprint),
             'robot_radius': float(world.robot_radius)}
    params: dict[str, dict[str, Any]] = {
        'global_planner': {
            'use_sim_time': True, 'world_file': str(world_file),
            'goal': [float(v) for v in world.goal], 'seed': int(options.seed),
            'analytic_path': analytic, **robot,
        },
        'mpc_controller': {
            'use_sim_time': True, 'world_file': str(world_file), 'analytic_path': analytic,
            **_controller_for_reality(options.reality), **robot,
        },
        'unicycle_simulator': {
            'publish_clock': True, 'real_time_factor': float(options.rtf),
            'initial_pose': [float(v) for v in world.start],
            'world_file': str(world_file), **robot,
            # exact odometry IS the pose in map: said so, nodes with tf2 look nothing up
            'frame_id': 'map',
            'reality': options.reality,
        },
    }
    if not world.footprint.is_circle:
        params['global_planner']['clearance'] = POLYGON_CLEARANCE
    if options.sensing:
        if map_file is None:
            msg = '--sensing needs the map of the known obstacles (map_file)'
            raise ValueError(msg)
        params['map_server'] = {'use_sim_time': True, 'yaml_filename': str(map_file)}
        params['global_planner'].update(use_map=True, use_scan=True, world_file='')
        params['mpc_controller'].update(obstacle_sources=['map', 'scan'], world_file='')
    if options.drift:
        params['unicycle_simulator'].update({
            'odom_drift.position': float(options.drift), 'odom_drift.heading': float(
                options.drift)})
    if localized(options):
        # odometry that drifts or is noisy is not the pose in map: a localizer says where
        # the robot is, as on a real robot
        params['unicycle_simulator'].update({
            'frame_id': 'odom', 'localizer.rate': LOCALIZER_RATE,
            'localizer.noise_std': LOCALIZER_NOISE})
        for name in ('global_planner', 'mpc_controller'):
            params[name]['localization_topic'] = LOCALIZER_TOPIC
    for name, extra in options.extra_parameters.items():
        if name not in params:  # map_server: only with --sensing
            msg = f'parameters for {name}, which does not run here (map_server needs --sensing)'
            raise ValueError(msg)
        params[name].update(extra)
    return params


def run_world(options: LoopOptions, world_file: Path, world: World,
              folder: Path) -> tuple[Path, World, str]:
    """Return the run's world file, its world and where its robot comes from.

    Without --footprint or --robot-radius: the world file itself ('the world'). With one:
    the world file with its robot replaced, written to folder/<world name>.yaml, so that
    every node reads the same robot and the bag records it (the name stays the world's).

    Raises:
        ValueError: both options given, an invalid footprint or radius, or a BARN JSON world
            (its format holds no robot).

    """
    if options.footprint is None and options.robot_radius is None:
        return world_file, world, 'the world'
    if options.footprint is not None and options.robot_radius is not None:
        msg = 'give either --footprint (a polygon) or --robot-radius (a circle), not both'
        raise ValueError(msg)
    if options.footprint is not None:
        robot = parse_footprint(options.footprint)
        if robot.is_circle:
            msg = (f'--footprint {options.footprint!r}: give a polygon "[[x, y], ...]" (a '
                   'round robot: --robot-radius)')
            raise ValueError(msg)
        source, key, value = '--footprint', 'footprint', robot.vertices.tolist()
    else:
        robot = Footprint.circle(float(options.robot_radius))
        source, key, value = '--robot-radius', 'robot_radius', robot.radius
    if world_file.suffix.lower() not in ('.yaml', '.yml'):
        msg = (f'{source}: {world_file.name} is not a YAML world (a BARN world holds no '
               'robot); write one with the robot instead')
        raise ValueError(msg)
    data = yaml.safe_load(world_file.read_text(encoding='utf-8'))
    data = {k: v for k, v in data.items() if k not in ('footprint', 'robot_radius')}
    data[key] = value
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f'{world.name}.yaml'
    path.write_text(f'# closed_loop: {world_file} with the robot of {source}\n'
                    + yaml.safe_dump(data, sort_keys=False, default_flow_style=None),
                    encoding='utf-8')
    return path, load_world(path), source


def _ros_arg(name: str, value: Any) -> str:
    if isinstance(value, bool):
        text = 'true' if value else 'false'
    elif isinstance(value, (list, tuple)):
        text = '[' + ','.join(repr(float(v)) if isinstance(v, float) else str(v)
                              for v in value) + ']'
    elif isinstance(value, float):
        text = repr(value)
    elif isinstance(value, str):
        # ROS reads a -p value as YAML: quote a string that would read as something else
        # ('' as nothing, a footprint "[[x, y], ...]" as a nested list)
        try:
            plain = yaml.safe_load(value) == value
        except yaml.YAMLError:
            plain = False
        text = value if plain else "'" + value.replace("'", "''") + "'"
    else:
        text = str(value)
    return f'{name}:={text}'


def write_known_map(world: World, folder: Path) -> Path:
    """Rasterise the world's KNOWN obstacles at MAP_RESOLUTION into folder; return the YAML."""
    return save_map(rasterize_world(world, MAP_RESOLUTION), folder, world.name)


def recorder_topics(*, sensing: bool) -> dict[str, list[str]]:
    """Return the recorder's topics, types and latched topics (scan too with sensing)."""
    topics = [*DEFAULT_TOPICS, CONTACTS_TOPIC]
    types = [*DEFAULT_TYPES, 'std_msgs/msg/UInt32']
    if sensing:
        topics.append(SCAN_TOPIC)
        types.append('sensor_msgs/msg/LaserScan')
    return {'topics': topics, 'types': types,
            'transient_local_topics': [*DEFAULT_LATCHED, CONTACTS_TOPIC]}


def _raw_polygons(msg: MarkerArray) -> list[np.ndarray]:
    """Return the (K, 2) outlines of the markers in the raw namespace (closed rings opened)."""
    polygons = []
    for marker in msg.markers:
        if marker.ns != RAW_NAMESPACE or marker.action != Marker.ADD or len(marker.points) < 2:
            continue
        ring = np.array([(p.x, p.y) for p in marker.points], dtype=float)
        if len(ring) > 2 and np.allclose(ring[0], ring[-1]):
            ring = ring[:-1]
        polygons.append(ring)
    return polygons


class _Monitor(Node):
    """Watch the controller's diagnostics for the goal and the planner's for a failure.

    Also counts the simulator's contacts and, with sensing, keeps what the controller
    avoids (its raw obstacles) at a few instants for the figure.
    """

    def __init__(self, *, sensing: bool = False, **kwargs: Any) -> None:
        super().__init__('closed_loop_monitor', **kwargs)
        self.goal_reached = False
        self.replans = 0  # the planner's count of re-plans, as it last reported it
        self.contacts: int | None = None  # the simulator's count, once heard
        # (simulated time, raw obstacle outlines) every SNAPSHOT_PERIOD at most
        self.sensed: list[tuple[float, list[np.ndarray]]] = []
        self.messages = 0  # diagnostics messages of the controller received
        self.last_reason = ''
        self.plan_failure: str | None = None  # why the planner published no plan
        self._sub = self.create_subscription(DiagnosticArray, CONTROLLER_DIAGNOSTICS_TOPIC,
                                             self.diagnostics_callback, DIAGNOSTICS_QOS)
        self._planner_sub = self.create_subscription(
            DiagnosticArray, PLANNER_DIAGNOSTICS_TOPIC, self.planner_callback,
            PLANNER_DIAGNOSTICS_QOS)
        self._contacts_sub = self.create_subscription(UInt32, CONTACTS_TOPIC,
                                                      self.contacts_callback, CONTACTS_QOS)
        self._obstacles_sub = None
        if sensing:
            self._obstacles_sub = self.create_subscription(
                MarkerArray, OBSTACLES_TOPIC, self.obstacles_callback, LOCAL_PLAN_QOS)

    def contacts_callback(self, msg: UInt32) -> None:
        """Keep the simulator's contact count (it only grows)."""
        self.contacts = max(int(msg.data), self.contacts or 0)

    def obstacles_callback(self, msg: MarkerArray) -> None:
        """Keep what the controller avoids, once per SNAPSHOT_PERIOD of simulated time."""
        now = self.sim_time()
        if self.sensed and now < self.sensed[-1][0] + SNAPSHOT_PERIOD:
            return
        polygons = _raw_polygons(msg)
        if polygons:
            self.sensed.append((now, polygons))

    @property
    def diagnostics_topic(self) -> str:
        """The controller's diagnostics topic, resolved."""
        return self._sub.topic_name

    def diagnostics_callback(self, msg: DiagnosticArray) -> None:
        """Note each control step and whether the controller is at the goal."""
        self.messages += 1
        for status in msg.status:
            step = ControllerDiagnostics.from_values((kv.key, kv.value) for kv in status.values)
            self.last_reason = step.message
            self.goal_reached = step.goal_reached

    def planner_callback(self, msg: DiagnosticArray) -> None:
        """Note whether the planner's latest goal failed (a later plan clears it)."""
        for status in msg.status:
            outcome = PlannerDiagnostics.from_values((kv.key, kv.value) for kv in status.values)
            self.replans = max(self.replans, outcome.replans)
            if outcome.waiting:
                continue  # waiting for the map: the plan is still to come
            self.plan_failure = (outcome.detail or 'no plan') if outcome.failed else None

    def sim_time(self) -> float:
        """Return the current ROS (simulated) time in seconds."""
        return self.get_clock().now().nanoseconds * 1e-9


def flush_recording(executor: Executor, recorder: BagRecorderNode, monitor: _Monitor, *,
                    timeout_sec: float = FLUSH_TIMEOUT) -> bool:
    """Spin until the recorder holds every controller diagnostics message the monitor saw.

    The run stops on the message that says the goal is reached; without this the executor
    may never run the recorder's callback for it, and the bag (so metrics.json's
    controller_goal_reached) would miss the arrival.

    Returns:
        True if the recorder caught up within timeout_sec.

    """
    return spin_until(
        executor, lambda: recorder.counts.get(monitor.diagnostics_topic, 0) >= monitor.messages,
        timeout_sec=timeout_sec)


def check_plannable(world: World, planner_parameters: dict[str, Any]) -> None:
    """Refuse a start or goal that no plan can reach: inside an obstacle as the planner grows it.

    For a round robot the planner grows every obstacle by robot_radius (the larger of its
    parameter and the world's) plus clearance; for a polygon (the footprint parameter's,
    else the world's) it checks the polygon at the pose's heading grown by the clearance, as
    the global_planner node will with these parameters.

    Raises:
        PlanningError: saying which pose is in which inflated obstacle (or out of bounds).

    """
    defaults = PlannerConfig()
    radius = max(float(planner_parameters.get('robot_radius', defaults.robot_radius)),
                 world.robot_radius)
    clearance = float(planner_parameters.get('clearance', defaults.clearance))
    footprint = resolve(str(planner_parameters.get('footprint', '')),
                        world_footprint=world.footprint)
    polygon = () if footprint.is_circle else tuple(map(tuple, footprint.vertices.tolist()))
    planner = RrtStarPlanner(world.obstacles, world.bounds,
                             config=PlannerConfig(robot_radius=radius, clearance=clearance,
                                                  footprint=polygon))
    for label, pose in (('start', world.start), ('goal', world.goal)):
        try:
            planner.check_endpoint(pose, label)
        except PlanningError as err:
            msg = f'{world.name}: no plan can come: {err}'
            raise PlanningError(msg) from None


def run_closed_loop(options: LoopOptions, *, ros_args: Sequence[str] = ()) -> LoopResult:
    """Run the loop to the goal or a limit, then analyse its bag.

    Raises:
        FileNotFoundError: if the world file does not exist.
        ValueError: on an invalid option (e.g. --path analytic on a world without one).
        PlanningError: with --path rrt, if no plan can come (a start or goal inside an
            inflated obstacle, found before anything starts) or the planner says it found
            none (the run ends at once; the bag is kept, not analysed).

    """
    source_file = resolve_data_file(options.world)
    world = load_world(source_file)
    if not options.rtf > 0:
        msg = f'--rtf must be > 0, got {options.rtf}'
        raise ValueError(msg)
    if options.respawn and not options.separate_processes:
        msg = '--respawn needs --separate-processes'
        raise ValueError(msg)
    world_file, world, robot_source = run_world(options, source_file, world,
                                                Path(options.out) / 'world')
    params = node_parameters(options, world_file, world,
                             map_file=Path(options.out) / 'map' / f'{world.name}.yaml')
    if options.path == 'rrt':
        check_plannable(world, params['global_planner'])
    time_limit = options.time_limit or world.time_limit or DEFAULT_TIME_LIMIT
    out = Path(options.out)
    out.mkdir(parents=True, exist_ok=True)
    if options.sensing:
        params['map_server']['yaml_filename'] = str(write_known_map(world, out / 'map'))
    bag = out / 'bag'
    if bag.exists():
        shutil.rmtree(bag)

    context = Context()
    rclpy.init(args=['--ros-args', *ros_args] if ros_args else None, context=context)
    nodes: list[Node] = []
    children: dict[str, subprocess.Popen] = {}
    respawns: list[dict[str, Any]] = []
    # one thread: with rclpy 7.1 a MultiThreadedExecutor spun with spin_once piles up
    # pending callback futures faster than 2 cores drain them, and the loop collapses
    # (seen at rtf 4: 7 control steps in 40 s wall); the simulator advances simulated
    # time per tick, so a solve that blocks the thread only slows the loop, never skews it
    executor = SingleThreadedExecutor(context=context)
    start = time.monotonic()
    stop_reason = 'timeout'
    plan_failure: str | None = None
    sim_time = math.nan
    try:
        sim = [Parameter('use_sim_time', value=True)]
        recorder = BagRecorderNode(context=context, parameter_overrides=[
            *sim, Parameter('output', value=str(bag)),
            Parameter('world_file', value=str(world_file)),
            *(Parameter(k, value=v)
              for k, v in recorder_topics(sensing=options.sensing).items())])
        monitor = _Monitor(context=context, parameter_overrides=sim, sensing=options.sensing)
        nodes += [recorder, monitor]
        if options.separate_processes:
            children = _spawn(params, out / 'logs')
        else:
            nodes += _create_nodes(params, context)
        for node in nodes:
            executor.add_node(node)
        deadline = start + options.timeout
        while True:
            executor.spin_once(timeout_sec=0.05)
            sim_time = monitor.sim_time()
            if monitor.goal_reached:
                stop_reason = 'goal reached'
                break
            if monitor.plan_failure is not None:
                plan_failure = monitor.plan_failure
                stop_reason = f'no plan: {plan_failure}'
                break
            if sim_time > time_limit:
                stop_reason = f'simulated time limit ({time_limit:g} s)'
                break
            if time.monotonic() > deadline:
                stop_reason = f'wall-clock timeout ({options.timeout:g} s)'
                break
            dead = [name for name, c in children.items() if c.poll() is not None]
            if dead and not _respawn(options, dead, children, params, out / 'logs', respawns,
                                     sim_time):
                name = dead[0]
                stop_reason = f'{name} exited (code {children[name].returncode})'
                break
        flush_recording(executor, recorder, monitor)
        from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode
        truth = [n.state for n in nodes if isinstance(n, UnicycleSimulatorNode)]
    finally:
        wall_time = time.monotonic() - start
        _stop_children(list(children.values()))
        executor.shutdown()
        for node in reversed(nodes):
            node.destroy_node()
        rclpy.try_shutdown(context=context)

    if plan_failure is not None:
        msg = f'{world.name}: no plan came: {plan_failure}'
        raise PlanningError(msg)
    run_info = {'stop_reason': stop_reason, 'wall_time': wall_time, 'sim_time': sim_time,
                'separate_processes': options.separate_processes, 'rtf': options.rtf,
                'respawns': respawns, 'sensing': options.sensing,
                'contacts': monitor.contacts, 'replans': monitor.replans,
                'path_source': options.path, 'world': str(source_file),
                'world_file': str(world_file), 'footprint_source': robot_source,
                'drift': options.drift, 'reality': options.reality,
                'reality_values': _run_reality(params)}
    if truth:  # one process: the simulator's true pose, whatever odometry said
        run_info['true_final_pose'] = [float(v) for v in truth[0]]
        run_info['true_goal_error'] = float(np.hypot(*(truth[0][:2] - world.goal[:2])))
    shape = '' if world.footprint.is_circle else ', polygon footprint'
    title = (f'{world.name}: {options.path} path, rtf {options.rtf:g}'
             + (', sensing' if options.sensing else '') + shape)
    real = not reality_preset(options.reality).ideal
    tolerances = (ControllerSettings().xy_goal_tolerance, ControllerSettings().yaw_goal_tolerance
                  ) if real else (0.05, 0.1)
    metrics = analyze(bag, out, extra=run_info, title=title,
                      position_tolerance=tolerances[0], heading_tolerance=tolerances[1])
    if options.sensing or world.unknown_obstacles:
        _plot_sensing(bag, out / 'trajectory.png', world, monitor.sensed, title)
    success = (bool(metrics.get('reached')) and not metrics.get('collision')
               and not monitor.contacts)
    if localized(options) and truth:
        # arrival is declared on the estimate: the truth within it plus its error
        success = success and run_info['true_goal_error'] <= true_goal_tolerance(tolerances[0])
    return LoopResult(metrics=metrics, stop_reason=stop_reason, wall_time=wall_time,
                      sim_time=sim_time, out=out, success=success)


def _run_reality(params: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Return the simulator's reality as the run set it: the preset with its overrides.

    An infinite value (no acceleration limit) is None: metrics.json stays standard JSON.
    """
    from mpc_local_planner.ros.unicycle_simulator_node import reality_from_parameters

    def finite(value: Any) -> Any:
        if isinstance(value, list):
            return [finite(v) for v in value]
        return None if isinstance(value, float) and not math.isfinite(value) else value

    values = reality_from_parameters(params['unicycle_simulator']).as_dict()
    return {name: finite(value) for name, value in values.items()}


def _plot_sensing(bag: Path, png: Path, world: World,
                  sensed: Sequence[tuple[float, list[np.ndarray]]], title: str) -> None:
    """Redraw the run's figure with the unknown obstacles and a few sensed snapshots."""
    run = read_run(bag)
    step = max(1, len(run.predictions) // 8)
    picks = sorted({int(round(i)) for i in np.linspace(0, len(sensed) - 1,
                                                        min(SENSED_SNAPSHOTS, len(sensed)))})
    plot_runs(png, world=world, reference=run.plan, runs=[('mpc_controller', run.rows)],
              predictions=run.predictions[::step], title=title, show_unknown=True,
              sensed=[sensed[i] for i in picks] if sensed else (), footprint=world.footprint)


def _create_nodes(params: dict[str, dict[str, Any]], context: Context) -> list[Node]:
    """Create (map server,) planner, controller and simulator; autostart the lifecycle ones.

    Raises:
        ValueError: if a node refuses its parameters, or a lifecycle node does not configure
            or activate (the nodes created so far are destroyed).

    """
    from mpc_local_planner.ros.global_planner_node import GlobalPlannerNode
    from mpc_local_planner.ros.map_server_node import MapServerNode
    from mpc_local_planner.ros.mpc_controller_node import MpcControllerNode
    from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode

    # the simulator last: the clock starts once everyone listens
    classes = (('map_server', MapServerNode), ('global_planner', GlobalPlannerNode),
               ('mpc_controller', MpcControllerNode),
               ('unicycle_simulator', UnicycleSimulatorNode))
    nodes: list[Node] = []
    for name, node_class in classes:
        if name not in params:  # map_server: only with --sensing
            continue
        overrides = [Parameter(k, value=v) for k, v in params[name].items()]
        try:
            node = node_class(context=context, parameter_overrides=overrides)
        except (ParameterException, ValueError, TypeError, OSError) as err:
            node, problem = None, f'refusing to start: {err}'
        else:
            nodes.append(node)
            # as run_node does: configured and activated unless autostart is false
            problem = autostart(node) if isinstance(node, LifecycleNode) else None
        if problem is not None:
            for created in reversed(nodes):
                created.destroy_node()
            msg = f'{name}: {problem}'
            raise ValueError(msg)
    return nodes


def node_command(name: str, parameters: dict[str, Any]) -> list[str]:
    """Return the command that runs node name (a key of MODULES) with parameters.

    ``python -m <module> --ros-args -p key:=value ...``: no ros2cli or colcon install needed.
    """
    command = [sys.executable, '-m', MODULES[name], '--ros-args']
    for key, value in parameters.items():
        command += ['-p', _ros_arg(key, value)]
    return command


def spawn_node(name: str, parameters: dict[str, Any], log: Path, *,
               append: bool = False) -> subprocess.Popen:
    """Start node name as a process; stdout and stderr go to log."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, 'a' if append else 'w', encoding='utf-8') as stream:
        if append:
            stream.write(f'--- {name} started again ---\n')
            stream.flush()
        # the child holds its own descriptor once started
        return subprocess.Popen(node_command(name, parameters), stdout=stream,
                                stderr=subprocess.STDOUT, env=dict(os.environ))


def _spawn(params: dict[str, dict[str, Any]], logs: Path) -> dict[str, subprocess.Popen]:
    return {name: spawn_node(name, params[name], logs / f'{name}.log')
            for name in MODULES if name in params}


def _respawn(options: LoopOptions, dead: list[str], children: dict[str, subprocess.Popen],
             params: dict[str, dict[str, Any]], logs: Path, respawns: list[dict[str, Any]],
             sim_time: float) -> bool:
    """Start the dead node processes again if --respawn allows; return False to end the run."""
    if not options.respawn:
        return False
    for name in dead:
        code = children[name].returncode
        if code == EXIT_INVALID_PARAMETERS or len(respawns) >= MAX_RESPAWNS:
            return False
        respawns.append({'node': name, 'exit_code': code, 'sim_time': sim_time})
        print(f'closed_loop: {name} exited (code {code}) at {sim_time:.1f} s simulated; '
              'starting it again', file=sys.stderr, flush=True)
        children[name] = spawn_node(name, params[name], logs / f'{name}.log', append=True)
    return True


def _stop_children(children: list[subprocess.Popen]) -> None:
    for child in children:
        if child.poll() is None:
            child.send_signal(signal.SIGINT)
    deadline = time.monotonic() + CHILD_EXIT_TIMEOUT
    for child in children:
        try:
            child.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()


def parse_parameter(text: str) -> tuple[str, str, Any]:
    """Return (node, name, value) of ``NODE.NAME:=VALUE`` (the value read as YAML, as -p does).

    Raises:
        ValueError: text is not of that form, or NODE is none of closed_loop's nodes.

    """
    key, sep, value = text.partition(':=')
    node, dot, name = key.partition('.')
    if not sep or not dot or not name:
        msg = f'--param {text!r}: expected NODE.NAME:=VALUE, e.g. global_planner.clearance:=0.05'
        raise ValueError(msg)
    if node not in MODULES:
        msg = f'--param {text!r}: unknown node {node!r}, expected one of {sorted(MODULES)}'
        raise ValueError(msg)
    try:
        parsed = yaml.safe_load(value) if value else ''
    except yaml.YAMLError:
        parsed = value
    return node, name, '' if parsed is None else parsed


def main(argv: Sequence[str] | None = None) -> int:
    """Run the closed loop from the command line; exit 0 iff the target was reached safely."""
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args: list[str] = []
    if '--ros-args' in argv:
        index = argv.index('--ros-args')
        argv, ros_args = argv[:index], argv[index + 1:]
    parser = argparse.ArgumentParser(prog='closed_loop', description=__doc__.splitlines()[0])
    defaults = LoopOptions()
    parser.add_argument('--world', default=defaults.world,
                        help="world file (a path, or a name in config/worlds/ with or without "
                             "'.yaml')")
    parser.add_argument('--out', default=defaults.out, help='output directory')
    parser.add_argument('--path', choices=('rrt', 'analytic'), default=defaults.path,
                        help="reference: the world's analytic path or an RRT* plan")
    parser.add_argument('--rtf', type=float, default=defaults.rtf,
                        help='real-time factor of the simulated clock')
    parser.add_argument('--timeout', type=float, default=defaults.timeout,
                        help='wall-clock limit (s)')
    parser.add_argument('--time-limit', type=float, default=None,
                        help="simulated-time limit (s; default: the world's, else "
                             f'{DEFAULT_TIME_LIMIT:g})')
    parser.add_argument('--seed', type=int, default=defaults.seed, help='RRT* seed')
    parser.add_argument('--separate-processes', action='store_true',
                        help='run planner, controller and simulator as separate processes')
    parser.add_argument('--sensing', action='store_true',
                        help='the planner and the controller know only a map of the known '
                             "obstacles and the simulator's laser scans; unknown obstacles "
                             'are found by the laser')
    parser.add_argument('--drift', type=float, nargs='?', const=DEFAULT_DRIFT, default=0.0,
                        metavar='RATE',
                        help='the odometry drifts by RATE of the distance travelled (and '
                             'RATE rad/m in heading; default 5 %%), and the nodes follow a '
                             'localizer stand-in on amcl_pose')
    parser.add_argument('--reality', choices=tuple(REALITY_PRESETS), default=defaults.reality,
                        help="how real the simulator's robot and laser are (core/reality.py): "
                             'ideal (exact), mild, real or harsh (latency, lag, acceleration '
                             'limits, odometry noise and drift, laser noise, NaN/-inf beams, '
                             'lost scans); a non-ideal one runs with the localizer, as --drift')
    parser.add_argument('--respawn', action='store_true',
                        help='with --separate-processes: start a node process that exits '
                             'again instead of ending the run (a restart drill)')
    robot = parser.add_mutually_exclusive_group()
    robot.add_argument('--footprint', default=None,
                       help="the robot's convex polygon instead of the world's, Nav2's form "
                            "'[[x, y], ...]' (robot frame, x forward), for every node")
    robot.add_argument('--robot-radius', type=float, default=None,
                       help="a round robot of this radius (m) instead of the world's, for "
                            'every node')
    parser.add_argument('--param', action='append', default=[], metavar='NODE.NAME:=VALUE',
                        help="a node's parameter, applied last (repeatable), e.g. "
                             f'global_planner.clearance:=0.05; NODE is one of {sorted(MODULES)}')
    args = parser.parse_args(argv)
    try:
        extra: dict[str, dict[str, Any]] = {}
        for text in args.param:
            node, name, value = parse_parameter(text)
            extra.setdefault(node, {})[name] = value
        options = LoopOptions(world=args.world, out=args.out, path=args.path, rtf=args.rtf,
                              timeout=args.timeout, time_limit=args.time_limit,
                              seed=args.seed, separate_processes=args.separate_processes,
                              respawn=args.respawn, sensing=args.sensing, drift=args.drift,
                              reality=args.reality,
                              footprint=args.footprint, robot_radius=args.robot_radius,
                              extra_parameters=extra)
        result = run_closed_loop(options, ros_args=ros_args)
    except PlanningError as err:
        print(f'closed_loop: {err}', file=sys.stderr, flush=True)
        return EXIT_NO_PLAN
    except (FileNotFoundError, ValueError) as err:
        print(f'closed_loop: {err}', file=sys.stderr, flush=True)
        return 2
    print(f'stopped: {result.stop_reason} after {result.wall_time:.1f} s wall, '
          f'{result.sim_time:.1f} s simulated')
    print(summary(result.metrics))
    print(f'contacts: {result.metrics.get("contacts")}')
    print(f'outputs in {result.out.resolve()}: bag/, trajectory.csv, metrics.json, '
          'trajectory.png' + (', map/' if options.sensing else ''))
    return 0 if result.success else 1


if __name__ == '__main__':
    sys.exit(main())
