# SPDX-License-Identifier: Apache-2.0
"""The nodes with a localizer: they wait for it, then act on the pose in map.

The odometry is offset from the true pose by a known map <- odom correction (as drifted
odometry is); the localizer gives the true pose. Without the correction the robot would
follow the plan displaced by the offset.
"""

from __future__ import annotations

import math
from typing import Callable

from conftest import SimClock
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
import numpy as np
import pytest
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter

from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.perception.localization import compose, invert
from mpc_local_planner.ros.conversions import (
    path_to_poses,
    poses_to_path,
    seconds_to_stamp,
    stamp_to_seconds,
    u_from_twist,
    yaw_to_quaternion,
)
from mpc_local_planner.ros.global_planner_node import GlobalPlannerNode
from mpc_local_planner.ros.mpc_controller_node import MpcControllerNode
from mpc_local_planner.ros.node_main import autostart
from mpc_local_planner.ros.qos import LOCALIZER_QOS
from mpc_local_planner.worlds.world import paper_world

pytestmark = pytest.mark.dds  # DDS

WORLD = paper_world()
# A plan around the paper's box (above it), as test_reliability's.
PLAN = np.array([[0.0, 0.0, WORLD.start[2]], [0.8, 1.3, 0.0], [1.7, 1.3, -0.96],
                 [2.5, 0.0, WORLD.goal[2]]])
# map <- odom: where the drifted odometry's origin is in map.
DRIFT = np.array([0.3, -0.2, 0.1])
NO_POSE = "no pose in the plan's frame"


class DriftingRobot(SimClock):
    """A unicycle driven by cmd_vel in simulated time; odometry = inverse(DRIFT) * truth.

    Each tick integrates the latest command over dt and publishes the odometry.
    """

    def __init__(self, ros, probe, dt: float = 0.05) -> None:
        super().__init__(ros, probe, dt=dt)
        self.truth = np.array(WORLD.start[:3], dtype=float)
        self.localizer = probe.create_publisher(PoseWithCovarianceStamped, 'amcl_pose',
                                                LOCALIZER_QOS)

    @property
    def odometry(self) -> np.ndarray:
        return compose(invert(DRIFT), self.truth)

    def publish(self) -> None:
        v, omega = u_from_twist(self.probe.cmds[-1]) if self.probe.cmds else (0.0, 0.0)
        x, y, theta = self.truth
        self.truth = np.array([x + v * math.cos(theta) * self.dt,
                               y + v * math.sin(theta) * self.dt, theta + omega * self.dt])
        self.probe.publish_odom(self.odometry, stamp=self.t)

    def localize(self) -> None:
        """Publish the true pose in map, stamped now (odometry of that stamp is kept)."""
        msg = PoseWithCovarianceStamped()
        msg.header.frame_id = 'map'
        msg.header.stamp = seconds_to_stamp(self.t)
        msg.pose.pose.position.x, msg.pose.pose.position.y = map(float, self.truth[:2])
        msg.pose.pose.orientation = yaw_to_quaternion(float(self.truth[2]))
        self.localizer.publish(msg)

    def run_until(self, condition: Callable[[], bool], timeout: float = 60.0,
                  localize_every: int = 0) -> bool:
        """Tick until condition() holds (see SimClock), localizing every localize_every ticks."""
        ticks = 0

        def tick() -> None:
            nonlocal ticks
            self.tick()
            ticks += 1
            if localize_every and ticks % localize_every == 0:
                self.localize()

        return self.ros.tick_until(tick, condition, timeout)


def start_localized_controller(ros, **params) -> tuple[MpcControllerNode, object,
                                                           DriftingRobot]:
    """A controller in simulated time on amcl_pose's localizer, given PLAN (params override)."""
    overrides = [Parameter('use_sim_time', value=True),
                 Parameter('world_file', value='paper_obstacle.yaml'),
                 Parameter('localization_topic', value='amcl_pose')]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    node = ros.add(MpcControllerNode(context=ros.context, parameter_overrides=overrides))
    assert autostart(node) is None
    probe = ros.probe(use_sim_time=True)
    robot = DriftingRobot(ros, probe)
    assert ros.spin_until(lambda: probe.plan_pub.get_subscription_count() > 0
                          and robot.localizer.get_subscription_count() > 0)
    probe.plan_pub.publish(poses_to_path(PLAN))
    return node, probe, robot


