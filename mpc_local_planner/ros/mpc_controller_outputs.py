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

"""What mpc_controller publishes each control step, and what it logs.

cmd_vel (Twist, or TwistStamped in ``robot_base_frame``), ``local_plan`` (the prediction),
``mpc/diagnostics`` (core/diagnostics.py's keys), ``mpc/obstacles`` (MarkerArray: the
obstacles raw, grown and active, sent when that changes and every OBSTACLE_REFRESH_STEPS
control steps) and ``mpc/footprint``, all in ``global_frame``; a log line when the reason
changes (`log_line`). ControllerOutputs is a part of MpcControllerNode
(ros/mpc_controller_node.py), which holds the publishers and the state these read.
"""

from __future__ import annotations

from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist, TwistStamped
import numpy as np
from visualization_msgs.msg import MarkerArray

from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.diagnostics import (
    ControllerDiagnostics,
    Level,
)
from mpc_local_planner.ros.conversions import (
    delete_all_marker,
    diagnostic_array,
    polygon_marker,
    polygon_stamped,
    poses_to_path,
    seconds_to_stamp,
    twist_from_u,
    twist_stamped_from_u,
)

__all__ = ['ControllerOutputs', 'MARKER_STYLE', 'OBSTACLE_REFRESH_STEPS', 'OBSTACLES_TOPIC',
           'log_line']

# What the controller avoids, as markers (closed_loop's monitor reads it too).
OBSTACLES_TOPIC = 'mpc/obstacles'

# mpc/obstacles goes out when what it shows changes, and at least every this many control
# steps (for an RViz that subscribes late: the topic is volatile).
OBSTACLE_REFRESH_STEPS = 10
# Marker namespaces, colours (r, g, b, a) and line widths (m).
MARKER_STYLE = {
    'raw': ((0.2, 0.2, 0.2, 1.0), 0.02),  # as described in the world
    'grown': ((1.0, 0.6, 0.0, 0.8), 0.015),  # inflated by robot radius + collision margin
    'active': ((0.9, 0.0, 0.0, 1.0), 0.04),  # held in the NLP at the last solve
}


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
    """MpcControllerNode's publishing and logging of a control step's output."""

    def _publish_outputs(self, output: ControlOutput, now: float) -> None:
        """Publish cmd_vel, then local_plan, diagnostics, obstacles and footprint; log."""
        self._cmd_pub.publish(self._cmd_message(output.u, now))
        try:
            stamp = seconds_to_stamp(max(now, 0.0))
            frame = str(self.get_parameter('global_frame').value)
            if output.solution is not None:
                self._local_plan_pub.publish(poses_to_path(
                    output.solution.x_pred[:, :3], frame_id=frame, stamp=stamp))
            self._diag_pub.publish(self._diagnostics(output, now))
            self._publish_obstacles(output, frame, stamp)
            if self._state is not None:
                # the shape the MPC keeps clear: the polygon, or the circle as a 16-gon
                self._footprint_pub.publish(polygon_stamped(
                    self.controller.config.robot_footprint.at(self._state), frame_id=frame,
                    stamp=stamp))
        except Exception as err:  # a message that cannot be built: keep controlling
            self.get_logger().warning(f'could not publish: {err}', throttle_duration_sec=1.0)
        self._log(output)

    def _cmd_message(self, u: np.ndarray, now: float) -> Twist | TwistStamped:
        """Return cmd_vel's message for u: a Twist, or a TwistStamped in base_link."""
        if not self._stamped:
            return twist_from_u(u)
        return twist_stamped_from_u(u, stamp=seconds_to_stamp(max(now, 0.0)),
                                    frame_id=str(self.get_parameter('robot_base_frame').value))

    def _publish_obstacles(self, output: ControlOutput, frame: str, stamp: Any) -> None:
        """Publish the obstacles raw, grown and active when that changes (or now and then).

        Each publication starts with DELETEALL, so markers of obstacles gone (or no longer
        active) disappear; ids are the obstacles' indices within their namespace.
        """
        grown = self.controller.grown_obstacles
        # active only if this step solved: a stop without a solve holds nothing
        active = self.controller.active_obstacles if output.solution is not None else ()
        self._steps_since_markers += 1
        shown = self._markers_shown
        if (shown is not None and _same(shown[0], grown) and _same(shown[1], active)
                and self._steps_since_markers < OBSTACLE_REFRESH_STEPS):
            return
        markers = [delete_all_marker(frame_id=frame, stamp=stamp)]
        for ns, polygons in (('raw', self.controller.obstacles), ('grown', grown),
                             ('active', active)):
            rgba, width = MARKER_STYLE[ns]
            markers += [polygon_marker(p.vertices, ns=ns, marker_id=i, frame_id=frame,
                                       stamp=stamp, rgba=rgba, width=width)
                        for i, p in enumerate(polygons)]
        self._obstacles_pub.publish(MarkerArray(markers=markers))
        self._markers_shown = (grown, active)
        self._steps_since_markers = 0

    def _log(self, output: ControlOutput) -> None:
        """Log a change of reason (refused input is logged, throttled, where refused)."""
        message = output.message
        if message == self._last_message:
            return
        self._last_message = message
        self.goal_reached = output.reason is Reason.GOAL_REACHED
        if output.reason in (Reason.INVALID_ODOM, Reason.INVALID_PLAN, Reason.NO_LOCALIZATION):
            return
        if output.reason is Reason.ERROR and not self._problems.report('error'):
            return
        state = self._state if self._state is not None else np.full(3, np.nan)
        level, line = log_line(output, failures=self.controller.solver_failures,
                               goal_error=self.controller.goal_error(state))
        # one call site per severity: rclpy refuses a call site that changes severity
        if level is Level.ERROR:
            self.get_logger().error(line)
        elif level is Level.WARN:
            self.get_logger().warning(line)
        else:
            self.get_logger().info(line)

    def _diagnostics(self, output: ControlOutput, now: float) -> DiagnosticArray:
        record = ControllerDiagnostics.from_output(
            output, state=self._state, state_time=self._state_time,
            failures_total=self.controller.solver_failures, blockage=self.blockage,
            timeouts_total=self.controller.timeouts)
        return diagnostic_array(name=f'{self.get_name()}: MPC',
                                hardware_id=self.get_fully_qualified_name(),
                                level=record.level, message=record.message,
                                values=record.to_values(),
                                stamp=seconds_to_stamp(max(now, 0.0)))
