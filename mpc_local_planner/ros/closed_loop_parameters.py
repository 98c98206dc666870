# SPDX-License-Identifier: Apache-2.0
"""closed_loop's options, and the parameters each node of the run gets from them.

`LoopOptions` is what the command line says; `node_parameters` turns it into every node's
parameters (the robot said to every node, sensing, drift and the localizer stand-in, the
reality preset, ``--param`` overrides), `run_world` writes the world with the robot an option
gives, and `parse_parameter` reads ``--param NODE.NAME:=VALUE``. The module docstring of
ros/closed_loop.py says why each choice is made.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from mpc_local_planner.core.footprint import Footprint, parse_footprint
from mpc_local_planner.ros.parameters import (
    params_file_problem,
    params_file_sections,
    section_applies,
)
from mpc_local_planner.ros.unicycle_simulator_parameters import LOCALIZER_TOPIC
from mpc_local_planner.sim.localizer import LOCALIZER_NOISE, LOCALIZER_RATE
from mpc_local_planner.sim.reality import reality_preset
from mpc_local_planner.worlds.world import load_world, World

__all__ = ['DEFAULT_DRIFT', 'DEFAULT_WORLD', 'LoopOptions', 'MODULES',
           'PAPER_GOAL_TOLERANCES', 'POLYGON_CLEARANCE', 'footprint_parameter', 'localized',
           'file_parameters', 'node_parameters', 'parse_parameter', 'run_world']

# The world closed_loop runs unless --world says otherwise: the paper's scenario (the nodes
# themselves default to no world at all).
DEFAULT_WORLD = 'worlds/paper_obstacle.yaml'
# The planner's clearance (m) for a polygon robot (see the module docstring).
POLYGON_CLEARANCE = 0.05
# The controller's arrival on the paper's scenario (see the module docstring).
PAPER_GOAL_TOLERANCES = {'xy_goal_tolerance': 0.02, 'yaw_goal_tolerance': 0.05}
# --drift: the odometry's drift when the option comes without a rate. The localizer
# stand-in's rate and noise are sim/localizer.py's LOCALIZER_RATE and LOCALIZER_NOISE, which
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
    # the simulator's reality preset (sim/reality.py): how real the robot and laser are
    reality: str = 'ideal'
    # the simulator's plant: kinematic, or mujoco (sim/physics/: wheels, slip, wheel odometry)
    plant: str = 'kinematic'
    # the robot, instead of the world's: a polygon (Nav2's "[[x, y], ...]") or a circle
    footprint: str | None = None
    robot_radius: float | None = None
    # the simulator holds the clock for every node's step (ros/lockstep.py); rtf is unused
    lockstep: bool = False
    # a robot whose odometry is not exact is told its pose by the localizer stand-in; off,
    # its odometry is the pose the nodes have (BARN's robot: odometry and a laser)
    localizer: bool = True
    # the referee (the TRUE pose, as BARN judges): arrival within this of the goal ends the
    # run as reached, whatever the controller says; None: the controller's own verdict
    referee_radius: float | None = None
    # standing still (true speeds ~0) this long ends the run (the suites' stall rule)
    stall_seconds: float | None = None
    # the user's params files (ros__parameters YAML, sections matched to node names as rcl
    # does), applied over closed_loop's choices and under extra_parameters
    params_files: tuple[str, ...] = ()
    # node -> parameter -> value, applied last (over what closed_loop chooses)
    extra_parameters: dict[str, dict[str, Any]] = field(default_factory=dict)


def footprint_parameter(footprint: Footprint) -> str:
    """Return the footprint parameter for a robot: Nav2's "[[x, y], ...]", '' for a circle."""
    if footprint.is_circle:
        return ''
    return '[' + ', '.join(f'[{x!r}, {y!r}]' for x, y in footprint.vertices.tolist()) + ']'


def localized(options: LoopOptions) -> bool:
    """Whether the run's odometry is not the true pose.

    So with --drift, a non-ideal reality, or the mujoco plant (its odometry counts wheels).

    Raises:
        ValueError: for an unknown --reality (the message lists the presets).

    """
    return (bool(options.drift) or not reality_preset(options.reality).ideal_base
            or options.plant == 'mujoco')


