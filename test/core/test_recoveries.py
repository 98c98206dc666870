# SPDX-License-Identifier: Apache-2.0
"""The recovery behaviours: a stuck forward-only robot backs out along its own trail.

Each test drives a unicycle (the ideal plant: the pose integrates the command) with a
`Recoveries` around a stand-in controller that drives a straight line into a pocket and then
answers STOP, as the MPC does when no verified forward plan exists.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.recoveries import (
    Recoveries,
    RecoveryKind,
    RecoverySettings,
    Trail,
)

H = 0.05  # control period, s


def pocket() -> list[ConvexPolygon]:
    """Return walls around a 0.7 m wide pocket along +x from x = 2.2, closed at x = 3.4.

    The Jackal's body fits inside it; its 0.67 m circumscribed disc, with room to turn, does not.
    """
    return [ConvexPolygon.from_box(2.2, 0.35, 3.6, 0.5),
            ConvexPolygon.from_box(2.2, -0.5, 3.6, -0.35),
            ConvexPolygon.from_box(3.4, -0.5, 3.6, 0.5)]


class IntoThePocket:
    """Drives at 0.5 m/s along +x while the way ahead is clear, then answers STOP."""

    def __init__(self, stop_at: float = 3.0) -> None:
        self.stop_at = stop_at
        self.calls = 0

    def compute(self, pose: np.ndarray) -> ControlOutput:
        self.calls += 1
        if pose[0] < self.stop_at:
            return ControlOutput(np.array([0.5, 0.0]), None, Reason.TRACKING)
        return ControlOutput(np.zeros(2), None, Reason.STOP, 'no feasible candidate')


def drive(recoveries: Recoveries, controller: IntoThePocket, seconds: float, *,
          pose: np.ndarray | None = None, plan_at: float | None = None, start: float = 0.0,
          obstacles: list[ConvexPolygon] | None = None
          ) -> tuple[np.ndarray, list[ControlOutput], list[np.ndarray]]:
    """Run the loop for seconds; a new plan comes at plan_at (the re-planner's)."""
    pose = np.array([0.0, 0.0, 0.0]) if pose is None else pose.copy()
    answers, poses = [], [pose.copy()]
    recoveries.set_obstacles(pocket() if obstacles is None else obstacles)
    twist = np.zeros(2)
    for k in range(int(round(seconds / H))):
        now = start + k * H
        if plan_at is not None and abs(now - plan_at) < 0.5 * H:
            recoveries.plan_changed(np.array([[pose[0], pose[1], 0.0], [6.0, 0.0, 0.0]]))
        answer = recoveries.step(pose, twist, now, lambda p=pose: controller.compute(p))
        answers.append(answer)
        v, omega = answer.u
        pose = pose + H * np.array([v * math.cos(pose[2]), v * math.sin(pose[2]), omega])
        twist = answer.u.copy()
        poses.append(pose.copy())
    return pose, answers, poses


def new_recoveries(**settings: float | bool) -> Recoveries:
    recoveries = Recoveries(JACKAL, v_max=2.0, omega_max=4.0,
                            settings=RecoverySettings(**settings))
    recoveries.plan_changed(np.array([[0.0, 0.0, 0.0], [6.0, 0.0, 0.0]]))
    return recoveries


def test_trail_keeps_its_length_and_spacing() -> None:
    trail = Trail(spacing=0.1, length=1.0)
    for x in np.arange(0.0, 3.0, 0.01):
        trail.record(np.array([x, 0.0, 0.0]))
    xs = trail.poses[:, 0]
    assert np.all(np.diff(xs) >= 0.1 - 1e-9)
    assert xs[-1] - xs[0] <= 1.0 + 1e-9
    assert xs[-1] > 2.8
    trail.pop_passed(np.array([xs[-1], 0.0, 0.0]))
    assert trail.poses[-1, 0] < xs[-1]


def test_a_stuck_forward_only_robot_backs_out_along_its_trail_then_waits_for_a_plan() -> None:
    recoveries = new_recoveries()
    controller = IntoThePocket()
    _, answers, poses = drive(recoveries, controller, 25.0, plan_at=20.0)
    reasons = [a.reason for a in answers]
    first = reasons.index(Reason.RECOVERY)
    # stuck_timeout after its last progress (it stopped at x = 3.0, at 6 s; progress is
    # counted in steps of progress_radius, 0.5 s at 0.5 m/s)
    stopped = 3.0 / 0.5
    assert (stopped - 0.5 + recoveries.settings.stuck_timeout - H <= first * H
            <= stopped + recoveries.settings.stuck_timeout + H)
    backing = [a for a in answers if a.reason is Reason.RECOVERY and a.u[0] < 0.0]
    assert backing, 'no back-out'
    assert all('backing out along the trail' in a.detail for a in backing)
    kinds = [r.kind for r in recoveries.log]
    assert kinds[:3] == [RecoveryKind.BACK_OUT, RecoveryKind.SPIN, RecoveryKind.WAIT]
    assert recoveries.log[0].ended == 'a turn in place is possible'
    assert recoveries.log[2].ended == 'a new plan came'
    # it backed out of the pocket along the trail (y = 0), and never touched a wall
    backed = np.array(poses[:int(round(recoveries.log[0].end / H)) + 1])
    assert backed[:, 0].min() < 2.2 - JACKAL.radius - recoveries.settings.turn_clearance
    assert recoveries.log[0].distance < recoveries.settings.back_out_max
    assert np.max(np.abs(backed[:, 1])) < 0.02
    # nor in the spin and the wait (after them the stand-in, blind, drives on as it likes)
    recovering = np.array(poses[:int(round(recoveries.log[2].end / H)) + 1])
    assert recoveries._clearance(recovering) > 0.0
    # after the plan the controller answers again
    assert reasons[-1] is not Reason.RECOVERY and recoveries.phase is None


def test_a_trail_crossed_by_an_obstacle_seen_since_is_not_taken() -> None:
    recoveries = new_recoveries()
    controller = IntoThePocket()
    pose, answers, _ = drive(recoveries, controller, 3.0 / 0.5 + 1.0)
    assert recoveries.phase is None and len(recoveries.trail) > 10
    # something now stands across the trail behind the robot (a person, a box seen since)
    behind = pocket() + [ConvexPolygon.from_box(pose[0] - 0.6, -0.3, pose[0] - 0.5, 0.3)]
    _, answers, poses = drive(recoveries, controller, 10.0, pose=pose, obstacles=behind,
                              start=3.0 / 0.5 + 1.0)
    assert not any(a.u[0] < 0.0 for a in answers)
    assert recoveries.log[0].kind is RecoveryKind.BACK_OUT
    assert 'blocked by an obstacle seen since' in recoveries.log[0].ended
    assert recoveries.log[0].distance == 0.0


class DriveThenTurn:
    """Drives to x = 1 along +x, turns in place to 1 rad there, then answers STOP."""

    def compute(self, pose: np.ndarray) -> ControlOutput:
        if pose[0] < 1.0:
            return ControlOutput(np.array([0.5, 0.0]), None, Reason.TRACKING)
        if pose[2] < 1.0:
            return ControlOutput(np.array([0.0, 0.5]), None, Reason.TRACKING)
        return ControlOutput(np.zeros(2), None, Reason.STOP, 'no feasible candidate')


def test_a_robot_that_turned_in_place_turns_back_before_it_reverses() -> None:
    # reversing at the turned heading would sweep the body where it never was (behind it,
    # where the laser does not see): the back-out retraces the turn first
    recoveries = new_recoveries()
    # a post ahead of the turned robot, beyond its corners' sweep (0.333 m) and within the
    # disc a turn in place needs (0.385 m): it cannot turn there
    post = np.array([1.0, 0.0]) + 0.385 * np.array([math.cos(1.0), math.sin(1.0)])
    ahead = [ConvexPolygon.from_box(*(post - 0.02), *(post + 0.02))]
    _, answers, poses = drive(recoveries, DriveThenTurn(), 25.0, obstacles=ahead)
    recovering = [(a, p) for a, p in zip(answers, poses, strict=False)
                  if a.reason is Reason.RECOVERY and 'backing out' in a.detail]
    assert recovering
    turning = [(a, p) for a, p in recovering if a.u[0] == 0.0]
    assert turning and all(a.u[1] < 0.0 for a, _ in turning)
    for answer, pose in recovering:
        if answer.u[0] < 0.0:
            assert abs(pose[2]) < 0.1 + 1e-9  # reverses only once aligned with the trail
    assert recoveries.log[0].ended == 'a turn in place is possible'
    assert recoveries._clearance(np.array(poses)) > 0.0


def test_a_robot_that_may_reverse_does_not_back_out() -> None:
    recoveries = new_recoveries(back_out=False)
    controller = IntoThePocket()
    _, answers, _ = drive(recoveries, controller, 20.0)
    assert not any(a.u[0] < 0.0 for a in answers)
    assert recoveries.log and recoveries.log[0].kind is RecoveryKind.SPIN
    assert recoveries.log[0].ended == 'no room to turn in place'


def test_recoveries_are_bounded_per_goal() -> None:
    recoveries = new_recoveries(max_tries=2, wait_timeout=1.0, back_out_max=0.1)
    controller = IntoThePocket(stop_at=0.0)  # stuck from the start, nowhere to go
    _, answers, _ = drive(recoveries, controller, 60.0, obstacles=[])
    assert recoveries.started == 2 and recoveries.exhausted
    assert answers[-1].reason is Reason.STOP
    # a plan to a new goal allows them again
    recoveries.plan_changed(np.array([[0.0, 0.0, 0.0], [0.0, 5.0, 0.0]]))
    assert recoveries.tries == 0 and not recoveries.exhausted


@pytest.mark.parametrize('reason', [Reason.NO_SCAN, Reason.STALE_ODOM, Reason.GOAL_REACHED])
def test_a_robot_stopped_for_its_inputs_or_at_its_goal_is_not_stuck(reason: Reason) -> None:
    recoveries = new_recoveries()
    for k in range(int(30.0 / H)):
        answer = recoveries.step(np.zeros(3), np.zeros(2), k * H,
                                 lambda: ControlOutput(np.zeros(2), None, reason))
        assert answer.reason is reason
    assert recoveries.started == 0


def test_off_the_controller_always_answers() -> None:
    recoveries = new_recoveries(enabled=False)
    controller = IntoThePocket()
    _, answers, _ = drive(recoveries, controller, 25.0)
    assert Reason.RECOVERY not in [a.reason for a in answers]


def test_settings_refuse_unbounded_values() -> None:
    with pytest.raises(ValueError, match='back_out_max'):
        RecoverySettings(back_out_max=math.inf)
    with pytest.raises(ValueError, match='max_tries'):
        RecoverySettings(max_tries=-1)
