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

"""unicycle_simulator: integrate cmd_vel with saturation, publish odom (and clock).

With ``publish_clock`` the node is the clock: each tick of a steady wall timer, fired at
``rate * real_time_factor`` Hz, advances simulated time by exactly ``1 / rate`` s, publishes
``clock`` and ``odom`` stamped with that time. Nodes with ``use_sim_time`` then run at
``real_time_factor`` times real time, and a slow tick slows the simulation down instead of
making it jump. Without it, the node integrates in ROS time (wall or an external clock).

``cmd_vel`` is a geometry_msgs/Twist, or a TwistStamped with ``enable_stamped_cmd_vel``
(Nav2's parameter; give the controller the same value). A cmd_vel older than ``cmd_timeout``
(a controller that died or hangs; the age counts from its arrival, stamped or not) is
replaced by zero, and so is one with NaN or inf in linear.x or angular.z (its sender is
broken: no part of it is trusted); the saturation bounds every command that is integrated.
"""

from __future__ import annotations

import math
import sys
from typing import Any

from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock as ClockMsg

from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.ros.conversions import seconds_to_stamp, state_to_odometry, u_from_twist
from mpc_local_planner.ros.node_main import run_node
from mpc_local_planner.ros.parameters import declare_parameters, ParameterSpec
from mpc_local_planner.ros.qos import CLOCK_QOS, CMD_VEL_QOS, ODOM_QOS
from mpc_local_planner.ros.throttle import ProblemThrottle

__all__ = ['PARAMETERS', 'SUMMARY', 'UnicycleSimulatorNode', 'main',
           'validate_simulator_parameters']


# At most this many integration steps catch up a late tick (real-time mode).
MAX_CATCH_UP_STEPS = 10
_MODEL = Unicycle()  # the single source of the saturation defaults

SUMMARY = ('Integrate a unicycle driven by cmd_vel (Twist, or TwistStamped with '
           'enable_stamped_cmd_vel) with saturation; publish odom, and clock with '
           'publish_clock.')

PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('initial_pose', [0.0, 0.0, 0.0],
                  'start pose [x, y, theta] (m, m, rad); read once at start'),
    ParameterSpec('rate', 50.0,
                  'integration rate in Hz of simulated time (one RK4 step of 1/rate per tick)',
                  float_range=(1.0, 1000.0)),
    ParameterSpec('cmd_timeout', 0.5,
                  'a cmd_vel older than this (s of simulated time) is replaced by zero; '
                  '0 = never', float_range=(0.0, 60.0)),
    ParameterSpec('enable_stamped_cmd_vel', False,
                  "subscribe cmd_vel as geometry_msgs/TwistStamped (Nav2's name); false = "
                  'Twist; read once at start', read_only=True),
    ParameterSpec('publish_clock', False,
                  'drive /clock from the simulation (other nodes then use_sim_time)',
                  read_only=True),
    ParameterSpec('real_time_factor', 1.0,
                  'simulated seconds per wall second when publish_clock is true',
                  float_range=(0.01, 100.0)),
    ParameterSpec('v_max', _MODEL.v_max, 'saturation of |linear.x| (m/s)',
                  float_range=(0.001, 10.0)),
    ParameterSpec('omega_max', _MODEL.omega_max, 'saturation of |angular.z| (rad/s)',
                  float_range=(0.001, 50.0)),
    ParameterSpec('frame_id', 'odom', 'odometry frame'),
    ParameterSpec('child_frame_id', 'base_link', 'robot frame'),
)


def validate_simulator_parameters(values: dict[str, Any]) -> str | None:
    """Return why the simulator's parameter values are invalid, or None."""
    pose = values.get('initial_pose')
    if pose is not None:
        pose = list(pose)
        if len(pose) != 3 or not all(math.isfinite(float(v)) for v in pose):
            return f'initial_pose must be [x, y, theta] (3 finite numbers), got {pose}'
    return None


