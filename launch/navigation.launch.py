# SPDX-License-Identifier: Apache-2.0
"""Run the planner and the MPC on a real robot (``ros2 launch ... navigation.launch.py``).

The robot's driver supplies ``odom`` and takes ``cmd_vel``; goals come on ``goal_pose``
(RViz's "2D Goal Pose"), and nothing moves before one does. The map server serves the
robot's map ``map:=FILE`` (map_server format; required: there is no default map) on
``/map``; the planner plans on it (``use_map``) and the controller avoids its occupied cells
(``obstacle_sources: [map]``). No world file and no goal are given: a real robot's
obstacles are those of its map, not a demo's.

Checked statically only: ``launch`` and ``launch_ros`` are not installable from PyPI, so the
tests compile this file and check the executables and files it names (test/ros/test_launch.py).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = 'mpc_local_planner'


def generate_launch_description() -> LaunchDescription:
    """Declare the arguments and the three nodes."""
    config = os.path.join(get_package_share_directory(PACKAGE), 'config')
    use_sim_time = LaunchConfiguration('use_sim_time')
    return LaunchDescription([
        DeclareLaunchArgument('map',
                              description="the robot's map (map_server YAML): a path or a name"),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='true when a simulator or a bag drives /clock'),
        DeclareLaunchArgument('planner_params',
                              default_value=os.path.join(config, 'global_planner.yaml')),
        DeclareLaunchArgument('controller_params',
                              default_value=os.path.join(config, 'mpc_controller.yaml')),
        Node(package=PACKAGE, executable='map_server', name='map_server', output='screen',
             parameters=[{'use_sim_time': use_sim_time,
                          'yaml_filename': LaunchConfiguration('map')}]),
        Node(package=PACKAGE, executable='global_planner', name='global_planner',
             output='screen',
             parameters=[LaunchConfiguration('planner_params'),
                         {'use_sim_time': use_sim_time, 'use_map': True}]),
        Node(package=PACKAGE, executable='mpc_controller', name='mpc_controller',
             output='screen',
             parameters=[LaunchConfiguration('controller_params'),
                         {'use_sim_time': use_sim_time, 'obstacle_sources': ['map']}]),
    ])
