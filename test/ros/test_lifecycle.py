# SPDX-License-Identifier: Apache-2.0
"""The controller as a lifecycle node: every transition over DDS, its markers and options.

The transitions are requested as a lifecycle manager (or ``ros2 lifecycle set``) does:
through ``mpc_controller/change_state`` and ``mpc_controller/get_state`` from another node.
The test owns simulated time, so "silent" means: the clock went on for several control
periods and no control step ran.
"""

from __future__ import annotations

import gc
import math
import os
import subprocess
import sys
import weakref

from conftest import SimClock
from geometry_msgs.msg import PolygonStamped, TwistStamped
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from visualization_msgs.msg import Marker, MarkerArray

from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.ros.conversions import poses_to_path, u_from_twist
from mpc_local_planner.ros.mpc_controller_node import FOOTPRINT_TOPIC, MpcControllerNode
from mpc_local_planner.ros.mpc_controller_outputs import OBSTACLES_TOPIC
from mpc_local_planner.ros.node_main import autostart
from mpc_local_planner.ros.qos import CMD_VEL_QOS, LOCAL_PLAN_QOS
from mpc_local_planner.worlds.world import paper_world

pytestmark = pytest.mark.dds  # DDS, and a node process
WORLD = paper_world()
# A plan around the paper's box (above it), headings as the planner sends them.
PLAN = np.array([[0.0, 0.0, WORLD.start[2]], [0.8, 1.3, 0.0], [1.7, 1.3, -0.96],
                 [2.5, 0.0, WORLD.goal[2]]])
STEP = 0.2  # the prediction step h, and the control period these tests run the node at (s)
TICK = 0.05  # simulated seconds per tick of the test's clock
QUIET_PERIODS = 5  # control periods of simulated time that must pass in silence


class LifecycleProbe(Node):
    """Ask a lifecycle node for transitions over its services; keep markers and footprints."""

    def __init__(self, context, target: str = 'mpc_controller') -> None:
        super().__init__('lifecycle_probe', context=context)
        self.change_client = self.create_client(ChangeState, f'/{target}/change_state')
        self.state_client = self.create_client(GetState, f'/{target}/get_state')
        self.markers: list[MarkerArray] = []
        self.footprints: list[PolygonStamped] = []
        self.create_subscription(MarkerArray, OBSTACLES_TOPIC, self.markers.append,
                                 LOCAL_PLAN_QOS)
        self.create_subscription(PolygonStamped, FOOTPRINT_TOPIC, self.footprints.append,
                                 LOCAL_PLAN_QOS)


def call(ros, client, request):
    """Call a service over DDS and spin until the answer comes."""
    assert ros.spin_until(client.service_is_ready)
    future = client.call_async(request)
    assert ros.spin_until(future.done, timeout=60.0)
    return future.result()


def change_state(ros, probe: LifecycleProbe, transition: int) -> bool:
    return call(ros, probe.change_client,
                ChangeState.Request(transition=Transition(id=transition))).success


def get_state(ros, probe: LifecycleProbe) -> str:
    return call(ros, probe.state_client, GetState.Request()).current_state.label


class Clock(SimClock):
    """The test's simulated time (conftest's SimClock): each tick publishes odometry."""

    def __init__(self, ros, probe) -> None:
        super().__init__(ros, probe, dt=TICK)
        self.odom = np.array(WORLD.start, dtype=float)

    def publish(self) -> None:
        self.probe.publish_odom(self.odom, stamp=self.t)


def published(node: Node) -> set[str]:
    """The topics node itself publishes (from the ROS graph)."""
    return {name for name, _ in node.get_publisher_names_and_types_by_node(
        node.get_name(), node.get_namespace())}


def subscribed(node: Node) -> set[str]:
    """The topics node itself subscribes to (from the ROS graph)."""
    return {name for name, _ in node.get_subscriber_names_and_types_by_node(
        node.get_name(), node.get_namespace())}


def is_zero(twist) -> bool:
    return twist.linear.x == 0.0 and twist.angular.z == 0.0


def driving(probe) -> bool:
    return any(c.linear.x > 0.01 for c in probe.cmds)


