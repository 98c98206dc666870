# SPDX-License-Identifier: Apache-2.0
"""What mpc_controller publishes each control step, and what it logs.

cmd_vel (Twist, or TwistStamped in ``robot_base_frame``), ``local_plan`` (the prediction),
``mpc/diagnostics`` (core/diagnostics.py's keys), ``mpc/obstacles`` (MarkerArray: the
obstacles raw, grown and active, sent when that changes and every OBSTACLE_REFRESH_STEPS
control steps, and only while subscribed), ``mpc/footprint`` and, with ``track_moving``,
``mpc/tracks`` (MarkerArray: each track of the laser's clusters, `track_markers`), all in
``global_frame``;
a log line when the reason changes (`log_line`). ControllerOutputs is a component MpcControllerNode
(ros/mpc_controller_node.py) builds at configure: it owns these publishers and what it last
sent, and the node hands it each control step's output.
"""

from __future__ import annotations

import math
from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PolygonStamped, Twist, TwistStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.duration import Duration
from rclpy.lifecycle import LifecycleNode
from visualization_msgs.msg import Marker, MarkerArray

from mpc_local_planner.core.control_output import Blockage, ControlOutput, Reason
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.diagnostics import (
    CONTROLLER_DIAGNOSTICS_TOPIC,
    ControllerDiagnostics,
    Level,
)
from mpc_local_planner.perception.tracking import Track
from mpc_local_planner.ros.conversions import (
    arrow_marker,
    cylinder_marker,
    delete_all_marker,
    diagnostic_array,
    polygon_marker,
    polygon_stamped,
    poses_to_path,
    seconds_to_stamp,
    twist_from_u,
    twist_stamped_from_u,
)
from mpc_local_planner.ros.qos import CMD_VEL_QOS, DIAGNOSTICS_QOS, LOCAL_PLAN_QOS
from mpc_local_planner.ros.throttle import ERROR_THROTTLE_S, ProblemThrottle

__all__ = ['ControllerOutputs', 'FOOTPRINT_TOPIC', 'MARKER_STYLE', 'MARKERS_QOS',
           'OBSTACLE_REFRESH_STEPS', 'OBSTACLES_TOPIC', 'log_line', 'track_markers',
           'TRACKS_TOPIC']

# What the controller avoids, as markers (closed_loop's monitor reads it too).
OBSTACLES_TOPIC = 'mpc/obstacles'
# The robot's outline (PolygonStamped).
FOOTPRINT_TOPIC = 'mpc/footprint'
# Streams like local_plan: reliable, volatile, depth 10.
MARKERS_QOS = LOCAL_PLAN_QOS

# mpc/obstacles goes out when what it shows changes, and at least every this many control
# steps (for an RViz that subscribes late: the topic is volatile).
OBSTACLE_REFRESH_STEPS = 10
# ...but a change goes out at most this often (s of ROS time): the laser's memory changes at
# every scan, and building the markers of its pieces at every one took a fifth of the
# controller node's time on BARN (issue 34); 5 Hz is the MPC's solve rate at h = 0.2 s.
OBSTACLE_MARKER_PERIOD = 0.2
# A timer's ticks land on the period's end to the last digit (20 Hz: 4 ticks = 0.2 s): a tick
# this close (s) counts as past it, whichever way the sum rounded.
_PERIOD_SLACK = 1e-3
# Marker namespaces, colours (r, g, b, a) and line widths (m).
MARKER_STYLE = {
    'raw': ((0.2, 0.2, 0.2, 1.0), 0.02),  # as described in the world
    'grown': ((1.0, 0.6, 0.0, 0.8), 0.015),  # inflated by robot radius + collision margin
    'active': ((0.9, 0.0, 0.0, 1.0), 0.04),  # held in the NLP at the last solve
}

