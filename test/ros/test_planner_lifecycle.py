# SPDX-License-Identifier: Apache-2.0
"""global_planner is a lifecycle node: every transition driven over DDS, as a manager would.

A probe node calls ``/global_planner/change_state`` and ``/global_planner/get_state``
(lifecycle_msgs) on a planner started with ``autostart:=false``, and watches ``plan``,
``odom``/``goal_pose`` and /rosout.
"""

from __future__ import annotations

import gc

from geometry_msgs.msg import PoseStamped
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
import numpy as np
import pytest
from rclpy.parameter import Parameter

from mpc_local_planner.ros.conversions import path_to_poses, yaw_to_quaternion
from mpc_local_planner.ros.global_planner_node import GlobalPlannerNode
from mpc_local_planner.worlds.world import paper_world

pytestmark = pytest.mark.dds  # lifecycle services and topics over DDS

WORLD = paper_world()
GOAL = [float(v) for v in WORLD.goal]
START = np.array([0.1, -0.2, 0.3])
EMPTY_WORLD = 'bounds: [-1, 3, -1, 3]\nobstacles: []\nstart: [0, 0, 0]\ngoal: [2, 2, 0]\n'
# Wall seconds a service call or a plan may take before the test fails.
TIMEOUT = 20.0


class Manager:
    """The lifecycle clients of a probe node, as nav2_lifecycle_manager uses them."""

    def __init__(self, ros, probe) -> None:
        self.ros = ros
        self.change = probe.create_client(ChangeState, '/global_planner/change_state')
        self.get = probe.create_client(GetState, '/global_planner/get_state')
        assert ros.spin_until(lambda: self.change.service_is_ready()
                              and self.get.service_is_ready(), timeout=TIMEOUT)

    def _call(self, client, request):
        future = client.call_async(request)
        self.ros.executor.spin_until_future_complete(future, timeout_sec=TIMEOUT)
        assert future.done(), f'no answer from {client.srv_name}'
        return future.result()

    def state(self) -> str:
        """Return the planner's state label ('unconfigured', 'inactive', ...)."""
        return self._call(self.get, GetState.Request()).current_state.label

    def transition(self, transition_id: int) -> bool:
        """Request a transition; return whether it succeeded."""
        request = ChangeState.Request()
        request.transition.id = transition_id
        return self._call(self.change, request).success


def planner_endpoints(probe) -> set[str]:
    """Return which of plan, odom and goal_pose the planner publishes or subscribes now."""
    endpoints = {
        'plan': probe.get_publishers_info_by_topic('/plan'),
        'odom': probe.get_subscriptions_info_by_topic('/odom'),
        'goal_pose': probe.get_subscriptions_info_by_topic('/goal_pose'),
    }
    return {topic for topic, infos in endpoints.items()
            if any(info.node_name == 'global_planner' for info in infos)}


ALL_ENDPOINTS = {'plan', 'odom', 'goal_pose'}


def goal_message(x: float, y: float, yaw: float) -> PoseStamped:
    goal = PoseStamped()
    goal.header.frame_id = 'map'
    goal.pose.position.x, goal.pose.position.y = x, y
    goal.pose.orientation = yaw_to_quaternion(yaw)
    return goal


def start(ros, **parameters):
    """Return the planner (autostart false), a probe and its manager."""
    overrides = [Parameter('autostart', value=False),
                 Parameter('world_file', value='paper_obstacle.yaml')]
    overrides += [Parameter(name, value=value) for name, value in parameters.items()]
    planner = ros.add(GlobalPlannerNode(context=ros.context, parameter_overrides=overrides))
    probe = ros.probe()
    return planner, probe, Manager(ros, probe)


def refused_while_inactive(ros, planner, probe, goal: PoseStamped) -> None:
    """Send odometry and goal to an inactive planner: it says so and publishes nothing."""
    plans, received = planner.plan_count, len(probe.raw_plans)
    before = len(probe.log_lines('global_planner'))

    def located() -> bool:
        probe.publish_odom(START)
        pose = planner.robot_pose
        return pose is not None and np.allclose(pose, START)

    assert ros.spin_until(located, timeout=TIMEOUT)
    probe.goal_pub.publish(goal)  # once: a goal still queued at activation would be planned
    assert ros.spin_until(lambda: any('the planner is inactive' in line for line in
                                      probe.log_lines('global_planner')[before:]),
                          timeout=TIMEOUT), probe.log_lines('global_planner')
    assert planner.plan_count == plans and len(probe.raw_plans) == received


def wait_for_plan(ros, planner, probe, count: int) -> np.ndarray:
    """Publish odometry until the count-th plan arrives; return its poses."""

    def planned() -> bool:
        probe.publish_odom(START)
        return len(probe.raw_plans) >= count

    assert ros.spin_until(planned, timeout=TIMEOUT), probe.log_lines('global_planner')
    assert len(probe.raw_plans) == count and planner.plan_count == count
    return path_to_poses(probe.plans[-1])