def test_every_lifecycle_transition_over_dds_and_what_each_state_publishes(ros) -> None:
    # one control tick per step h, as the test's clock steps (the 20 Hz ticks between solves
    # are test_control_rate.py's): the counts below are per step
    node = ros.add(MpcControllerNode(context=ros.context, parameter_overrides=[
        Parameter('use_sim_time', value=True), Parameter('autostart', value=False),
        Parameter('world_file', value='paper_obstacle.yaml'),
        Parameter('control_frequency', value=1.0 / STEP)]))
    lifecycle = ros.add(LifecycleProbe(ros.context))
    probe = ros.probe(use_sim_time=True)
    clock = Clock(ros, probe)

    # unconfigured: parameters only, no controller, nothing subscribed
    assert get_state(ros, lifecycle) == 'unconfigured'
    assert node.controller is None
    assert '/cmd_vel' not in published(node) and '/plan' not in subscribed(node)

    # configure -> inactive: odometry and the plan are taken in, nothing is published
    assert change_state(ros, lifecycle, Transition.TRANSITION_CONFIGURE)
    assert get_state(ros, lifecycle) == 'inactive'
    assert node.controller is not None
    assert ros.spin_until(lambda: {'/plan', '/odom'} <= subscribed(node)
                          and probe.count_publishers('cmd_vel') == 2)
    probe.plan_pub.publish(poses_to_path(PLAN))
    assert clock.run_until(lambda: node.controller.path is not None)
    clock.run_for(QUIET_PERIODS * STEP)
    assert node.control_steps == 0 and node.last_output is None
    assert probe.cmds == [] and probe.diagnostics == [] and probe.local_plans == []
    assert lifecycle.markers == [] and lifecycle.footprints == []

    # activate -> active: the control timer runs, cmd_vel flows
    assert change_state(ros, lifecycle, Transition.TRANSITION_ACTIVATE)
    assert get_state(ros, lifecycle) == 'active'
    assert clock.run_until(lambda: driving(probe))
    assert node.last_output.reason is Reason.TRACKING

    # deactivate -> inactive: exactly one zero cmd_vel, then silence
    assert change_state(ros, lifecycle, Transition.TRANSITION_DEACTIVATE)
    assert get_state(ros, lifecycle) == 'inactive'
    steps = node.control_steps
    expected = steps + 1  # one per control step, and the zero
    assert ros.spin_until(lambda: len(probe.cmds) >= expected)
    assert is_zero(probe.cmds[-1]) and not is_zero(probe.cmds[-2])
    clock.run_for(QUIET_PERIODS * STEP)
    assert node.control_steps == steps
    assert len(probe.cmds) == expected

    # cleanup -> unconfigured: the controller and its NLP are freed, subscriptions gone
    mpc = weakref.ref(node.controller.mpc)
    assert change_state(ros, lifecycle, Transition.TRANSITION_CLEANUP)
    assert get_state(ros, lifecycle) == 'unconfigured'
    assert node.controller is None
    gc.collect()
    assert mpc() is None
    assert ros.spin_until(lambda: not {'/plan', '/odom'} & subscribed(node)
                          and not {'/cmd_vel', '/mpc/obstacles'} & published(node))

    # configure again (the latched plan comes again) -> activate -> driving again
    assert change_state(ros, lifecycle, Transition.TRANSITION_CONFIGURE)
    assert get_state(ros, lifecycle) == 'inactive'
    assert clock.run_until(lambda: node.controller.path is not None)
    assert ros.spin_until(lambda: probe.count_publishers('cmd_vel') == 2)
    assert change_state(ros, lifecycle, Transition.TRANSITION_ACTIVATE)
    before = len(probe.cmds)
    assert clock.run_until(lambda: any(c.linear.x > 0.01 for c in probe.cmds[before:]))

    # shutdown from active -> finalized: one zero cmd_vel, everything freed
    steps = node.control_steps
    assert change_state(ros, lifecycle, Transition.TRANSITION_ACTIVE_SHUTDOWN)
    assert get_state(ros, lifecycle) == 'finalized'
    assert node.controller is None
    expected = before + steps + 1
    assert ros.spin_until(lambda: len(probe.cmds) >= expected)
    assert len(probe.cmds) == expected and is_zero(probe.cmds[-1])


def test_a_configure_that_cannot_read_the_world_fails_and_the_node_stays_unconfigured(
        ros, tmp_path) -> None:
    world = tmp_path / 'world.yaml'
    good = ('bounds: [-5, 5, -5, 5]\nobstacles:\n  - box: [1, -1, 1.5, 1]\n'
            'start: [0.0, 0.0, 0.0]\ngoal: [2.5, 0.0, 0.0]\n')
    world.write_text(good)
    node = ros.add(MpcControllerNode(context=ros.context, parameter_overrides=[
        Parameter('world_file', value=str(world)), Parameter('autostart', value=False)]))
    lifecycle = ros.add(LifecycleProbe(ros.context))
    world.write_text('bounds: [0, 1\n')  # broken after the parameter was accepted
    assert not change_state(ros, lifecycle, Transition.TRANSITION_CONFIGURE)
    assert get_state(ros, lifecycle) == 'unconfigured'
    assert node.controller is None
    world.write_text(good)
    assert change_state(ros, lifecycle, Transition.TRANSITION_CONFIGURE)
    assert get_state(ros, lifecycle) == 'inactive'
    assert len(node.controller.obstacles) == 1


def test_a_destroyed_controller_leaves_rosout_to_the_next_one_of_its_name(ros) -> None:
    context = Context()
    rclpy.init(context=context)
    try:
        old = MpcControllerNode(context=context, parameter_overrides=[
            Parameter('autostart', value=False)])
        old.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    node = ros.add(MpcControllerNode(context=ros.context))
    probe = ros.probe()
    del old
    gc.collect()  # what is left of the old node must not unregister the new one's /rosout
    assert autostart(node) is None
    assert ros.spin_until(lambda: any(line.startswith('configured')
                                      for line in probe.log_lines('mpc_controller')))