# The tracks of the laser's clusters (with track_moving), as markers.
TRACKS_TOPIC = 'mpc/tracks'
# Their namespaces' colours (r, g, b, a); a track's disc is its cluster's radius grown by
# TRACK_SIGMAS standard deviations of its position; a moving (or suspect) track's arrow shows
# where its velocity takes it in TRACK_ARROW_S seconds.
TRACK_STYLE = {
    'static': (0.5, 0.5, 0.5, 0.5),
    'suspect': (1.0, 0.55, 0.0, 0.7),
    'moving': (0.8, 0.0, 0.8, 0.7),
    'velocity': (0.8, 0.0, 0.8, 1.0),
}
TRACK_SIGMAS = 2.0
TRACK_ARROW_S = 1.0
TRACK_HEIGHT = 0.3
TRACK_ARROW_WIDTH = 0.04


def track_markers(tracks: list[Track], *, frame_id: str, stamp: Any) -> MarkerArray:
    """Return mpc/tracks' markers: DELETEALL, then a disc per track and an arrow per mover.

    A track's marker id is its track id, so RViz follows one object from scan to scan; a
    disc is the cluster's radius plus TRACK_SIGMAS standard deviations of the position
    (the larger axis of its covariance), in 'moving', 'suspect' (predicted as a mover, not
    yet told moving: `Track.suspect`) or 'static'.
    """
    markers = [delete_all_marker(frame_id=frame_id, stamp=stamp)]
    for track in tracks:
        x, y = (float(v) for v in track.position)
        spread = float(np.sqrt(max(np.linalg.eigvalsh(track.covariance[:2, :2])[-1], 0.0)))
        ns = 'moving' if track.moving else 'suspect' if track.suspect else 'static'
        markers.append(cylinder_marker(x, y, track.size + TRACK_SIGMAS * spread, ns=ns,
                                       marker_id=track.id, frame_id=frame_id, stamp=stamp,
                                       rgba=TRACK_STYLE[ns], height=TRACK_HEIGHT))
        if track.moving or track.suspect:
            end = track.position + TRACK_ARROW_S * track.velocity
            markers.append(arrow_marker((x, y), end, ns='velocity', marker_id=track.id,
                                        frame_id=frame_id, stamp=stamp,
                                        rgba=TRACK_STYLE['velocity'],
                                        width=TRACK_ARROW_WIDTH))
    return MarkerArray(markers=markers)


def _same(a: tuple, b: tuple) -> bool:
    """Say whether two tuples hold the same objects (identity, not equality)."""
    return len(a) == len(b) and all(x is y for x, y in zip(a, b, strict=True))


def log_line(output: ControlOutput, *, failures: int,
             goal_error: tuple[float, float]) -> tuple[Level, str]:
    """Return the level and the line the node logs when the reason changes to output's.

    Args:
        output: the control step.
        failures: the controller's solver failures so far.
        goal_error: (position, heading) error to the end of the plan.

    """
    reason, message = output.reason, output.message
    if reason is Reason.CANDIDATE:
        v, omega = output.u
        return Level.WARN, (f'{message}: applying its input v = {v:.3f} m/s, omega = '
                            f'{omega:.3f} rad/s (solver failures so far: {failures})')
    if reason is Reason.EVADE:
        v, omega = output.u
        return Level.WARN, (f'{message}: v = {v:.3f} m/s, omega = {omega:.3f} rad/s '
                            f'(solver failures so far: {failures})')
    if reason in (Reason.STALE_ODOM, Reason.STOP, Reason.STALE_SCAN, Reason.NO_SCAN,
                  Reason.NO_MAP):
        return Level.WARN, f'{message}: cmd_vel is zero (solver failures so far: {failures})'
    if reason is Reason.GOAL_REACHED:
        position, heading = goal_error
        return Level.OK, f'{message}: {position:.3f} m, {heading:.3f} rad off'
    if reason is Reason.ERROR:
        return Level.ERROR, f'{message}; cmd_vel is zero'
    return Level.OK, message


