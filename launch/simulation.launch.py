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


"""Simulate the robot and drive it with the paper's MPC (``ros2 launch ... simulation.launch.py``).

Starts the unicycle simulator (it drives ``/clock``), the map server, the global planner and
the MPC controller, all on simulated time, and the bag recorder with ``record:=true``. The
world (``world:=NAME`` or a path) gives the simulator's start pose and the planner's goal; the
map server serves ``map:=FILE``, by default the world's map ``maps/<world name>.yaml`` (its
known obstacles, made by ``world_to_map``), and is left out if the world has none. Each
node's parameters come from its YAML under ``share/mpc_local_planner/config`` unless a
``*_params`` argument names another file.

Checked statically only: ``launch`` and ``launch_ros`` are not installable from PyPI, so the
tests compile this file and check the executables and files it names (test/ros/test_launch.py).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchContext, LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

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


def _nodes(context: LaunchContext) -> list[Node]:
    """Read the world once the arguments are known, and start the nodes for it."""
    from mpc_local_planner.worlds.data_files import resolve_data_file
    from mpc_local_planner.worlds.world import load_world

    def arg(name: str) -> str:
        return LaunchConfiguration(name).perform(context)

    world_file = str(resolve_data_file(arg('world')))
    world = load_world(world_file)
    use_sim_time = arg('use_sim_time').lower() == 'true'
    common = {'use_sim_time': use_sim_time}
    map_file = _map_file(arg('map'), world.name)
    map_server = [] if map_file is None else [
        Node(package=PACKAGE, executable='map_server', name='map_server', output='screen',
             parameters=[common, {'yaml_filename': map_file}])]
    return map_server + [
        Node(package=PACKAGE, executable='unicycle_simulator', name='unicycle_simulator',
             output='screen',
             parameters=[arg('simulator_params'), {
                 'publish_clock': use_sim_time,
                 'real_time_factor': float(arg('real_time_factor')),
                 'initial_pose': [float(v) for v in world.start]}]),
        Node(package=PACKAGE, executable='global_planner', name='global_planner',
             output='screen',
             parameters=[arg('planner_params'), common, {
                 'world_file': world_file, 'goal': [float(v) for v in world.goal]}]),
        Node(package=PACKAGE, executable='mpc_controller', name='mpc_controller',
             output='screen',
             parameters=[arg('controller_params'), common, {'world_file': world_file}]),
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