def test_markers_show_the_obstacles_raw_grown_and_active_and_the_footprint_follows_odom(
        ros) -> None:
    radius = 0.1
    node = ros.add(MpcControllerNode(context=ros.context, parameter_overrides=[
        Parameter('use_sim_time', value=True), Parameter('robot_radius', value=radius),
        Parameter('world_file', value='paper_obstacle.yaml'),
        Parameter('control_frequency', value=1.0 / STEP)]))  # a tick per clock step
    assert autostart(node) is None
    lifecycle = ros.add(LifecycleProbe(ros.context))
    probe = ros.probe(use_sim_time=True)
    clock = Clock(ros, probe)
    # along the box's top, just outside it as the MPC grows it: the box is in the NLP
    clock.odom = np.array([0.9, 1.15, 0.0])
    probe.plan_pub.publish(poses_to_path(np.array([[0.5, 1.15, 0.0], [2.0, 1.15, 0.0]])))

    def namespaces(array: MarkerArray) -> set[str]:
        return {m.ns for m in array.markers if m.action == Marker.ADD}

    assert clock.run_until(lambda: any('active' in namespaces(a) for a in lifecycle.markers)
                           and lifecycle.footprints)
    array = next(a for a in lifecycle.markers if 'active' in namespaces(a))
    assert array.markers[0].action == Marker.DELETEALL
    by_ns = {ns: [m for m in array.markers if m.ns == ns] for ns in ('raw', 'grown', 'active')}
    assert [len(v) for v in by_ns.values()] == [1, 1, 1]
    grown = node.controller.grown_obstacles[0].vertices
    for ns, vertices in (('raw', WORLD.obstacles[0].vertices), ('grown', grown),
                         ('active', grown)):
        marker = by_ns[ns][0]
        assert marker.type == Marker.LINE_STRIP and marker.header.frame_id == 'map'
        points = np.array([[p.x, p.y] for p in marker.points])
        np.testing.assert_allclose(points, np.vstack([vertices, vertices[:1]]), atol=1e-6)
    assert by_ns['active'][0].color != by_ns['grown'][0].color
    # grown by the robot radius plus the collision margin (v_max step / 2 by default)
    margin = node.controller.config.inflation(node.controller.model.v_max)
    assert margin == pytest.approx(radius + 0.31 * STEP / 2)
    np.testing.assert_allclose(grown.min(axis=0), [1.0 - margin, -1.0 - margin])

    footprint = lifecycle.footprints[-1]
    assert footprint.header.frame_id == 'map'
    corners = np.array([[p.x, p.y] for p in footprint.polygon.points])
    assert len(corners) == 16
    distances = np.hypot(*(corners - clock.odom[:2]).T)
    np.testing.assert_allclose(distances, radius / math.cos(math.pi / 16), atol=1e-6)


def test_enable_stamped_cmd_vel_publishes_twist_stamped_in_base_link(ros) -> None:
    node = ros.add(MpcControllerNode(context=ros.context, parameter_overrides=[
        Parameter('enable_stamped_cmd_vel', value=True),
        Parameter('world_file', value='paper_obstacle.yaml')]))
    assert autostart(node) is None
    listener = ros.add(Node('stamped_listener', context=ros.context))
    received: list[TwistStamped] = []
    listener.create_subscription(TwistStamped, 'cmd_vel', received.append, CMD_VEL_QOS)
    assert ros.spin_until(lambda: len(received) >= 2)  # no plan: zero, stamped
    for msg in received:
        assert msg.header.frame_id == 'base_link'
        assert msg.header.stamp.sec > 0
        np.testing.assert_array_equal(u_from_twist(msg.twist), [0.0, 0.0])
    assert node.last_output.reason is Reason.NO_PLAN


def test_help_lists_the_parameters_with_defaults_starts_nothing_and_exits_0(tmp_path) -> None:
    env = dict(os.environ, ROS_LOG_DIR=str(tmp_path / 'ros_log'), ROS_HOME=str(tmp_path))
    work = tmp_path / 'work'
    work.mkdir()
    result = subprocess.run(
        [sys.executable, '-m', 'mpc_local_planner.ros.mpc_controller_node', '--help'],
        cwd=work, env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith('usage: mpc_controller')
    lines = {line.split()[0]: line for line in result.stdout.splitlines()
             if line.startswith('  ')}
    assert lines['horizon'].split()[1] == '10'
    assert lines['autostart'].split()[1] == 'true:'
    assert lines['enable_stamped_cmd_vel'].split()[1] == 'false:'
    assert 'mpc/obstacles' in result.stdout and result.stderr == ''
    assert sorted(p.name for p in tmp_path.iterdir()) == ['work']
    assert list(work.iterdir()) == []
