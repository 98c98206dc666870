# SPDX-License-Identifier: Apache-2.0
"""The algorithm and its data, without rclpy.

It reads and writes no files but one: with SolverSettings.compile the MPC's NLPs are compiled
once and kept in a cache folder (core/mpc/compilation.compile_cache_dir(), ~/.cache or
$MPC_LOCAL_PLANNER_CACHE), so that a restarted controller loads them at once.
"""
