# SPDX-License-Identifier: Apache-2.0
"""The QoS of every topic the package uses, shared by publishers, subscribers and recorder.

Latched topics (``plan``, ``planner/diagnostics``) are reliable and transient_local with
depth 1, so that a node that starts late still gets the latest message; the streams
(``odom``, ``cmd_vel``, ``local_plan``, ``mpc/diagnostics``, ``goal_pose``) are reliable and
volatile with depth 10.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = [
    'CLOCK_QOS',
    'CMD_VEL_QOS',
    'CONTACTS_QOS',
    'DIAGNOSTICS_QOS',
    'GOAL_QOS',
    'LOCAL_PLAN_QOS',
    'LOCALIZER_QOS',
    'MAP_QOS',
    'ODOM_QOS',
    'PLAN_QOS',
    'PLANNER_DIAGNOSTICS_QOS',
    'SCAN_QOS',
    'recorder_qos',
]

PLAN_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL,
                      history=HistoryPolicy.KEEP_LAST)
# the outcome of the latest goal: a supervisor that subscribes late still learns it
PLANNER_DIAGNOSTICS_QOS = PLAN_QOS
ODOM_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
CMD_VEL_QOS = ODOM_QOS
LOCAL_PLAN_QOS = ODOM_QOS
DIAGNOSTICS_QOS = ODOM_QOS
GOAL_QOS = ODOM_QOS
CLOCK_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)

# Messages the recorder queues per topic while the executor is busy.
_RECORDER_DEPTH = 100


def recorder_qos(*, latched: bool) -> QoSProfile:
    """Return the recorder's subscription QoS (reliable; transient_local if latched)."""
    return QoSProfile(depth=_RECORDER_DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                      durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                                  else DurabilityPolicy.VOLATILE),
                      history=HistoryPolicy.KEEP_LAST)

# ``map`` as nav2_map_server publishes it: reliable, transient_local, depth 1, so RViz or a
# planner that starts after the map server still receives the map it sent once.
MAP_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     history=HistoryPolicy.KEEP_LAST)

# ``scan`` as a subscriber takes it: best effort (what sensor drivers publish, and a reliable
# publisher such as the simulator matches it too), depth 5, volatile: an old scan is useless.
SCAN_QOS = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
# ``simulator/contacts``: the number of contact episodes so far, latched like ``plan``.
CONTACTS_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL,
                          history=HistoryPolicy.KEEP_LAST)

# ``amcl_pose`` (geometry_msgs/PoseWithCovarianceStamped) as a subscriber takes it: reliable
# and volatile, which matches AMCL's transient_local publisher and a volatile one alike.
LOCALIZER_QOS = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
