# SPDX-License-Identifier: Apache-2.0
"""Packaging for colcon (ament_python) and for pip on a machine without ROS."""

from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'mpc_local_planner'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['py.typed', 'data/barn/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        (os.path.join('share', package_name, 'config'), glob('config/*.yaml')),
        (os.path.join('share', package_name, 'config', 'worlds'), glob('config/worlds/*.yaml')),
        (os.path.join('share', package_name, 'config', 'maps'), glob('config/maps/*')),
        (os.path.join('share', package_name, 'launch'), glob('launch/*.launch.py')),
        (os.path.join('share', package_name, 'rviz'), glob('rviz/*.rviz')),
    ],
    install_requires=[
        'numpy',
        'casadi>=3.6',
        'ompl>=2.0',
        'rosbags>=0.10',
        'matplotlib',
        'pyyaml',
        'scipy',
        'pillow',
    ],
    extras_require={
        # The ROS 2 Jazzy Python wheels on PyPI, for machines without a ROS install.
        'wheels': [
            'ros-rclpy[fastrtps]==7.1.6',
            'ros-geometry-msgs==5.3.6',
            'ros-nav-msgs==5.3.6',
            'ros-std-msgs==5.3.6',
            'ros-visualization-msgs==5.3.6',
            'ros-diagnostic-msgs==5.3.6',
            'ros-rosgraph-msgs==2.0.3',
            'ros-sensor-msgs==5.3.6',
            'ros-lifecycle-msgs==2.0.3',
        ],
        # evaluate --executor dask: the runs on a Dask cluster (dask scheduler, dask worker).
        'cluster': ['dask[distributed]>=2024.1'],
        # the MuJoCo plant (sim/physics/): plant: mujoco, --plant mujoco, step_response
        'physics': ['mujoco>=3,<4'],
        # the tests run the Dask executor too
        'test': ['pytest', 'pytest-timeout', 'hypothesis', 'ruff', 'dask[distributed]>=2024.1'],
    },
    python_requires='>=3.10',
    zip_safe=True,
    maintainer='mpc_local_planner developers',
    maintainer_email='maintainers@mpc-local-planner.invalid',
    description='MPC local planner for a unicycle robot following an RRT* path (ROS 2 Jazzy).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'global_planner = mpc_local_planner.ros.global_planner_node:main',
            'mpc_controller = mpc_local_planner.ros.mpc_controller_node:main',
            'unicycle_simulator = mpc_local_planner.ros.unicycle_simulator_node:main',
            'bag_recorder = mpc_local_planner.ros.bag_recorder_node:main',
            'closed_loop = mpc_local_planner.ros.closed_loop:main',
            'analyze_bag = mpc_local_planner.evaluation.analyze_bag:main',
            'identify_base = mpc_local_planner.evaluation.identify_base:main',
            'replay_step = mpc_local_planner.ros.replay_step:main',
            'mpc_bench = mpc_local_planner.evaluation.bench:main',
            'mpc_bench_dds = mpc_local_planner.ros.latency_bench:main',
            'step_response = mpc_local_planner.sim.step_response:main',
            'world_to_map = mpc_local_planner.worlds.world_to_map:main',
            'map_server = mpc_local_planner.ros.map_server_node:main',
            'mpc_local_planner_share = mpc_local_planner.worlds.data_files:main',
        ],
    },
)
