# SPDX-License-Identifier: Apache-2.0
"""The global_planner node and the evaluation's Navigator re-plan alike (core/replanning.py).

Both are driven with one scripted fake planner (blocked or not, failing or not, at given
times) and the same times: the node's checks at its timer's ticks, the Navigator's at its
control steps, one per check period. They must make the same decisions, ask the planner
with the same seed offsets, and count the same.
"""

from __future__ import annotations

from typing import Any, Sequence

from conftest import SimClock
from geometry_msgs.msg import PoseStamped
import numpy as np
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter
from rclpy.time import Time

from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.diagnostics import PlanTrigger
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.replanning import (
    PROGRESS_ANGLE,
    PROGRESS_RADIUS,
    PROGRESS_TIMEOUT,
    Replanner,
    ReplanOutcome,
    ReplanSettings,
)
from mpc_local_planner.evaluation.navigation import NavigationSettings, Navigator
from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.ros.conversions import (
    seconds_to_stamp,
    state_to_odometry,
    yaw_to_quaternion,
)
from mpc_local_planner.ros.global_planner_node import GlobalPlannerNode
from mpc_local_planner.ros.node_main import autostart

CHECK_PERIOD = 0.5  # the node's default replan_check_rate, 2 Hz
REPLAN_PERIOD = 2.0
POSE = np.array([1.0, 1.0, 0.0])
GOAL = np.array([4.0, 1.0, 0.0])
# time of a check -> (rest blocked, planning fails); the goal is planned at 0 s
SCRIPT = {
    1.0: (True, True),
    1.5: (True, True),
    2.0: (True, False),
    3.0: (True, True),
    3.5: (False, True),  # clear, no periodic re-plan due (the plan is from 2 s)
    4.0: (False, True),  # periodic, fails
    4.5: (False, False),  # periodic, made
    5.0: (True, True),
}
TIMES = [CHECK_PERIOD * k for k in range(1, 13)]