def _controller_for(options: LoopOptions) -> dict[str, Any]:
    """Return the controller's arrival and braking settings for the simulated robot.

    A robot whose odometry is its exact pose arrives within the paper's tolerances
    (PAPER_GOAL_TOLERANCES). A localized one (--drift, or a real base) keeps the node's
    defaults, sized for a pose estimate that jumps by a centimetre or so at every localizer
    pose: within 0.02 m of such an estimate the MPC, whose plans must end exactly on the goal
    pose, re-plans a parking manoeuvre from each jump, back and forth, and the robot dithered
    40 s before an estimate came within 0.02 m (--drift). A real base also brakes within its
    deceleration limits, as a user configures a real robot (docs/real_robot.md).

    Raises:
        ValueError: for an unknown --reality.

    """
    if not localized(options):
        return dict(PAPER_GOAL_TOLERANCES)
    accel = reality_preset(options.reality).acceleration_limits
    return {'max_decel': [float(a) for a in accel]} if accel is not None else {}


def node_parameters(options: LoopOptions, world_file: Path, world: World, *,
                    map_file: Path | None = None) -> dict[str, dict[str, Any]]:
    """Return each node's parameter values for a run (use_sim_time included).

    The simulator always gets the true world (for the laser and the contacts). With
    options.sensing the planner and the controller get no world file: they see the map
    (map_file, which map_server serves) and the scans. The robot (world.footprint: pass the
    run's world, see run_world) reaches all three as ``footprint`` and ``robot_radius``, in
    every mode; for a polygon the planner's clearance is POLYGON_CLEARANCE; the controller
    arrives within PAPER_GOAL_TOLERANCES when its odometry is exact, with the node's defaults
    (and braking on a real base) when localized (_controller_for). options.extra_parameters
    come last.

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
            **robot,
        },
        'unicycle_simulator': {
            'publish_clock': True, 'real_time_factor': float(options.rtf),
            'initial_pose': [float(v) for v in world.start],
            'world_file': str(world_file), **robot,
            # exact odometry IS the pose in map: said so, nodes with tf2 look nothing up
            'odom_frame': 'map',
            'reality': options.reality,
            # the mujoco plant's robot: the Jackal for a polygon, else the small robot
            'plant': options.plant,
            'physics.robot': 'small' if world.footprint.is_circle else 'jackal',
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
    if localized(options) and options.localizer:
        # odometry that drifts or is noisy is not the pose in map: a localizer says where
        # the robot is, as on a real robot
        params['unicycle_simulator'].update({
            'odom_frame': 'odom', 'localizer.rate': LOCALIZER_RATE,
            'localizer.noise_std': LOCALIZER_NOISE})
        for name in ('global_planner', 'mpc_controller'):
            params[name]['localization_topic'] = LOCALIZER_TOPIC
    if options.lockstep:
        participants = [name for name in params if name != 'unicycle_simulator']
        for name in participants:
            params[name]['lockstep'] = True
        # the recorder too (closed_loop's own node): the bag misses nothing
        params['unicycle_simulator'].update({
            'lockstep': True, 'lockstep.participants': [*participants, 'bag_recorder']})
    # the controller's tuning for the simulated robot yields to the user's files; the run's
    # wiring (world, map, sources, robot, clock) does not
    tuning: dict[str, dict[str, Any]] = {'mpc_controller': _controller_for(options)}
    for path in options.params_files:
        for name in params:
            tuning.setdefault(name, {}).update(file_parameters(path, name))
    for name in params:
        params[name] = {**tuning.get(name, {}), **params[name]}
    for name, extra in options.extra_parameters.items():
        if name not in params:  # map_server: only with --sensing
            msg = f'parameters for {name}, which does not run here (map_server needs --sensing)'
            raise ValueError(msg)
        params[name].update(extra)
    return params


def file_parameters(path: str, node: str) -> dict[str, Any]:
    """Return the parameters a params file gives the node /node (its matching sections).

    Sections match as rcl matches them (``/**``, ``/*``, the node's name); nested mappings
    under ros__parameters are dotted names, as ROS reads them (``weights: {position: 1}``
    is ``weights.position``). Later sections of the file win, as in rcl.

    Raises:
        ValueError: if the file cannot be read as YAML (the reason, in one line).

    """
    problem = params_file_problem(path)
    if problem is not None:
        raise ValueError(problem)
    data = yaml.safe_load(Path(path).read_text(encoding='utf-8')) or {}
    values: dict[str, Any] = {}

    def flatten(mapping: dict[str, Any], prefix: str) -> None:
        for key, value in mapping.items():
            name = f'{prefix}.{key}' if prefix else str(key)
            if isinstance(value, dict):
                flatten(value, name)
            else:
                values[name] = value

    for section, parameters in params_file_sections(data):
        if isinstance(parameters, dict) and section_applies(section, '/' + node):
            flatten(parameters, '')
    return values


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
