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


"""The algorithm and its data, without rclpy.

It reads and writes no files but one: with SolverSettings.compile the MPC's NLPs are compiled
once and kept in a cache folder (core/mpc/compilation.compile_cache_dir(), ~/.cache or
$MPC_LOCAL_PLANNER_CACHE), so that a restarted controller loads them at once.
"""
