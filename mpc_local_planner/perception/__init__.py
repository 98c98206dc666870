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


"""What the robot knows, without rclpy.

Scans read as REP 117 says (scans.py) and taken in order at the pose of their stamp
(scan_intake.py), ray casting against shapes (raycast.py: the memory clears what beams pass
through; sim/ casts the simulated laser with it), scans to convex obstacles with a memory
(scan_obstacles.py), grids to rectangles and the planner's grid
(grids.py), the obstacles near the robot as the MPC takes them (local_obstacles.py), and the
robot's pose in the map frame (pose_history.py, localization.py).
"""
