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

"""Path-following MPC for a unicycle robot in non-convex domains, with an RRT* global planner.

Layers, each importing only those before it (test/test_layers.py checks it): ``core`` (the
algorithm: models, paths, obstacles, the MPC, the planner, a real base's model), ``worlds``
(world files, BARN, maps), ``perception`` (scans and grids to obstacles), ``evaluation``
(closed loops without ROS, suites, benchmark) and ``ros`` (the nodes and closed_loop, the only
layer that imports rclpy).
"""

__version__ = '0.1.0'
