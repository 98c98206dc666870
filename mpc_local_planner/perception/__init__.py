# SPDX-License-Identifier: Apache-2.0
"""What the robot knows, without rclpy.

Scans read as REP 117 says (scans.py) and taken in order at the pose of their stamp
(scan_intake.py), ray casting against shapes (raycast.py: the memory clears what beams pass
through; sim/ casts the simulated laser with it), scans to convex obstacles with a memory
(scan_obstacles.py), grids to rectangles and the planner's grid
(grids.py), the obstacles near the robot as the MPC takes them (local_obstacles.py), and the
robot's pose in the map frame (pose_history.py, localization.py).
"""
