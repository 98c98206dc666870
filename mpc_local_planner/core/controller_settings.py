# SPDX-License-Identifier: Apache-2.0
"""`ControllerSettings`: what `MpcController` checks around the MPC, as plain data."""

from __future__ import annotations

from dataclasses import dataclass
import math

__all__ = ['ControllerSettings', 'is_stale']


def is_stale(age: float, timeout: float) -> bool:
    """Say whether data measured age seconds ago is stale, by the nodes' one rule.

    Stale: older than timeout, or from the future by more than timeout (the clock jumped
    back); a NaN age (NaN compares false) is stale too. The controller stops on it, and the
    planner stops re-planning on it.
    """
    return not -timeout <= age <= timeout


@dataclass(frozen=True)
class ControllerSettings:
    """What the controller checks around the MPC.

    Arrival is Nav2's SimpleGoalChecker's (same names, same meaning): the robot has arrived
    when it is within xy_goal_tolerance of the plan's last position and within
    yaw_goal_tolerance of its heading. Once the position has been met, the robot turns in
    place to the heading (Reason.ROTATE_TO_HEADING) instead of letting the MPC manoeuvre for
    the last centimetres. The defaults are for a real robot, whose wheel odometry wanders by
    0.5-3 cm and whose base answers a command a step late: 0.1 m is a few times that noise plus
    one step's creep at approach speed (Nav2 allows 0.25 m), and 0.15 rad leaves room for the
    overshoot of an in-place turn under actuator lag (Nav2 allows 0.25 rad). The paper's
    0.02 m / 0.05 rad are kept where its scenario is run (closed_loop's
    PAPER_GOAL_TOLERANCES, the benchmark's REACHED_POSITION and REACHED_HEADING); why not
    everywhere: docs/design/measurements.md, Goal tolerances.

    Attributes:
        xy_goal_tolerance: distance to the plan's last position that counts as arrived (m).
        yaw_goal_tolerance: heading error to the plan's last heading that counts as arrived
            (rad); pi or more accepts any heading.
        stateful: as Nav2's SimpleGoalChecker: once the position tolerance is met it stays
            met for the plan (the robot only has to turn to the heading, even if noise moves
            the measured position back out), and once arrived the command stays zero until a
            new plan comes. False: each step judges the pose afresh, and a pose that drifts
            out of the tolerances is driven back.
        odom_timeout: odometry older than this (seconds of ROS time) is stale.
        turn_length: metres of path parameter per radian turned in place at plan corners.
        capacity: segments a waypoint plan may have (the solver's size; fixed so that
            re-plans reuse the built solver).
        max_plan_poses: a plan with more poses is refused: converting and simplifying it
            would hold up the control loop (10,000 poses at 5 cm is 500 m).
        scan_timeout: a scan older than this (seconds of ROS time) is stale, when the
            laser is a source of obstacles (compute's scan_required).
        control_frequency: commands per second (Hz). A real base wants them at 10-20 Hz,
            while the MPC predicts in steps of h (MpcConfig.step, 0.2 s). The MPC solves
            once a step; the calls between return the input its last verified plan gives
            for the current time (the plan is piecewise constant over its steps, so this is
            the plan, applied), after every safety check. 1 / step or less: every call solves.
        max_decel: the base's deceleration limits (m/s^2, rad/s^2), as Nav2's velocity
            smoother names them. A stop of a moving robot (stale data, a failure, a rejected
            candidate) brakes along the last verified plan within them (`Brake`) instead of
            commanding zero at once, which a real base cannot follow; inf: zero at once.
        actuation_delay: with a first-order hold (MpcConfig.input_hold 'first_order'), how
            far ahead of now the plan's velocity ramp is commanded (s): the base's command
            latency plus its lag's time constant (a first-order lag follows a ramp that much
            behind), so that the velocity the base reaches is the one the plan predicts. 0:
            the ramp's value now; ignored with a zero hold (the plan's inputs as they are).

    """

    xy_goal_tolerance: float = 0.1
    yaw_goal_tolerance: float = 0.15
    stateful: bool = True
    odom_timeout: float = 0.5
    turn_length: float = 0.25
    capacity: int = 64
    max_plan_poses: int = 10_000
    scan_timeout: float = 0.5
    control_frequency: float = 20.0
    max_decel: tuple[float, float] = (math.inf, math.inf)
    actuation_delay: float = 0.0

    def __post_init__(self) -> None:
        """Refuse non-positive or non-finite tolerances and timeouts, and small capacities."""
        decel = tuple(float(a) for a in self.max_decel)
        if len(decel) != 2 or not all(a > 0 for a in decel):
            msg = f'max_decel must be two values > 0 (inf: none), got {self.max_decel!r}'
            raise ValueError(msg)
        object.__setattr__(self, 'max_decel', decel)
        for name in ('xy_goal_tolerance', 'yaw_goal_tolerance', 'odom_timeout',
                     'turn_length', 'scan_timeout', 'control_frequency'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                msg = f'{name} must be > 0 and finite, got {value}'
                raise ValueError(msg)
        if not (math.isfinite(self.actuation_delay) and self.actuation_delay >= 0):
            msg = f'actuation_delay must be >= 0 and finite, got {self.actuation_delay}'
            raise ValueError(msg)
        if not isinstance(self.stateful, bool):
            msg = f'stateful must be true or false, got {self.stateful!r}'
            raise ValueError(msg)
        if self.capacity < 3:
            msg = f'capacity must be >= 3, got {self.capacity}'
            raise ValueError(msg)
        if self.max_plan_poses < 2:
            msg = f'max_plan_poses must be >= 2, got {self.max_plan_poses}'
            raise ValueError(msg)

    def goal_check(self, position_error: float, heading_error: float, *,
                   position_met: bool = False) -> tuple[bool, bool]:
        """Return (position met, arrived): THE definition of arrival, Nav2's SimpleGoalChecker.

        The controller decides with it at every step, and analyze_bag judges a recording
        without the controller's verdict with it: one rule, so that they cannot disagree.

        Args:
            position_error: distance to the plan's last position (m).
            heading_error: |wrapped heading error| to the plan's last heading (rad).
            position_met: the position was met before on this plan (kept when stateful).

        """
        met = position_error <= self.xy_goal_tolerance or (self.stateful and position_met)
        return met, met and heading_error <= self.yaw_goal_tolerance
