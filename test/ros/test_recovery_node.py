# SPDX-License-Identifier: Apache-2.0
"""The controller node's recoveries: a forward-only robot stuck in a pocket backs out of it.

The test owns the clock and is the robot: each tick integrates the last cmd_vel (a unicycle)
and publishes the odometry. The node follows a plan straight into a pocket (its obstacles
from the world file) whose closed end the plan passes through: the MPC stops in front of the
end, where the Jackal's body fits and a turn in place does not, and stands there.
"""

from __future__ import annotations

import math
from pathlib import Path

from conftest import SimClock
import numpy as np
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter

from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet, polygon_separation
from mpc_local_planner.ros.conversions import poses_to_path, u_from_twist
from mpc_local_planner.ros.mpc_controller_node import MpcControllerNode
from mpc_local_planner.ros.node_main import autostart

# A pocket 0.7 m wide from x = 1.2, closed at x = 2.6: the Jackal (0.43 m wide) drives in with
# a 0.1 m margin at 0.2 m/s (the node reads the test's odometry a few ticks late, and the
# test's robot acts on a command a tick late); its 0.67 m circumscribed disc does not turn
# inside it.
POCKET = [(1.2, 0.35, 2.8, 0.5), (1.2, -0.5, 2.8, -0.35), (2.6, -0.5, 2.8, 0.5)]
MARGIN = 0.1
SPEED = 0.2
WORLD = """bounds: [-2.0, 4.0, -2.0, 2.0]
obstacles:
{boxes}
start: [0.0, 0.0, 0.0]
goal: [3.5, 0.0, 0.0]
""".format(boxes='\n'.join(f'  - box: [{a}, {b}, {c}, {d}]' for a, b, c, d in POCKET))
STUCK_TIMEOUT = 2.0  # s: short, so the test is


class DrivenClock(SimClock):
    """Simulated time whose robot moves as cmd_vel says (a unicycle, each tick)."""

    def __init__(self, ros, probe, dt: float = 0.05) -> None:
        super().__init__(ros, probe, dt=dt)
        self.pose = np.zeros(3)
        self.poses: list[np.ndarray] = []

    def publish(self) -> None:
        if self.probe.cmds:
            v, omega = u_from_twist(self.probe.cmds[-1])
            self.pose = self.pose + self.dt * np.array(
                [v * math.cos(self.pose[2]), v * math.sin(self.pose[2]), omega])
        self.poses.append(self.pose.copy())
        self.probe.publish_odom(self.pose, stamp=self.t)


def recovering(probe, text: str) -> list:
    return [d for d in probe.diagnostics
            if d.step.reason is Reason.RECOVERY and text in d.step.detail]


def test_a_forward_only_robot_stuck_in_a_pocket_backs_out_along_its_trail(ros, tmp_path: Path
                                                                            ) -> None:
    world = tmp_path / 'pocket.yaml'
    world.write_text(WORLD, encoding='utf-8')
    footprint = '[' + ', '.join(f'[{x}, {y}]' for x, y in JACKAL.vertices) + ']'
    node = ros.add(MpcControllerNode(context=ros.context, parameter_overrides=[
        Parameter('use_sim_time', value=True), Parameter('world_file', value=str(world)),
        Parameter('footprint', value=footprint), Parameter('allow_reversing', value=False),
        Parameter('budget', value='iterations'), Parameter('collision_margin', value=MARGIN),
        Parameter('v_max', value=SPEED),
        Parameter('recovery_stuck_timeout', value=STUCK_TIMEOUT)]))
    assert autostart(node) is None  # configure and activate, as run_node does
    probe = ros.probe(use_sim_time=True)
    clock = DrivenClock(ros, probe)
    assert ros.spin_until(lambda: probe.plan_pub.get_subscription_count() > 0
                          and probe.odom_pub.get_subscription_count() > 0)
    probe.plan_pub.publish(poses_to_path(np.array([[0.0, 0.0, 0.0], [3.5, 0.0, 0.0]])))
    clock.tick()

    # it drives into the pocket, stands in front of its end, then backs out
    assert clock.run_until(lambda: bool(recovering(probe, 'backing out')), timeout=120.0)
    recovery_start = len(clock.poses) - 1
    deepest = max(p[0] for p in clock.poses)
    assert deepest > 2.0
    assert clock.run_until(lambda: bool(recovering(probe, 'waiting for a new plan')),
                           timeout=120.0)
    backed = min(p[0] for p in clock.poses[int(np.argmax([p[0] for p in clock.poses])):])
    # out of the pocket, to where a turn in place is possible: the circumscribed disc 5 cm
    # clear of the pocket's mouth (its corners at x = 1.2, y = +-0.35), at x <= 1.05
    assert 0.6 < backed < 1.06
    reversing = [u_from_twist(c)[0] for c in probe.cmds if u_from_twist(c)[0] < 0.0]
    assert reversing and min(reversing) >= -SPEED - 1e-9  # the back-out's 0.25 m/s, capped
    # the back-out and the spin never took the body nearer the pocket's walls than it stood
    # (how near the MPC and the test's lagging robot brought it is not this test's), and
    # they ended clear of them
    walls = ObstacleSet([ConvexPolygon.from_box(*box) for box in POCKET])
    signed, _ = polygon_separation(Footprint.polygon(JACKAL.vertices).at_poses(
        np.array(clock.poses[recovery_start:])), walls)
    clearance = np.min(signed, axis=1)
    assert float(np.min(clearance)) >= min(float(clearance[0]), 0.0) - 1e-6
    assert float(clearance[-1]) > 0.05
    logged = [entry.msg for entry in probe.logs if entry.name == 'mpc_controller']
    assert any(f'no progress for {STUCK_TIMEOUT:g} s: recovery 1 of 3' in line
               for line in logged)
    assert any('recovery back_out' in line and 'a turn in place is possible' in line
               for line in logged)
    assert node.recoveries is not None and node.recoveries.started == 1

    # a new plan ends the wait: the MPC answers again
    probe.plan_pub.publish(poses_to_path(np.array([[clock.pose[0], clock.pose[1], 0.0],
                                                   [clock.pose[0], -1.5, -math.pi / 2]])))
    after = len(probe.diagnostics)
    assert clock.run_until(lambda: any(d.step.reason is not Reason.RECOVERY
                                       for d in probe.diagnostics[after:]), timeout=60.0)
    assert not any(entry.level == Log.ERROR for entry in probe.logs
                   if entry.name == 'mpc_controller')
