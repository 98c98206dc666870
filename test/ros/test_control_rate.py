# SPDX-License-Identifier: Apache-2.0
"""mpc_controller's control timer at control_frequency, and its stops braking within max_decel.

The test owns simulated time (it publishes /clock) and plays the base: each tick it moves the
odometry along the latest cmd_vel (the unicycle's step) and publishes it with that twist, so
the controller sees a robot that drives as commanded. Every assertion is about ROS time.
"""

from __future__ import annotations

from typing import Callable

from conftest import SimClock
import numpy as np
import pytest
from rclpy.parameter import Parameter

from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import PlanSource
from mpc_local_planner.ros.conversions import (
    poses_to_path,
    seconds_to_stamp,
    state_to_odometry,
    u_from_twist,
)
from mpc_local_planner.ros.mpc_controller_node import MpcControllerNode
from mpc_local_planner.ros.node_main import autostart
from mpc_local_planner.worlds.world import paper_world

pytestmark = pytest.mark.dds  # DDS: the node spins in an rclpy context
WORLD = paper_world()
# A plan around the paper's box (above it), headings as the planner sends them.
PLAN = np.array([[0.0, 0.0, WORLD.start[2]], [0.8, 1.3, 0.0], [1.7, 1.3, -0.96],
                 [2.5, 0.0, WORLD.goal[2]]])
STEP = 0.2  # the MPC's default step h (s)
FREQUENCY = 20.0  # the default control_frequency (Hz)
DT = 0.01  # simulated seconds per test tick: a fifth of a control period


class Base(SimClock):
    """A base that follows cmd_vel exactly, publishing odometry, in the test's simulated time.

    Each tick (every DT) moves the pose along the latest cmd_vel (the unicycle) and publishes
    odometry (pose and twist) while `publishing`.
    """

    def __init__(self, ros, probe) -> None:
        super().__init__(ros, probe, dt=DT)
        self.state = WORLD.start.copy()
        self.model = Unicycle()
        self.publishing = True

    def command(self) -> np.ndarray:
        return u_from_twist(self.probe.cmds[-1]) if self.probe.cmds else np.zeros(2)

    def publish(self) -> None:
        u = self.command()
        self.state = np.asarray(self.model.step(self.state, u, DT), dtype=float).reshape(3)
        if self.publishing:
            self.probe.odom_pub.publish(state_to_odometry(self.state, u,
                                                          stamp=seconds_to_stamp(self.t)))

    def run_until(self, condition: Callable[[], bool], timeout: float = 60.0) -> bool:
        """Tick until condition() holds or timeout wall seconds pass; return condition()."""
        return super().run_until(condition, timeout)


def start(ros, **params) -> tuple[MpcControllerNode, object, Base]:
    """A controller in simulated time following PLAN, driving (a solver step with v > 0.1)."""
    overrides = [Parameter('use_sim_time', value=True),
                 Parameter('world_file', value='paper_obstacle.yaml')]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    node = ros.add(MpcControllerNode(context=ros.context, parameter_overrides=overrides))
    assert autostart(node) is None
    probe = ros.probe(use_sim_time=True)
    base = Base(ros, probe)
    assert ros.spin_until(lambda: probe.plan_pub.get_subscription_count() > 0
                          and probe.odom_pub.get_subscription_count() > 0)
    probe.plan_pub.publish(poses_to_path(PLAN))
    assert base.run_until(lambda: any(
        d.step.reason is Reason.TRACKING and d.step.source is PlanSource.SOLVER
        and d.step.v > 0.1 for d in probe.diagnostics))
    return node, probe, base


def test_the_timer_runs_at_control_frequency_and_the_mpc_solves_once_per_step(ros) -> None:
    node, probe, base = start(ros)
    assert node.control_period_ns == round(1e9 / FREQUENCY)
    first, since = len(probe.diagnostics), base.t
    span = 1.0  # simulated seconds counted: five steps, twenty control periods
    assert base.run_until(lambda: base.t >= since + span + 2 * DT)
    steps = [d for d in probe.diagnostics[first:] if since < d.stamp <= since + span]
    assert all(d.step.reason in (Reason.TRACKING, Reason.CANDIDATE) for d in steps), steps[-3:]
    # one cmd_vel per control period (the diagnostics go with it), about four per step h
    assert FREQUENCY * span - 2 <= len(steps) <= FREQUENCY * span + 1
    for k in range(int(span / STEP)):
        window = [d for d in steps if since + k * STEP < d.stamp <= since + (k + 1) * STEP]
        assert 3 <= len(window) <= 5, [d.stamp for d in window]
    # the MPC solved about once per step; the ticks between held its verified plan
    solved = [d for d in steps if d.step.solved]
    assert span / STEP - 1 <= len(solved) <= span / STEP + 1, [d.stamp for d in solved]
    gaps = np.diff([d.stamp for d in solved])
    np.testing.assert_allclose(gaps, STEP, atol=2 * DT + 1e-6)
    held = [d for d in steps if not d.step.solved]
    assert held and all(d.step.source is not None for d in held)  # they apply the held plan


def test_a_stale_odometry_stop_of_a_moving_robot_brakes_within_max_decel(ros) -> None:
    decel = (0.5, 1.0)  # gentle: the braking from cruise lasts several control periods
    _, probe, base = start(ros, max_decel=list(decel))
    assert base.run_until(lambda: base.command()[0] > 0.2)  # at speed
    first = len(probe.diagnostics)
    base.publishing = False  # the odometry stops; the base drives on as commanded

    def stale() -> list:
        return [d for d in probe.diagnostics[first:] if d.step.reason is Reason.STALE_ODOM]

    assert base.run_until(lambda: len(stale()) >= 2 and stale()[-1].step.v == 0.0)
    braking = stale()
    index = probe.diagnostics.index(braking[0])
    before = probe.diagnostics[index - 1].step
    speeds = np.array([d.step.v for d in braking])
    # the first stop command brakes: not zero at once, and not faster than before
    assert 0.0 < speeds[0] <= before.v + 1e-9
    # it comes down to zero, never above the speed it braked from, within the limit's time
    assert speeds[-1] == 0.0 and np.all(speeds <= speeds[0] + 1e-9)
    nonzero = int(np.count_nonzero(speeds))
    assert nonzero >= 2  # several control periods of braking, not one
    assert nonzero / FREQUENCY <= Unicycle().v_max / decel[0] + 2 / FREQUENCY
    # between two stop commands v falls at about max_decel at most (the brake's promise
    # along a plan whose inputs are held over each step)
    drops = -np.diff(speeds[:nonzero + 1])
    assert np.all(drops <= decel[0] / FREQUENCY * 3 + 1e-6), drops