class ScriptedPlanner:
    """A planner that is blocked or fails when SCRIPT says so, at the time the test sets."""

    def __init__(self) -> None:
        self.now = 0.0
        self.calls: list[tuple[float, str, int]] = []

    def _path(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        if SCRIPT.get(self.now, (False, False))[1]:
            problem = f'no path at {self.now} s'
            raise PlanningError(problem)
        return np.array([start[:2], [2.5, 1.0 + self.now], goal[:2]])

    def plan(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        self.calls.append((self.now, 'plan', 0))
        return self._path(start, goal)

    def replan(self, start: np.ndarray, goal: np.ndarray, *, failures: int = 0,
               grid: Any = None, escape_distance: float = 1.0,
               local_obstacles: Sequence[Any] = ()) -> np.ndarray:
        self.calls.append((self.now, 'replan', failures))
        return self._path(start, goal)

    def rest_problem(self, plan: np.ndarray, position: Sequence[float]) -> str | None:
        return 'blocked' if SCRIPT.get(self.now, (False, False))[0] else None


def record(replanner: Replanner, decisions: list) -> None:
    """Record (outcome, trigger) of every decision the re-planner makes."""
    for name in ('plan_goal', 'check'):
        method = getattr(replanner, name)

        def wrapped(*args: Any, _method: Any = method, **kwargs: Any) -> Any:
            decision = _method(*args, **kwargs)
            if decision.outcome is not ReplanOutcome.NOT_DUE:
                decisions.append((decision.outcome, decision.trigger))
            return decision

        setattr(replanner, name, wrapped)


class StillLocal:
    """A local controller that stands still and keeps the plans it is given."""

    def __init__(self) -> None:
        self.plans: list[np.ndarray] = []

    def set_plan(self, poses: np.ndarray) -> None:
        self.plans.append(poses)

    def set_obstacles(self, obstacles: Sequence[Any]) -> None:
        pass

    def compute(self, pose: np.ndarray | None, twist: np.ndarray | None,
                now: float) -> ControlOutput:
        return ControlOutput(np.zeros(2), None, Reason.TRACKING, compute_time_s=0.0)

    def reset(self) -> None:
        self.plans.clear()

    def set_speed_limit(self, v_max: float | None) -> None:
        pass


class NoGrid:
    """A grid the scans go into and nothing comes out of."""

    def add_scan(self, scan: Any, pose: Sequence[float], *, body: Any = None) -> None:
        pass


def run_navigator() -> tuple[Navigator, ScriptedPlanner, list]:
    planner = ScriptedPlanner()
    settings = NavigationSettings(beams=16, replan_check_period=CHECK_PERIOD,
                                  replan_period=REPLAN_PERIOD)
    navigator = Navigator(StillLocal(), TrueGeometry([]), NoGrid(), planner, GOAL,
                          reach=1.0, h=CHECK_PERIOD, settings=settings)
    decisions: list = []
    record(navigator.replanner, decisions)
    for t in [0.0, *TIMES]:
        planner.now = t
        navigator.step(POSE)
    return navigator, planner, decisions


def goal_pose(goal: np.ndarray) -> PoseStamped:
    """The goal as RViz's 2D Goal Pose sends it (in map)."""
    msg = PoseStamped()
    msg.header.frame_id = 'map'
    msg.pose.position.x, msg.pose.position.y = float(goal[0]), float(goal[1])
    msg.pose.orientation = yaw_to_quaternion(float(goal[2]))
    return msg


def at(node: GlobalPlannerNode, planner: ScriptedPlanner, t: float) -> None:
    """Set the test's time t on the planner and the node's clock, with odometry at POSE."""
    planner.now = t
    node.get_clock().set_ros_time_override(Time(nanoseconds=round(t * 1e9)))
    node.odom_callback(state_to_odometry(POSE, np.zeros(2), stamp=seconds_to_stamp(t),
                                       frame_id='map'))


def run_node(ros) -> tuple[GlobalPlannerNode, ScriptedPlanner, list]:
    planner = ScriptedPlanner()
    # the test's clock (simulated time, no /clock: the timer is never spun) and planner
    node = ros.add(GlobalPlannerNode(planner=planner, context=ros.context, parameter_overrides=[
        Parameter('use_sim_time', value=True),
        Parameter('replan_check_rate', value=1.0 / CHECK_PERIOD),
        Parameter('replan_period', value=REPLAN_PERIOD)]))
    assert autostart(node) is None
    assert node.planner is planner
    decisions: list = []
    record(node.replanner, decisions)
    at(node, planner, 0.0)
    node.goal_callback(goal_pose(GOAL))
    for t in TIMES:
        at(node, planner, t)  # odometry as fresh as the navigator's
        node.check_plan()
    return node, planner, decisions


def test_the_node_and_the_navigator_make_the_same_replanning_decisions(ros) -> None:
    navigator, nav_planner, nav_decisions = run_navigator()
    node, node_planner, node_decisions = run_node(ros)

    assert node_decisions == nav_decisions
    assert node_planner.calls == nav_planner.calls
    planned, failed = ReplanOutcome.PLANNED, ReplanOutcome.FAILED
    blocked, periodic = PlanTrigger.BLOCKED, PlanTrigger.PERIODIC
    assert nav_decisions[:6] == [
        (planned, PlanTrigger.GOAL), (ReplanOutcome.CLEAR, None),
        (failed, blocked), (failed, blocked), (planned, blocked), (ReplanOutcome.CLEAR, None)]
    assert nav_decisions[6:10] == [(failed, blocked), (ReplanOutcome.CLEAR, None),
                                   (failed, periodic), (planned, periodic)]
    # consecutive failures move the seed; a plan made resets them
    assert [f for _, kind, f in nav_planner.calls if kind == 'replan'] == [0, 1, 2, 0, 1, 2,
                                                                           0]

    for replanner in (navigator.replanner, node.replanner):
        assert (replanner.plans, replanner.replans, replanner.replan_failures) == (3, 2, 5)
    # each adapter's counts are the re-planner's
    assert navigator.log.replans == navigator.replanner.replans == node.replan_count
    assert navigator.log.replan_failures == navigator.replanner.replan_failures
    assert len(navigator.local.plans) == node.plan_count == 3
    np.testing.assert_allclose(navigator.plan, node.last_plan[:, :2])


def test_the_navigators_settings_map_onto_the_nodes_defaults(ros) -> None:
    node = ros.add(GlobalPlannerNode(context=ros.context))
    assert node.replanner.settings == ReplanSettings.from_rate(
        2.0, escape_distance=1.0, progress_timeout=PROGRESS_TIMEOUT,
        progress_radius=PROGRESS_RADIUS)
    navigation = NavigationSettings().replan_settings()
    assert navigation.check_period == node.replanner.settings.check_period
    assert navigation.replan_period == node.replanner.settings.replan_period == 0.0
    assert navigation.escape_distance == node.replanner.settings.escape_distance
    assert navigation.progress_timeout == node.replanner.settings.progress_timeout
    assert navigation.progress_radius == node.replanner.settings.progress_radius
    assert navigation.progress_angle == node.replanner.settings.progress_angle == PROGRESS_ANGLE
    # without sensing the grid never changes: the navigator never checks (a rate of 0)
    assert NavigationSettings(sense=False).replan_settings().check_period == 0.0


class Odometry(SimClock):
    """The test's clock and robot: each tick publishes odometry at pose, unless it is None.

    None is the simulator (or the odometry's driver) gone while the clock runs on, as the
    wall clock does for nodes started by hand.
    """

    def __init__(self, ros, probe, pose: np.ndarray) -> None:
        super().__init__(ros, probe, dt=0.1)
        self.pose: np.ndarray | None = pose

    def publish(self) -> None:
        if self.pose is not None:
            self.probe.publish_odom(self.pose, stamp=self.t)


def test_stale_odometry_stops_replanning_with_one_warning_until_it_comes_again(ros) -> None:
    timeout = 2.0  # progress_timeout: no_progress re-plans every 2 s of a standing robot
    node = ros.add(GlobalPlannerNode(context=ros.context, parameter_overrides=[
        Parameter('use_sim_time', value=True), Parameter('world_file', value='paper_obstacle'),
        Parameter('goal', value=[2.5, 0.0, 0.0]), Parameter('progress_timeout', value=timeout)]))
    assert autostart(node) is None
    probe = ros.probe(use_sim_time=True)
    start, stands = np.array([0.0, 0.0, 0.9]), np.array([0.3, 0.4, 0.9])  # 0.5 m apart
    clock = Odometry(ros, probe, start)

    def triggers() -> list[PlanTrigger | None]:
        return [o.trigger for o in probe.planner_outcomes if o.planned]

    assert clock.run_until(lambda: triggers() == [PlanTrigger.GOAL])
    # the robot moves off its start, then stands: no_progress re-plans, one per timeout
    clock.pose = stands
    assert clock.run_until(lambda: triggers().count(PlanTrigger.NO_PROGRESS) == 2)
    assert node.get_parameter('odom_timeout').value == 0.5  # the controller's default

    clock.pose = None  # the simulator is gone; time runs on
    planned = node.plan_count
    clock.run_for(4 * timeout)
    assert node.plan_count == planned
    stale = [line for line in probe.log_lines('global_planner', Log.WARN) if 'stale' in line]
    assert len(stale) == 1 and 'not re-planning' in stale[0]

    # odometry again, the robot where it stood: re-planning resumes, and the time without
    # odometry was not time it stood (no no_progress re-plan at once)
    clock.pose = stands
    back = clock.t
    assert clock.run_until(lambda: node.plan_count > planned)
    assert triggers()[-1] is PlanTrigger.NO_PROGRESS
    assert clock.t - back >= timeout - 1e-6
    assert any('re-planning resumes' in line
               for line in probe.log_lines('global_planner', Log.INFO))
    assert len([line for line in probe.log_lines('global_planner', Log.WARN)
                if 'stale' in line]) == 1
