# SPDX-License-Identifier: Apache-2.0
"""closed_loop's watch on the run: the monitor node, the recorder's topics and its flush.

The monitor learns from the controller's diagnostics when the goal is reached, from the
planner's when no plan will come, counts the simulator's contacts and, with sensing, keeps
a few snapshots of what the controller avoided for the figure.
"""

from __future__ import annotations

import math
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from std_msgs.msg import UInt32
from visualization_msgs.msg import Marker, MarkerArray

from mpc_local_planner.core.diagnostics import (
    CONTROLLER_DIAGNOSTICS_TOPIC,
    ControllerDiagnostics,
    PLANNER_DIAGNOSTICS_TOPIC,
    PlannerDiagnostics,
)
from mpc_local_planner.evaluation.rollout import STALL_INPUT
from mpc_local_planner.ros.bag_recorder_node import (
    BagRecorderNode,
    DEFAULT_LATCHED,
    DEFAULT_TOPICS,
    DEFAULT_TYPES,
)
from mpc_local_planner.ros.conversions import odometry_to_state, odometry_twist
from mpc_local_planner.ros.executors import spin_until
from mpc_local_planner.ros.mpc_controller_outputs import OBSTACLES_TOPIC
from mpc_local_planner.ros.qos import (
    CONTACTS_QOS,
    DIAGNOSTICS_QOS,
    LOCAL_PLAN_QOS,
    ODOM_QOS,
    PLANNER_DIAGNOSTICS_QOS,
)
from mpc_local_planner.ros.unicycle_simulator_parameters import (
    ACTIVE_CONTACTS_TOPIC,
    CONTACTS_TOPIC,
    GROUND_TRUTH_TOPIC,
    LOCKSTEP_STALLS_TOPIC,
    PASSIVE_CONTACTS_TOPIC,
    SCAN_TOPIC,
)

__all__ = ['FLUSH_TIMEOUT', 'LoopMonitor', 'SENSED_SNAPSHOTS',
           'flush_recording', 'recorder_topics']

# Wall seconds the recorder gets, after the run stops, to write what the monitor has seen.
FLUSH_TIMEOUT = 5.0
# The namespace of the obstacles the controller takes in (from the map and the scans with
# --sensing) on OBSTACLES_TOPIC.
RAW_NAMESPACE = 'raw'
# With --sensing, the monitor keeps what the controller avoids at most once per this many
# simulated seconds; the figure shows SENSED_SNAPSHOTS of them, spread over the run.
SNAPSHOT_PERIOD = 2.0
SENSED_SNAPSHOTS = 4


def recorder_topics(*, sensing: bool) -> dict[str, list[str]]:
    """Return the recorder's topics, types and latched topics (scan too with sensing).

    The simulator's ground truth too: the one-step prediction error is measured against it
    (evaluation/prediction_error.py --bag).
    """
    counts = [CONTACTS_TOPIC, ACTIVE_CONTACTS_TOPIC, PASSIVE_CONTACTS_TOPIC]
    topics = [*DEFAULT_TOPICS, *counts, GROUND_TRUTH_TOPIC]
    types = [*DEFAULT_TYPES, *['std_msgs/msg/UInt32'] * len(counts), 'nav_msgs/msg/Odometry']
    if sensing:
        topics.append(SCAN_TOPIC)
        types.append('sensor_msgs/msg/LaserScan')
    return {'topics': topics, 'types': types,
            'transient_local_topics': [*DEFAULT_LATCHED, *counts]}


def _raw_polygons(msg: MarkerArray) -> list[np.ndarray]:
    """Return the (K, 2) outlines of the markers in the raw namespace (closed rings opened)."""
    polygons = []
    for marker in msg.markers:
        if marker.ns != RAW_NAMESPACE or marker.action != Marker.ADD or len(marker.points) < 2:
            continue
        ring = np.array([(p.x, p.y) for p in marker.points], dtype=float)
        if len(ring) > 2 and np.allclose(ring[0], ring[-1]):
            ring = ring[:-1]
        polygons.append(ring)
    return polygons


