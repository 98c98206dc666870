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
"""unicycle_simulator takes cmd_vel as Twist or, with enable_stamped_cmd_vel, TwistStamped.

Both are handled alike: a valid command moves the robot, a non-finite one stops it with an
error, and silence longer than cmd_timeout (simulated time) stops it too.
"""

from __future__ import annotations

import math

from geometry_msgs.msg import PoseWithCovarianceStamped, Twist, TwistStamped
import pytest
from rcl_interfaces.msg import Log
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from mpc_local_planner.ros.conversions import twist_from_u, twist_stamped_from_u
from mpc_local_planner.ros.qos import CMD_VEL_QOS, LOCALIZER_QOS
from mpc_local_planner.ros.unicycle_simulator_node import LOCALIZER_TOPIC, UnicycleSimulatorNode

pytestmark = pytest.mark.slow  # topics over DDS

# Wall seconds before a condition counts as never reached.
TIMEOUT = 20.0
CMD_TIMEOUT = 0.5  # s of simulated time
ROSOUT_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)


@pytest.mark.parametrize(('stamped', 'msg_type'), [(False, Twist), (True, TwistStamped)],
                         ids=['Twist', 'TwistStamped'])
def test_the_simulator_takes_cmd_vel_of_the_configured_type_with_the_same_checks(
        ros, stamped, msg_type) -> None:
    sim = ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter('enable_stamped_cmd_vel', value=stamped),
        Parameter('publish_clock', value=True), Parameter('real_time_factor', value=10.0),
        Parameter('cmd_timeout', value=CMD_TIMEOUT)]))
    # not the conftest Probe: its Twist endpoints on cmd_vel would clash (one DDS participant
    # per context) with a TwistStamped publisher
    probe = ros.add(Node('commander', context=ros.context))
    cmd_pub = probe.create_publisher(msg_type, 'cmd_vel', CMD_VEL_QOS)
    errors: list[str] = []

    def rosout(entry: Log) -> None:
        if entry.name == 'unicycle_simulator' and entry.level == Log.ERROR:
            errors.append(entry.msg)

    probe.create_subscription(Log, '/rosout', rosout, ROSOUT_QOS)

    def simulator_type() -> list[str]:
        return [info.topic_type for info in probe.get_subscriptions_info_by_topic('/cmd_vel')
                if info.node_name == 'unicycle_simulator']

    expected = 'geometry_msgs/msg/TwistStamped' if stamped else 'geometry_msgs/msg/Twist'
    assert ros.spin_until(lambda: simulator_type() == [expected]
                          and cmd_pub.get_subscription_count() > 0, timeout=TIMEOUT)

    def command(v: float) -> Twist | TwistStamped:
        if stamped:
            return twist_stamped_from_u([v, 0.0], stamp=probe.get_clock().now().to_msg())
        return twist_from_u([v, 0.0])

    def drive(v: float, distance: float) -> None:
        x0 = sim.state[0]

        def moved() -> bool:
            cmd_pub.publish(command(v))
            return sim.state[0] - x0 >= distance

        assert ros.spin_until(moved, timeout=TIMEOUT)

    def stands_still_for(span: float) -> None:
        x, t = sim.state[0], sim.sim_time
        assert ros.spin_until(lambda: sim.sim_time - t >= span, timeout=TIMEOUT)
        assert sim.state[0] == x

    drive(0.2, 0.05)
    # NaN: stop at once, with an error
    cmd_pub.publish(command(math.nan))
    assert ros.spin_until(lambda: any('invalid cmd_vel' in line for line in errors),
                          timeout=TIMEOUT)
    stands_still_for(0.2)
    # valid again: moves; then silence beyond cmd_timeout: stops
    drive(0.2, 0.05)
    t_last = sim.sim_time
    assert ros.spin_until(lambda: sim.sim_time - t_last > CMD_TIMEOUT + 0.1, timeout=TIMEOUT)
    stands_still_for(0.2)


def test_drifting_odometry_and_the_localizer_stand_in(ros) -> None:
    """Drifting odometry and the localizer stand-in.

    5 % and 0.05 rad/m of drift: odometry says 1.05 m and 0.05 rad per true metre, while the
    localizer stand-in publishes the true pose (no noise here) in map at its rate.
    """
    sim = ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter('publish_clock', value=True), Parameter('real_time_factor', value=10.0),
        Parameter('cmd_timeout', value=0.0), Parameter('odom_drift.position', value=0.05),
        Parameter('odom_drift.heading', value=0.05), Parameter('localizer.rate', value=5.0),
        Parameter('localizer.noise_std', value=0.0)]))
    probe = ros.add(Node('commander', context=ros.context))
    cmd_pub = probe.create_publisher(Twist, 'cmd_vel', CMD_VEL_QOS)
    poses: list[PoseWithCovarianceStamped] = []
    probe.create_subscription(PoseWithCovarianceStamped, LOCALIZER_TOPIC, poses.append,
                              LOCALIZER_QOS)
    assert ros.spin_until(lambda: cmd_pub.get_subscription_count() > 0, timeout=TIMEOUT)
    cmd_pub.publish(twist_from_u([0.5, 0.0]))
    start = sim.sim_time
    assert ros.spin_until(lambda: sim.state[0] >= 1.0, timeout=TIMEOUT)
    cmd_pub.publish(twist_from_u([0.0, 0.0]))
    stopped = sim.sim_time

    def localized_standing() -> bool:  # a localizer pose of the robot standing still
        return (sim.sim_time - stopped > 0.5 and bool(poses)
                and poses[-1].pose.pose.position.x == sim.state[0])

    assert ros.spin_until(localized_standing, timeout=TIMEOUT)
    true, odom = sim.state, sim.odometry
    assert true[1] == 0.0 and true[2] == 0.0  # straight in truth
    assert odom[2] == pytest.approx(0.05 * true[0], rel=1e-6)  # 0.05 rad per metre
    # the odometry's path is an arc of length 1.05 x the true distance
    chord = 2 * (1.05 * true[0] / odom[2]) * math.sin(odom[2] / 2)
    assert math.hypot(odom[0], odom[1]) == pytest.approx(chord, rel=1e-3)
    last = poses[-1]
    assert last.header.frame_id == 'map'
    assert last.pose.pose.position.y == 0.0
    seconds = sim.sim_time - start
    assert len(poses) <= 5 * seconds + 2  # at localizer.rate
