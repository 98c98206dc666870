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

"""Session-wide test setup: isolate ROS 2 discovery before anything imports rclpy.

The environment is set at import time because DDS reads it when the first context is
initialised; pytest imports conftest.py before any test module, hence before rclpy.
Keeping discovery on localhost and using a domain id derived from the pid keeps parallel
test sessions (and other machines) from seeing each other's nodes.
"""

from __future__ import annotations

import os

# Domain ids 1..100: 0 is the default everyone else uses, and ids above ~101 collide with
# the ephemeral port range on Linux for some RMW implementations.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ['ROS_DOMAIN_ID'] = str(1 + os.getpid() % 100)