class ControllerOutputs:
    """MpcControllerNode's publishers, and the publishing and logging of a control step.

    Args:
        node: the lifecycle node the publishers belong to (enabled with it).
        controller: the node's MpcController (obstacles, footprint, failures).
        stamped: cmd_vel as TwistStamped (enable_stamped_cmd_vel) rather than Twist.
        parameter: the current value of a node parameter (the frames: read when used).

    """

    def __init__(self, node: LifecycleNode, controller: MpcController, *, stamped: bool,
                 parameter: Callable[[str], Any]) -> None:
        self._controller = controller
        self._stamped = stamped
        self._parameter = parameter
        self._logger = node.get_logger()
        self._name = f'{node.get_name()}: MPC'
        self._hardware_id = node.get_fully_qualified_name()
        self._problems = ProblemThrottle(ERROR_THROTTLE_S)
        self._last_message = ''
        self._markers_shown: tuple[tuple, tuple] | None = None  # (grown, active) last sent
        self._steps_since_markers = 0
        self._markers_time = -math.inf  # ROS time of the last mpc/obstacles sent
        # the markers of the polygons last sent, by (namespace, polygon's identity)
        self._polygon_markers: dict[tuple[str, int], tuple[Any, Marker]] = {}
        self._cmd_pub = node.create_lifecycle_publisher(
            TwistStamped if stamped else Twist, 'cmd_vel', CMD_VEL_QOS)
        self._local_plan_pub = node.create_lifecycle_publisher(Path, 'local_plan',
                                                               LOCAL_PLAN_QOS)
        self._diag_pub = node.create_lifecycle_publisher(
            DiagnosticArray, CONTROLLER_DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS)
        self._obstacles_pub = node.create_lifecycle_publisher(MarkerArray, OBSTACLES_TOPIC,
                                                              MARKERS_QOS)
        self._footprint_pub = node.create_lifecycle_publisher(PolygonStamped, FOOTPRINT_TOPIC,
                                                              MARKERS_QOS)
        self._tracks_pub = node.create_lifecycle_publisher(MarkerArray, TRACKS_TOPIC,
                                                           MARKERS_QOS)

    @property
    def publishers(self) -> tuple[Any, ...]:
        """The publishers, for the node to destroy."""
        return (self._cmd_pub, self._local_plan_pub, self._diag_pub, self._obstacles_pub,
                self._footprint_pub, self._tracks_pub)

    def publish(self, output: ControlOutput, now: float, *, state: np.ndarray | None,
                state_time: float | None, blockage: Blockage,
                tracks: list[Track] | None = None) -> None:
        """Publish cmd_vel, then local_plan, diagnostics, obstacles, footprint, tracks; log.

        Args:
            output: the control step's output.
            now: its time (s of ROS time).
            state: the pose in the plan's frame it was computed for (None: none).
            state_time: when that pose was measured.
            blockage: where the plan is blocked (path_blockage), for the diagnostics.
            tracks: the laser's tracks (None: the node does not track; nothing is sent);
                sent only while mpc/tracks has a subscriber.

        """
        self._cmd_pub.publish(self._cmd_message(output.u, now))
        try:
            stamp = seconds_to_stamp(max(now, 0.0))
            frame = str(self._parameter('global_frame'))
            if output.solution is not None:
                self._local_plan_pub.publish(poses_to_path(
                    output.solution.x_pred[:, :3], frame_id=frame, stamp=stamp))
            self._diag_pub.publish(self._diagnostics(output, now, state, state_time,
                                                     blockage))
            self._publish_obstacles(output, frame, stamp, now)
            if tracks is not None and self._tracks_pub.get_subscription_count():
                self._tracks_pub.publish(track_markers(tracks, frame_id=frame, stamp=stamp))
            if state is not None:
                # the shape the MPC keeps clear: the polygon, or the circle as a 16-gon
                self._footprint_pub.publish(polygon_stamped(
                    self._controller.config.robot_footprint.at(state), frame_id=frame,
                    stamp=stamp))
        except Exception as err:  # a message that cannot be built: keep controlling
            self._logger.warning(f'could not publish: {err}', throttle_duration_sec=1.0)
        self._log(output, state)

    def publish_stop(self, now: float) -> None:
        """Publish one zero cmd_vel (while the publisher is enabled)."""
        self._cmd_pub.publish(self._cmd_message(np.zeros(2), now))

    def wait_for_cmd_acked(self, timeout_s: float) -> bool:
        """Wait until every cmd_vel subscriber acknowledged what was sent; say if they did."""
        return self._cmd_pub.wait_for_all_acked(Duration(seconds=timeout_s))

    def _cmd_message(self, u: np.ndarray, now: float) -> Twist | TwistStamped:
        """Return cmd_vel's message for u: a Twist, or a TwistStamped in base_link."""
        if not self._stamped:
            return twist_from_u(u)
        return twist_stamped_from_u(u, stamp=seconds_to_stamp(max(now, 0.0)),
                                    frame_id=str(self._parameter('robot_base_frame')))

    def _publish_obstacles(self, output: ControlOutput, frame: str, stamp: Any,
                           now: float | None = None) -> None:
        """Publish the obstacles raw, grown and active when that changes (or now and then).

        Each publication starts with DELETEALL, so markers of obstacles gone (or no longer
        active) disappear; ids are the obstacles' indices within their namespace. Nothing is
        built while nobody subscribes (building them took about half the node's own time
        among BARN's pieces: issue 34); a subscriber that comes gets them at the next step.
        A change goes out at most every OBSTACLE_MARKER_PERIOD of ROS time now (None: at
        once); one held back goes out at the first step after it.
        """
        if self._obstacles_pub.get_subscription_count() == 0:
            self._markers_shown = None
            return
        controller = self._controller
        grown = controller.grown_obstacles
        # active only if this step solved: a stop without a solve holds nothing
        active = controller.active_obstacles if output.solution is not None else ()
        self._steps_since_markers += 1
        shown = self._markers_shown
        if (shown is not None and _same(shown[0], grown) and _same(shown[1], active)
                and self._steps_since_markers < OBSTACLE_REFRESH_STEPS):
            return
        if (shown is not None and now is not None
                and 0.0 <= now - self._markers_time < OBSTACLE_MARKER_PERIOD - _PERIOD_SLACK):
            return  # a change, too soon after the last (a clock that went back: at once)
        markers = [delete_all_marker(frame_id=frame, stamp=stamp)]
        kept, built = self._polygon_markers, {}
        for ns, polygons in (('raw', controller.obstacles), ('grown', grown),
                             ('active', active)):
            rgba, width = MARKER_STYLE[ns]
            for i, polygon in enumerate(polygons):
                # a polygon shown before keeps its marker (the memory's pieces stay the same
                # objects from scan to scan): only its id and stamp are set again
                key = (ns, id(polygon))
                entry = kept.get(key)
                if (entry is None or entry[0] is not polygon or key in built
                        or entry[1].header.frame_id != frame):
                    entry = (polygon, polygon_marker(polygon.vertices, ns=ns, marker_id=i,
                                                     frame_id=frame, stamp=stamp, rgba=rgba,
                                                     width=width))
                else:
                    entry[1].id = i
                    entry[1].header.stamp = stamp
                built.setdefault(key, entry)
                markers.append(entry[1])
        self._polygon_markers = built
        self._obstacles_pub.publish(MarkerArray(markers=markers))
        self._markers_shown = (grown, active)
        self._steps_since_markers = 0
        self._markers_time = -math.inf if now is None else now

    def _log(self, output: ControlOutput, state: np.ndarray | None) -> None:
        """Log a change of reason (refused input is logged, throttled, where refused)."""
        message = output.message
        if message == self._last_message:
            return
        self._last_message = message
        if output.reason in (Reason.INVALID_ODOM, Reason.INVALID_PLAN, Reason.NO_LOCALIZATION):
            return
        if output.reason is Reason.ERROR and not self._problems.report('error'):
            return
        state = state if state is not None else np.full(3, np.nan)
        level, line = log_line(output, failures=self._controller.solver_failures,
                               goal_error=self._controller.goal_error(state))
        # one call site per severity: rclpy refuses a call site that changes severity
        if level is Level.ERROR:
            self._logger.error(line)
        elif level is Level.WARN:
            self._logger.warning(line)
        else:
            self._logger.info(line)

    def _diagnostics(self, output: ControlOutput, now: float, state: np.ndarray | None,
                     state_time: float | None, blockage: Blockage) -> DiagnosticArray:
        record = ControllerDiagnostics.from_output(
            output, state=state, state_time=state_time,
            failures_total=self._controller.solver_failures, blockage=blockage,
            timeouts_total=self._controller.timeouts)
        return diagnostic_array(name=self._name, hardware_id=self._hardware_id,
                                level=record.level, message=record.message,
                                values=record.to_values(),
                                stamp=seconds_to_stamp(max(now, 0.0)))