class LoopMonitor(Node):
    """Watch the controller's diagnostics for the goal and the planner's for a failure.

    Also counts the simulator's contacts and, with sensing, keeps what the controller
    avoids (its raw obstacles) at a few instants for the figure.
    """

    def __init__(self, *, sensing: bool = False, goal: np.ndarray | None = None,
                 referee_radius: float | None = None, stall_seconds: float | None = None,
                 **kwargs: Any) -> None:
        """Watch; with referee_radius, also judge arrival from the TRUE pose (the referee).

        With stall_seconds, `stalled` says the robot has stood still (true speeds below
        STALL_INPUT) that long, as the suites' stop rule ends a run.
        """
        super().__init__('closed_loop_monitor', **kwargs)
        self.true_pose: np.ndarray | None = None
        self.referee_time: float | None = None  # when the true pose first came within
        self.stalled = False
        self._goal = None if goal is None else np.asarray(goal, dtype=float)
        self._referee_radius = referee_radius
        self._stall_seconds = stall_seconds
        self._still_since: float | None = None
        self.lockstep_stalls = 0  # how often the lockstep clock gave up waiting
        self._stalls_sub = self.create_subscription(
            UInt32, LOCKSTEP_STALLS_TOPIC,
            lambda msg: setattr(self, 'lockstep_stalls', int(msg.data)), CONTACTS_QOS)
        self._truth_sub = self.create_subscription(Odometry, GROUND_TRUTH_TOPIC,
                                                   self.truth_callback, ODOM_QOS)
        self.goal_reached = False
        self.replans = 0  # the planner's count of re-plans, as it last reported it
        self.contacts: int | None = None  # the simulator's count, once heard
        # of those, the ones it began moving and standing still (run into), once heard
        self.active_contacts: int | None = None
        self.passive_contacts: int | None = None
        # (simulated time, raw obstacle outlines) every SNAPSHOT_PERIOD at most
        self.sensed: list[tuple[float, list[np.ndarray]]] = []
        self.messages = 0  # diagnostics messages of the controller received
        self.last_reason = ''
        self.plan_failure: str | None = None  # why the planner published no plan
        self._sub = self.create_subscription(DiagnosticArray, CONTROLLER_DIAGNOSTICS_TOPIC,
                                             self.diagnostics_callback, DIAGNOSTICS_QOS)
        self._planner_sub = self.create_subscription(
            DiagnosticArray, PLANNER_DIAGNOSTICS_TOPIC, self.planner_callback,
            PLANNER_DIAGNOSTICS_QOS)
        # the simulator's contact counts: all, and those it began moving or standing still
        self._count_subs = [
            self.create_subscription(UInt32, topic,
                                     lambda msg, name=name: self._keep_count(name, msg),
                                     CONTACTS_QOS)
            for topic, name in ((CONTACTS_TOPIC, 'contacts'),
                                (ACTIVE_CONTACTS_TOPIC, 'active_contacts'),
                                (PASSIVE_CONTACTS_TOPIC, 'passive_contacts'))]
        self._obstacles_sub = None
        if sensing:
            self._obstacles_sub = self.create_subscription(
                MarkerArray, OBSTACLES_TOPIC, self.obstacles_callback, LOCAL_PLAN_QOS,
                raw=True)

    def truth_callback(self, msg: Odometry) -> None:
        """Keep the true pose; judge arrival (referee_radius) and standing still."""
        self.true_pose = odometry_to_state(msg)
        now = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if (self._referee_radius is not None and self._goal is not None
                and self.referee_time is None
                and math.hypot(*(self.true_pose[:2] - self._goal[:2])) <= self._referee_radius):
            self.referee_time = now
        if self._stall_seconds is not None:
            moving = float(np.max(np.abs(odometry_twist(msg)))) >= STALL_INPUT
            if moving or self._still_since is None:
                self._still_since = now
            self.stalled = now - self._still_since >= self._stall_seconds

    def _keep_count(self, name: str, msg: UInt32) -> None:
        """Keep one of the simulator's contact counts (they only grow)."""
        setattr(self, name, max(int(msg.data), getattr(self, name) or 0))

    def obstacles_callback(self, msg: MarkerArray | bytes) -> None:
        """Keep what the controller avoids, once per SNAPSHOT_PERIOD of simulated time.

        Taken serialised: only a snapshot's message is read (a MarkerArray at every control
        step costs this process more than all it does besides).
        """
        now = self.sim_time()
        if self.sensed and now < self.sensed[-1][0] + SNAPSHOT_PERIOD:
            return
        if isinstance(msg, bytes):
            msg = deserialize_message(msg, MarkerArray)
        polygons = _raw_polygons(msg)
        if polygons:
            self.sensed.append((now, polygons))

    @property
    def diagnostics_topic(self) -> str:
        """The controller's diagnostics topic, resolved."""
        return self._sub.topic_name

    def diagnostics_callback(self, msg: DiagnosticArray) -> None:
        """Note each control step and whether the controller is at the goal."""
        self.messages += 1
        for status in msg.status:
            step = ControllerDiagnostics.from_values((kv.key, kv.value) for kv in status.values)
            self.last_reason = step.message
            self.goal_reached = step.goal_reached

    def planner_callback(self, msg: DiagnosticArray) -> None:
        """Note whether the planner's latest goal failed (a later plan clears it)."""
        for status in msg.status:
            outcome = PlannerDiagnostics.from_values((kv.key, kv.value) for kv in status.values)
            self.replans = max(self.replans, outcome.replans)
            if outcome.waiting:
                continue  # waiting for the map: the plan is still to come
            self.plan_failure = (outcome.detail or 'no plan') if outcome.failed else None

    def sim_time(self) -> float:
        """Return the current ROS (simulated) time in seconds."""
        return self.get_clock().now().nanoseconds * 1e-9


def flush_recording(executor: Executor, recorder: BagRecorderNode, monitor: LoopMonitor, *,
                    timeout_sec: float = FLUSH_TIMEOUT) -> bool:
    """Spin until the recorder holds every controller diagnostics message the monitor saw.

    The run stops on the message that says the goal is reached; without this the executor
    may never run the recorder's callback for it, and the bag (so metrics.json's
    controller_goal_reached) would miss the arrival.

    Returns:
        True if the recorder caught up within timeout_sec.

    """
    return spin_until(
        executor, lambda: recorder.counts.get(monitor.diagnostics_topic, 0) >= monitor.messages,
        timeout_sec=timeout_sec)