def test_the_planner_goes_through_every_transition_and_plans_only_while_active(ros) -> None:
    planner, probe, manager = start(ros, goal=GOAL)
    assert manager.state() == 'unconfigured'
    assert planner.planner is None and not planner_endpoints(probe)

    # configure: the planner, its publishers and subscriptions exist, but it does not plan
    assert manager.transition(Transition.TRANSITION_CONFIGURE)
    assert manager.state() == 'inactive' and planner.planner is not None
    assert ros.spin_until(lambda: planner_endpoints(probe) == ALL_ENDPOINTS)
    # odometry, the goal parameter and a goal_pose: still nothing on plan
    refused_while_inactive(ros, planner, probe, goal_message(2.5, 1.5, 1.0))
    np.testing.assert_allclose(planner.robot_pose, START)
    assert not probe.raw_plans

    # activate: the goal parameter is planned from the odometry
    assert manager.transition(Transition.TRANSITION_ACTIVATE)
    assert manager.state() == 'active'
    poses = wait_for_plan(ros, planner, probe, 1)
    np.testing.assert_allclose(poses[0], START, atol=1e-9)
    np.testing.assert_allclose(poses[-1], GOAL, atol=1e-9)
    # ... and goal_pose messages too
    probe.goal_pub.publish(goal_message(2.5, 1.5, 1.0))
    poses = wait_for_plan(ros, planner, probe, 2)
    np.testing.assert_allclose(poses[-1], [2.5, 1.5, 1.0], atol=1e-9)

    # deactivate: a new goal is not planned
    assert manager.transition(Transition.TRANSITION_DEACTIVATE)
    assert manager.state() == 'inactive' and planner.planner is not None
    refused_while_inactive(ros, planner, probe, goal_message(0.5, 1.0, 0.0))

    # cleanup: the planner is freed, the publishers and subscriptions are gone
    assert manager.transition(Transition.TRANSITION_CLEANUP)
    assert manager.state() == 'unconfigured'
    assert planner.planner is None and planner.robot_pose is None
    assert ros.spin_until(lambda: not planner_endpoints(probe))

    # configure and activate again: the goal parameter is planned again
    assert manager.transition(Transition.TRANSITION_CONFIGURE)
    assert manager.transition(Transition.TRANSITION_ACTIVATE)
    assert manager.state() == 'active'
    poses = wait_for_plan(ros, planner, probe, 3)
    np.testing.assert_allclose(poses[-1], GOAL, atol=1e-9)

    # shutdown from active: finalized, everything released
    assert manager.transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
    assert manager.state() == 'finalized'
    assert planner.planner is None and not planner.is_active
    assert ros.spin_until(lambda: not planner_endpoints(probe))


@pytest.mark.parametrize(('transitions', 'shutdown'), [
    ((), Transition.TRANSITION_UNCONFIGURED_SHUTDOWN),
    ((Transition.TRANSITION_CONFIGURE,), Transition.TRANSITION_INACTIVE_SHUTDOWN),
], ids=['unconfigured', 'inactive'])
def test_the_planner_shuts_down_from_unconfigured_and_inactive(ros, transitions,
                                                                 shutdown) -> None:
    planner, probe, manager = start(ros)
    for transition in transitions:
        assert manager.transition(transition)
    assert manager.transition(shutdown)
    assert manager.state() == 'finalized' and planner.planner is None
    assert ros.spin_until(lambda: not planner_endpoints(probe))


def test_a_configure_that_cannot_load_the_world_fails_and_the_planner_stays_unconfigured(
        ros, tmp_path) -> None:
    world = tmp_path / 'world.yaml'
    world.write_text(EMPTY_WORLD)
    planner, probe, manager = start(ros, world_file=str(world))
    world.unlink()  # valid when declared, gone when configured
    assert not manager.transition(Transition.TRANSITION_CONFIGURE)
    assert manager.state() == 'unconfigured' and planner.planner is None
    assert ros.spin_until(lambda: any('configure failed' in line for line in
                                      probe.log_lines('global_planner')))
    assert not planner_endpoints(probe)
    # the file is back: configure works
    world.write_text(EMPTY_WORLD)
    assert manager.transition(Transition.TRANSITION_CONFIGURE)
    assert manager.state() == 'inactive' and planner.planner is not None


def test_a_destroyed_planner_does_not_silence_the_rosout_of_a_later_one_of_the_same_name(
        ros) -> None:
    # rclpy 7.1 leaves a lifecycle node's rcl handle to the garbage collector; collected late,
    # it unregistered the /rosout publisher of the next node named global_planner
    old = GlobalPlannerNode(context=ros.context)
    old.destroy_node()
    del old
    planner = ros.add(GlobalPlannerNode(context=ros.context))
    probe = ros.probe()
    gc.collect()
    planner.get_logger().warning('still heard')
    assert ros.spin_until(lambda: 'still heard' in probe.log_lines('global_planner'),
                          timeout=TIMEOUT)
