# SPDX-License-Identifier: Apache-2.0
"""Path-following MPC for a unicycle robot in non-convex domains, with an RRT* global planner.

Layers, each importing only those before it (test/test_layers.py checks it): ``core`` (the
algorithm: models, paths, obstacles, the MPC, the planner, a real base's model), ``worlds``
(world files, BARN, maps), ``perception`` (scans and grids to obstacles), ``evaluation``
(closed loops without ROS, suites, benchmark) and ``ros`` (the nodes and closed_loop, the only
layer that imports rclpy).
"""

__version__ = '0.1.0'
