# SPDX-License-Identifier: Apache-2.0
"""Simulate the robot and drive it with the paper's MPC (``ros2 launch ... simulation.launch.py``).

Starts the unicycle simulator (it drives ``/clock``), the map server, the global planner and
the MPC controller, all on simulated time, and the bag recorder with ``record:=true``. The
world (``world:=NAME`` or a path) gives the simulator's start pose and the planner's goal; the
map server serves ``map:=FILE``, by default the world's map ``maps/<world name>.yaml`` (its
known obstacles, made by ``world_to_map``), and is left out if the world has none. Each
node's parameters come from its YAML under ``share/mpc_local_planner/config`` unless a
``*_params`` argument names another file.

The simulator always holds the true world (known and unknown obstacles: its laser on
``scan`` and its contact count on ``simulator/contacts``). With ``sensing:=true`` no other
node reads the world's obstacles: the planner plans on the map and the scans (``use_map``,
``use_scan``, no ``world_file``) and the controller avoids what the map and the scans show
(``obstacle_sources: [map, scan]``); a world without a map is then refused, since nothing
would know its known obstacles.

The robot's shape: ``footprint:="[[x, y], ...]"`` (Nav2's form, base_link, a convex polygon)
is given to the simulator (contacts of the true shape), the planner and the controller, over
their parameter files and the world's; empty (the default), each node takes the footprint of
its parameter file, else the world's polygon, else its robot_radius. With ``sensing:=true``
the planner and the controller no longer read the world, so the launch file hands them the
world's polygon itself (unless their parameter file sets one). An invalid footprint is
refused at launch, with the reason.

How real the simulated robot and laser are: ``reality:=ideal|mild|real|harsh`` (a preset of
sim/reality.py: command latency, actuator lag, acceleration limits, odometry noise and
drift, laser noise, NaN/-inf beams, lost scans) sets the simulator's ``reality`` over its
parameter file; empty (the default), the parameter file's (ideal in the shipped one). An
unknown name is refused at launch. The odometry of a non-ideal preset is not the pose in
``map``: run it with a localizer (closed_loop --reality does so with its stand-in).

Checked statically only: ``launch`` and ``launch_ros`` are not installable from PyPI, so the
tests compile this file and check the executables and files it names (test/ros/test_launch.py).
"""

import os
from typing import TYPE_CHECKING

from ament_index_python.packages import get_package_share_directory
from launch import LaunchContext, LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

if TYPE_CHECKING:
    from mpc_local_planner.worlds.world import World

PACKAGE = 'mpc_local_planner'


def _map_file(name: str, world_name: str) -> str | None:
    """Return the map to serve: the one named, else the world's own map (None if none)."""
    from mpc_local_planner.worlds.data_files import resolve_data_file

    if name:
        return str(resolve_data_file(name))
    try:
        return str(resolve_data_file(f'maps/{world_name}.yaml'))
    except FileNotFoundError:
        return None


def _radius(params_file: str, node: str, world_radius: float) -> float:
    """Return the radius the node's params file sets (>= 0), else the world's robot_radius."""
    import yaml

    try:
        with open(params_file, encoding='utf-8') as stream:
            values = yaml.safe_load(stream)[node]['ros__parameters']
        radius = float(values.get('robot_radius', -1.0))
    except (OSError, KeyError, TypeError, ValueError, yaml.YAMLError):
        return world_radius  # no such file or entry: the node's default (-1), the world's
    return world_radius if radius < 0.0 else radius


def _file_footprint(params_file: str, node: str) -> str:
    """Return the footprint one node's params file sets ('' if none or unreadable)."""
    import yaml

    try:
        with open(params_file, encoding='utf-8') as stream:
            values = yaml.safe_load(stream)[node]['ros__parameters']
        return str(values.get('footprint', '') or '').strip()
    except (OSError, KeyError, TypeError, ValueError, yaml.YAMLError):
        return ''


def _robot(footprint: str, world: 'World', params_file: str, node: str,
           sensing: bool) -> dict[str, str]:
    """Return the footprint parameter a node gets from the launch file ({} = none given).

    The footprint argument wins; with sensing, a node without the world (planner,
    controller) gets its params file's polygon, else the world's.
    """
    if footprint:
        return {'footprint': footprint}
    if not sensing or _file_footprint(params_file, node) or world.footprint.is_circle:
        return {}
    return {'footprint': str(world.footprint.vertices.tolist())}


def _check_footprint(text: str) -> str:
    """Return the footprint argument stripped ('' = none), or refuse it with the reason."""
    from mpc_local_planner.core.footprint import parse_footprint

    text = text.strip()
    if not text:
        return ''
    try:
        shape = parse_footprint(text)
    except ValueError as err:
        msg = f'footprint:={text}: {err}'
        raise RuntimeError(msg) from None
    if shape.is_circle:
        msg = f'footprint:={text}: give a convex polygon "[[x, y], ...]" (or leave it empty)'
        raise RuntimeError(msg)
    return text


def _check_reality(text: str) -> dict[str, str]:
    """Return the simulator's reality parameter for reality:=NAME ({} when empty).

    Raises:
        RuntimeError: for an unknown preset (the message lists the known ones).

    """
    from mpc_local_planner.sim.reality import REALITY_PRESETS

    if not text:
        return {}
    if text not in REALITY_PRESETS:
        msg = f'reality:={text}: choose one of {"|".join(REALITY_PRESETS)} (or leave it empty)'
        raise RuntimeError(msg)
    return {'reality': text}