class UnicycleSimulatorNode(Node):
    """Integrate a unicycle driven by cmd_vel; publish odom and optionally clock."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('unicycle_simulator', **kwargs)
        self.add_on_set_parameters_callback(self.parameters_callback)
        declare_parameters(self, PARAMETERS)
        self.add_post_set_parameters_callback(self.post_parameters_callback)
        pose = np.array(self.get_parameter('initial_pose').value, dtype=float)
        self._state = pose
        self._model = self._read_model()
        self._u = np.zeros(2)
        self._sim_time = 0.0
        self._last_cmd_time: float | None = None
        self._last_tick: float | None = None
        self._problems = ProblemThrottle(2.0)
        self._odom_pub = self.create_publisher(Odometry, 'odom', ODOM_QOS)
        self._clock_pub = self.create_publisher(ClockMsg, 'clock', CLOCK_QOS)
        cmd_type = TwistStamped if self.get_parameter('enable_stamped_cmd_vel').value else Twist
        self._cmd_sub = self.create_subscription(cmd_type, 'cmd_vel', self.cmd_vel_callback,
                                                 CMD_VEL_QOS)
        self._steady_clock = Clock(clock_type=ClockType.STEADY_TIME)
        self._timer = None
        self._make_timer()

    # ------------------------------------------------------------------ parameters
    def parameters_callback(self, parameters: list[Parameter]) -> SetParametersResult:
        """Refuse an initial_pose that is not three finite numbers."""
        values = {p.name: p.value for p in parameters}
        try:
            reason = validate_simulator_parameters(values)
        except (TypeError, ValueError) as err:
            reason = f'initial_pose must be [x, y, theta] (3 finite numbers): {err}'
        if reason is not None:
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def post_parameters_callback(self, parameters: list[Parameter]) -> None:
        """Apply new bounds and rates (rate changes restart the timer)."""
        names = {p.name for p in parameters}
        if names & {'v_max', 'omega_max'}:
            self._model = self._read_model()
        if names & {'rate', 'real_time_factor'}:
            self._make_timer()

    def _read_model(self) -> Unicycle:
        return Unicycle(v_max=float(self.get_parameter('v_max').value),
                        omega_max=float(self.get_parameter('omega_max').value))

    def _make_timer(self) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
        rate = float(self.get_parameter('rate').value)
        self._dt = 1.0 / rate
        if self.get_parameter('publish_clock').value:
            rtf = float(self.get_parameter('real_time_factor').value)
            self._timer = self.create_timer(self._dt / rtf, self.timer_callback,
                                            clock=self._steady_clock)
        else:
            self._timer = self.create_timer(self._dt, self.timer_callback)

    # ------------------------------------------------------------------ callbacks
    @property
    def state(self) -> np.ndarray:
        """The simulated state (x, y, theta), theta unwrapped."""
        return self._state.copy()

    @property
    def sim_time(self) -> float:
        """Simulated seconds so far (publish_clock mode)."""
        return self._sim_time

    def _now(self) -> float:
        if self.get_parameter('publish_clock').value:
            return self._sim_time
        return self.get_clock().now().nanoseconds * 1e-9

    def cmd_vel_callback(self, msg: Twist | TwistStamped) -> None:
        """Take the new command (saturated when integrated); a non-finite one means stop."""
        if isinstance(msg, TwistStamped):
            msg = msg.twist  # the same checks and timeout as a Twist
        raw = (msg.linear.x, msg.angular.z)
        if not all(math.isfinite(value) for value in raw):
            self._u = np.zeros(2)
            if self._problems.report('cmd_vel'):
                self.get_logger().error(
                    f'invalid cmd_vel: linear.x = {raw[0]}, angular.z = {raw[1]}; stopping')
        else:
            self._u = u_from_twist(msg)
            if self._problems.resolve('cmd_vel'):
                self.get_logger().info('cmd_vel is valid again')
        self._last_cmd_time = self._now()

    def timer_callback(self) -> None:
        """Advance the simulation and publish clock and odom."""
        try:
            if self.get_parameter('publish_clock').value:
                steps = 1
            else:
                now = self._now()
                last = self._last_tick if self._last_tick is not None else now - self._dt
                steps = min(max(int(round((now - last) / self._dt)), 0), MAX_CATCH_UP_STEPS)
                self._last_tick = last + steps * self._dt if steps else last
                if now - self._last_tick > MAX_CATCH_UP_STEPS * self._dt:
                    self._last_tick = now  # far behind (a clock jump): do not catch up
            u = self._u
            timeout = float(self.get_parameter('cmd_timeout').value)
            if timeout > 0 and (self._last_cmd_time is None
                                or self._now() - self._last_cmd_time > timeout):
                u = np.zeros(2)
            u = self._model.saturate(u)
            for _ in range(steps):
                self._state = self._model.step(self._state, u, self._dt)
                self._sim_time += self._dt
            publish_clock = self.get_parameter('publish_clock').value
            if publish_clock:
                stamp = seconds_to_stamp(self._sim_time)
            else:
                stamp = self.get_clock().now().to_msg()
            # odom before clock: a controller woken by the new time already has the state
            self._odom_pub.publish(state_to_odometry(
                self._state, u, stamp=stamp,
                frame_id=str(self.get_parameter('frame_id').value),
                child_frame_id=str(self.get_parameter('child_frame_id').value)))
            if publish_clock:
                self._clock_pub.publish(ClockMsg(clock=stamp))
        except Exception as err:  # never let a callback kill the executor
            if not self.context.ok():
                return  # Ctrl-C shut the context down during the step: not a failure
            self.get_logger().error(f'simulation step failed: {err}',
                                    throttle_duration_sec=1.0)


def main(args: list[str] | None = None) -> int:
    """Run the node until Ctrl-C (exit code 2, with the reason, on invalid parameters).

    ``--help`` prints the parameters and their defaults and starts nothing.
    """
    return run_node(UnicycleSimulatorNode, 'unicycle_simulator', args, summary=SUMMARY,
                    parameters=PARAMETERS)


if __name__ == '__main__':
    sys.exit(main())