def test_the_controller_stops_until_the_localizer_speaks_then_follows_the_plan_in_map(
        ros, throttle_clock) -> None:
    node, probe, robot = start_localized_controller(ros)

    # odometry and a plan, no localizer yet: zero commands, the reason said, one error

    def waiting() -> list:
        return [d for d in probe.diagnostics if d.message.startswith(NO_POSE)]

    def errors() -> list[str]:
        return [line for line in probe.log_lines('mpc_controller', Log.ERROR)
                if NO_POSE in line]

    assert robot.run_until(lambda: len(waiting()) >= 5 and errors())
    assert all(d.step.reason is Reason.NO_LOCALIZATION for d in waiting())
    assert "no localizer pose yet on 'amcl_pose'" in waiting()[0].message
    assert all(not u_from_twist(c).any() for c in probe.cmds)
    assert len(errors()) == 1  # the throttle's clock is held
    assert 'zero' in errors()[0]

    # the localizer's first pose: the controller tracks from the true pose, not the odometry
    robot.localize()
    start = len(probe.diagnostics)
    assert robot.run_until(lambda: any(d.step.reason is Reason.TRACKING
                                       for d in probe.diagnostics[start:]))
    tracked = next(d for d in probe.diagnostics[start:] if d.step.reason is Reason.TRACKING)
    np.testing.assert_allclose([tracked.step.x, tracked.step.y], robot.truth[:2], atol=0.05)
    assert np.hypot(*(robot.odometry[:2] - robot.truth[:2])) > 0.2  # the drift is visible
    assert ros.spin_until(lambda: probe.local_plans)
    first = path_to_poses(probe.local_plans[-1])[0]
    assert probe.local_plans[-1].header.frame_id == 'map'
    np.testing.assert_allclose(first[:2], robot.truth[:2], atol=0.1)

    # with the localizer at 2 Hz the robot reaches the plan's end in map
    def arrived() -> bool:
        return node.goal_reached

    assert robot.run_until(arrived, timeout=120.0, localize_every=10), probe.diagnostics[-1:]
    assert np.hypot(*(robot.truth[:2] - PLAN[-1, :2])) < 0.15
    assert np.hypot(*(robot.odometry[:2] - PLAN[-1, :2])) > 0.2  # the odometry is not there


def test_the_planner_waits_for_the_localizer_then_plans_from_the_pose_in_map(ros) -> None:
    planner = ros.add(GlobalPlannerNode(context=ros.context, parameter_overrides=[
        Parameter('world_file', value='paper_obstacle.yaml'),
        Parameter('localization_topic', value='amcl_pose')]))
    assert autostart(planner) is None
    probe = ros.probe()
    localizer = probe.create_publisher(PoseWithCovarianceStamped, 'amcl_pose', LOCALIZER_QOS)
    assert ros.spin_until(lambda: probe.goal_pub.get_subscription_count() > 0
                          and localizer.get_subscription_count() > 0)
    truth = np.array(WORLD.start[:3], dtype=float)
    odometry = compose(invert(DRIFT), truth)
    goal = PoseStamped()
    goal.header.frame_id = 'map'
    goal.pose.position.x, goal.pose.position.y = map(float, WORLD.goal[:2])
    goal.pose.orientation = yaw_to_quaternion(float(WORLD.goal[2]))

    def odometry_kept() -> bool:
        probe.publish_odom(odometry)
        return planner.odom_state is not None  # the odometry came; no pose in map yet

    assert ros.spin_until(odometry_kept)
    assert planner.robot_pose is None
    probe.goal_pub.publish(goal)
    assert ros.spin_until(lambda: any(NO_POSE in line for line in
                                      probe.log_lines('global_planner', Log.WARN)))
    assert planner.plan_count == 0  # the goal waits

    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = 'map'
    msg.header.stamp = probe.get_clock().now().to_msg()
    msg.pose.pose.position.x, msg.pose.pose.position.y = map(float, truth[:2])
    msg.pose.pose.orientation = yaw_to_quaternion(float(truth[2]))

    def planned() -> bool:
        probe.publish_odom(odometry, stamp=stamp_to_seconds(msg.header.stamp))
        localizer.publish(msg)
        return planner.plan_count > 0 and bool(probe.raw_plans)

    assert ros.spin_until(planned, timeout=20.0)
    np.testing.assert_allclose(planner.robot_pose, truth, atol=1e-9)
    start = path_to_poses(probe.plans[-1])[0]
    np.testing.assert_allclose(start[:2], truth[:2], atol=1e-6)


def test_the_controller_stops_when_the_localizer_falls_silent_while_moving_then_drives_on(
        ros, throttle_clock) -> None:
    node, probe, robot = start_localized_controller(ros, localization_max_travel=0.3)
    for _ in range(5):  # odometry kept for the localizer's stamp
        robot.tick()
    robot.localize()  # once: then silent, as a dead AMCL

    def silent() -> list:
        return [d for d in probe.diagnostics if 'silent or lost' in d.message]

    def errors() -> list[str]:
        return [line for line in probe.log_lines('mpc_controller', Log.ERROR)
                if 'silent or lost' in line]

    # /rosout is a topic of its own: its line may arrive after the diagnostics
    assert robot.run_until(lambda: len(silent()) >= 3 and errors())
    assert all(d.step.reason is Reason.NO_LOCALIZATION for d in silent())
    assert 'localization_max_travel 0.3' in silent()[0].message
    assert 'zero' in errors()[0]
    # it brakes to a stop and stays there: nothing moves it while the localizer is silent
    assert robot.run_until(lambda: probe.cmds and not u_from_twist(probe.cmds[-1]).any())
    stopped = robot.truth.copy()
    for _ in range(20):
        robot.tick()
    np.testing.assert_allclose(robot.truth, stopped, atol=1e-9)
    # the localizer speaks again: the controller drives on from the corrected pose
    robot.localize()
    start = len(probe.diagnostics)
    assert robot.run_until(lambda: any(d.step.reason is Reason.TRACKING
                                       for d in probe.diagnostics[start:]))

    def recovered() -> list[str]:
        return [line for line in probe.log_lines('mpc_controller', Log.INFO)
                if "a pose in the plan's frame again" in line]

    # the recovery's line (the second: one came at the start) follows every error line on
    # the node's one reliable /rosout publisher, so all of them are in: one, for the
    # throttle's clock is held
    assert robot.run_until(lambda: len(recovered()) >= 2)
    assert len(errors()) == 1