def _nodes(context: LaunchContext) -> list[Node]:
    """Read the world once the arguments are known, and start the nodes for it."""
    from mpc_local_planner.worlds.data_files import resolve_data_file
    from mpc_local_planner.worlds.world import load_world

    def arg(name: str) -> str:
        return LaunchConfiguration(name).perform(context)

    world_file = str(resolve_data_file(arg('world')))
    world = load_world(world_file)
    use_sim_time = arg('use_sim_time').lower() == 'true'
    sensing = arg('sensing').lower() == 'true'
    footprint = _check_footprint(arg('footprint'))
    reality = _check_reality(arg('reality'))
    common = {'use_sim_time': use_sim_time}
    map_file = _map_file(arg('map'), world.name)
    if sensing and map_file is None:
        msg = (f'sensing:=true needs a map of the known obstacles of {world.name} '
               '(map:=FILE, or config/maps/<world name>.yaml; world_to_map makes one)')
        raise RuntimeError(msg)
    # with sensing, the planner and the controller know the map and the scans only (and
    # the robot's radius, which they no longer read from the world)
    planner_world = ({'world_file': '', 'use_map': True, 'use_scan': True,
                      'robot_radius': _radius(arg('planner_params'), 'global_planner',
                                              world.robot_radius)}
                     if sensing else {'world_file': world_file})
    controller_world = ({'world_file': '', 'obstacle_sources': ['map', 'scan'],
                         'robot_radius': _radius(arg('controller_params'), 'mpc_controller',
                                                 world.robot_radius)}
                        if sensing else {'world_file': world_file})
    map_server = [] if map_file is None else [
        Node(package=PACKAGE, executable='map_server', name='map_server', output='screen',
             parameters=[common, {'yaml_filename': map_file}])]
    return map_server + [
        Node(package=PACKAGE, executable='unicycle_simulator', name='unicycle_simulator',
             output='screen',
             parameters=[arg('simulator_params'), {
                 'publish_clock': use_sim_time,
                 'real_time_factor': float(arg('real_time_factor')),
                 'initial_pose': [float(v) for v in world.start],
                 'world_file': world_file, 'robot_radius': float(world.robot_radius),
                 # no TF here (tf2 is not installable): the simulated odometry is ground truth
                 # in the map frame, so RViz (fixed frame map) shows it as it is
                 'odom_frame': 'map',
                 **_robot(footprint, world, arg('simulator_params'), 'unicycle_simulator',
                          False), **reality}]),
        Node(package=PACKAGE, executable='global_planner', name='global_planner',
             output='screen',
             parameters=[arg('planner_params'), common, {
                 **planner_world, 'goal': [float(v) for v in world.goal],
                 **_robot(footprint, world, arg('planner_params'), 'global_planner',
                          sensing)}]),
        Node(package=PACKAGE, executable='mpc_controller', name='mpc_controller',
             output='screen',
             parameters=[arg('controller_params'), common, {
                 **controller_world,
                 **_robot(footprint, world, arg('controller_params'), 'mpc_controller',
                          sensing)}]),
        Node(package=PACKAGE, executable='bag_recorder', name='bag_recorder',
             output='screen', condition=IfCondition(arg('record')),
             parameters=[arg('recorder_params'), common, {'output': arg('bag')}]),
    ]


def generate_launch_description() -> LaunchDescription:
    """Declare the arguments; the nodes are made when the world is known."""
    config = os.path.join(get_package_share_directory(PACKAGE), 'config')
    return LaunchDescription([
        DeclareLaunchArgument('world', default_value='paper_obstacle.yaml',
                              description='world YAML: a path, or a name under config/worlds'),
        DeclareLaunchArgument('map', default_value='',
                              description='map YAML for map_server: a path, or a name such as '
                                          'maps/unknown_box.yaml; empty: maps/<world name>.yaml '
                                          'if it exists, else no map_server'),
        DeclareLaunchArgument('sensing', default_value='false',
                              description='true: the planner and the controller know only the '
                                          "map and the simulator's laser scans (unknown "
                                          'obstacles are found by the laser)'),
        DeclareLaunchArgument('footprint', default_value='',
                              description="the robot's convex polygon, Nav2's form "
                                          '"[[x, y], ...]" in base_link, for the simulator, '
                                          "the planner and the controller; empty: each node's "
                                          "parameter file, else the world's footprint"),
        DeclareLaunchArgument('reality', default_value='',
                              description="how real the simulator's robot and laser are: "
                                          'ideal|mild|real|harsh (sim/reality.py); empty: '
                                          "the simulator's parameter file"),
        DeclareLaunchArgument('use_sim_time', default_value='true',
                              description='the simulator drives /clock; every node follows it'),
        DeclareLaunchArgument('real_time_factor', default_value='1.0',
                              description='simulated seconds per wall second'),
        DeclareLaunchArgument('record', default_value='false',
                              description='true: record a bag with bag_recorder'),
        DeclareLaunchArgument('bag', default_value='bag',
                              description='bag directory (must not exist) when record:=true'),
        DeclareLaunchArgument('simulator_params',
                              default_value=os.path.join(config, 'unicycle_simulator.yaml')),
        DeclareLaunchArgument('planner_params',
                              default_value=os.path.join(config, 'global_planner.yaml')),
        DeclareLaunchArgument('controller_params',
                              default_value=os.path.join(config, 'mpc_controller.yaml')),
        DeclareLaunchArgument('recorder_params',
                              default_value=os.path.join(config, 'bag_recorder.yaml')),
        OpaqueFunction(function=_nodes),
    ])
