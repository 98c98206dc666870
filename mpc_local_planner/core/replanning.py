# SPDX-License-Identifier: Apache-2.0
"""The re-planning policy, once: the global_planner node and the Navigator both adapt it.

`Replanner` holds the plan in force, its goal and the counts, and decides; it has no clock
(the caller passes ``now`` in seconds, its own clock's) and no ROS. The policy:

- **A new goal** is planned at once from the robot's pose (``RrtStarPlanner.plan``). A plan
  replaces the plan in force, and its goal the goal in force. A goal that cannot be planned
  to leaves the plan in force, and its goal, in force (the caller reports the error).
- **Checks** come every ``check_period`` seconds (0 = never: no check, so no re-plan of any
  kind), counted from the last check or from the last new goal's plan (which was just made
  on the grid in force). A check earlier than ``check_period - slack`` is not due and does
  nothing: a timer's ticks may come a little early or late, a simulation's steps land on the
  period exactly.
- **Blocked**: at a check, the rest of the plan in force (from the robot's projection onto
  it, less its first stretch) is judged with the rule plans are made with
  (``RrtStarPlanner.rest_problem``); if it fails, the goal in force is re-planned from the
  robot's pose.
- **Periodic**: otherwise, with ``replan_period`` > 0, the goal in force is re-planned at the
  first check at least ``replan_period`` seconds after the plan in force was made.
- **No progress** (Nav2's progress checker): otherwise, with ``progress_timeout`` > 0, when
  the robot, farther than ``progress_radius`` from the goal, has neither moved
  ``progress_radius`` nor turned ``progress_angle`` from where it was ``progress_timeout``
  seconds ago (Nav2's PoseProgressChecker), the goal is re-planned from where it stands.
  After a new goal's plan the rule counts only once the robot has moved or turned that much
  (a controller that starts late is not a robot that is stuck; one that turned in place and
  then stood is); after a re-plan it counts at once, as the controller was running. A real
  robot that re-planned while moving coasts on past the new plan's start, maybe by less than
  ``progress_radius``; a forward-only one may then have the plan behind it, and its
  controller no verified way back onto it. The clock of
  this rule restarts at each attempt, so a robot that cannot be helped is re-planned once
  per ``progress_timeout``.
- **Re-plans** go through ``RrtStarPlanner.replan``: from the robot's pose, or from the
  nearest clear point within ``escape_distance`` when the robot stands within the clearance,
  or from the nearest point within the planner's bounds when it stands outside them.
  The caller may pass the obstacles its local controller holds (the MPC's convex pieces):
  a re-plan then starts with a turn in place those pieces allow, where there is such a
  plan (a robot wedged among them, which the planner's grid would turn where the controller
  cannot, is sent on by a first motion it can make).
- **Failures**: a failed re-plan keeps the plan in force (and is checked again at the next
  check). Consecutive failed re-plans move the planner's seed on by their count (the same
  seed on the same grid would fail the same way); any plan made, for a goal or a re-plan,
  resets that count to 0. A failed goal neither counts nor resets.
- **Counts**, for logs and metrics: ``plans`` (every plan made), ``replans`` (re-plans
  made), ``replan_failures`` (re-plans that failed, in all) and ``consecutive_failures``
  (the seed's offset).

An error of the planner other than PlanningError is a failed attempt too (the node must not
die of it); the result carries it, and a caller that wants to stop on bugs re-raises it.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
import math
import time
from typing import NamedTuple, Protocol, Sequence, TYPE_CHECKING

import numpy as np

from mpc_local_planner.core.diagnostics import PlanTrigger

if TYPE_CHECKING:
    from mpc_local_planner.core.free_space import EscapeGrid
    from mpc_local_planner.core.obstacles import ConvexPolygon

__all__ = [
    'PROGRESS_ANGLE',
    'PROGRESS_RADIUS',
    'PROGRESS_TIMEOUT',
    'ReplanDecision',
    'Replanner',
    'ReplanningPlanner',
    'ReplanOutcome',
    'ReplanSettings',
    'TIME_EPSILON',
]

# Seconds: times computed as k * h by a simulation land on a period up to rounding.
TIME_EPSILON = 1e-9
# The no-progress rule as the planner node and the suites run it (ReplanSettings keeps it off
# unless asked): Nav2's progress checker allows 10 s for 0.5 m; a robot that stands 5 s has
# stopped (its controller found no verified plan), and 0.25 m is more than odometry noise
# and less than a third of the Jackal's length.
PROGRESS_TIMEOUT = 5.0
PROGRESS_RADIUS = 0.25
# A turn of this many radians counts as progress too (Nav2's PoseProgressChecker,
# required_movement_angle): a robot that turned in place since its plan was made has moved,
# and one that turned and then stood is stuck, whether or not it ever drove.
PROGRESS_ANGLE = 0.5


class ReplanningPlanner(Protocol):
    """What the re-planner needs of a planner (RrtStarPlanner has it)."""

    def plan(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Return (M, 2) waypoints from start to goal; raise PlanningError if none."""

    def replan(self, start: np.ndarray, goal: np.ndarray, *, failures: int = 0,
               grid: EscapeGrid | None = None, escape_distance: float = 1.0,
               local_obstacles: Sequence[ConvexPolygon] = ()) -> np.ndarray:
        """Plan again from where the robot is, the seed moved on by failures."""

    def rest_problem(self, plan: np.ndarray, position: Sequence[float]) -> str | None:
        """Say why the rest of the plan no longer passes the planner's check, or None."""


@dataclass(frozen=True)
class ReplanSettings:
    """When the plan in force is checked and re-planned.

    Attributes:
        check_period: Seconds between two checks of the rest of the plan (the node's
            1 / replan_check_rate); 0 = never checked, never re-planned.
        replan_period: Re-plan the goal in force this often (seconds) even when the plan
            is clear; 0 = only when blocked or for a new goal (the node's default).
        escape_distance: How far a re-plan may start from a robot standing within the
            planner's clearance (RrtStarPlanner.replan).
        slack: How much earlier than check_period a check still counts as due, seconds.
        progress_timeout: Re-plan from where the robot stands when it has not moved
            progress_radius in this many seconds away from the goal; 0 = never (Nav2's
            movement_time_allowance).
        progress_radius: Metres that count as progress (Nav2's required_movement_radius),
            and the distance to the goal within which standing still is arriving.
        progress_angle: Radians of turn that count as progress too (Nav2's
            PoseProgressChecker required_movement_angle); 0 = position only.

    """

    check_period: float = 0.5
    replan_period: float = 0.0
    escape_distance: float = 1.0
    slack: float = TIME_EPSILON
    progress_timeout: float = 0.0
    progress_radius: float = 0.25
    progress_angle: float = PROGRESS_ANGLE

    def __post_init__(self) -> None:
        """Refuse negative or non-finite periods."""
        for name in ('check_period', 'replan_period', 'escape_distance', 'slack',
                     'progress_timeout', 'progress_radius', 'progress_angle'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                problem = f'{name} must be finite and >= 0, got {value}'
                raise ValueError(problem)

    @classmethod
    def from_rate(cls, check_rate: float, **kwargs: float) -> ReplanSettings:
        """Return the settings for a check rate in Hz (0 = never), as the node declares it.

        The node's checks come from a timer at that rate, whose ticks may come late: a
        check up to half a period early still counts as due.
        """
        period = 1.0 / check_rate if check_rate > 0.0 else 0.0
        kwargs.setdefault('slack', 0.5 * period)
        return cls(check_period=period, **kwargs)


class ReplanOutcome(Enum):
    """What a call of the re-planner did."""

    NOT_DUE = 'not due'  # no check due (or checks off, or nothing to check): nothing done
    CLEAR = 'clear'  # checked: the plan in force stays (clear, and no periodic re-plan due)
    PLANNED = 'planned'  # a new plan (for a goal, or a re-plan): it is now in force
    FAILED = 'failed'  # planning failed: the plan in force (if any) stays


class ReplanDecision(NamedTuple):
    """The outcome of a call, for the adapter to convert (publish, follow, log).

    Attributes:
        outcome: What was done.
        trigger: What asked for a plan (None when none was asked for).
        waypoints: The new plan's (M, 2) waypoints when PLANNED, else None.
        start: The robot's pose (x, y, theta) the plan was asked from, else None.
        goal: The goal planned to, else None.
        problem: Why the rest of the plan was blocked (trigger BLOCKED), else None.
        error: The planner's exception when FAILED, else None.
        planning_s: Wall time the planning attempt took (a measurement, not the policy's
            time), seconds; 0 without one.

    """

    outcome: ReplanOutcome
    trigger: PlanTrigger | None = None
    waypoints: np.ndarray | None = None
    start: np.ndarray | None = None
    goal: np.ndarray | None = None
    problem: str | None = None
    error: Exception | None = None
    planning_s: float = 0.0

    @property
    def attempted(self) -> bool:
        """Whether the planner was asked for a plan."""
        return self.outcome in (ReplanOutcome.PLANNED, ReplanOutcome.FAILED)


class Replanner:
    """The re-planning policy (see the module's docstring) around a planner.

    The planner and the grid are passed at every call: the node replaces its planner when a
    map comes or a parameter changes.

    Args:
        settings: When to check and re-plan.

    """

    def __init__(self, settings: ReplanSettings | None = None) -> None:
        self.settings = settings or ReplanSettings()
        self._plan: np.ndarray | None = None
        self._goal: np.ndarray | None = None
        self._plan_time = -math.inf
        self._checked = -math.inf
        self.plans = 0
        self.replans = 0
        self.replan_failures = 0
        self.consecutive_failures = 0
        # where the robot was when progress was last measured, and when (No progress)
        self._anchor: np.ndarray | None = None
        self._anchor_time = -math.inf
        self._moved = False  # moved progress_radius or turned progress_angle since the plan

    @property
    def plan(self) -> np.ndarray | None:
        """The (M, 2) waypoints of the plan in force, or None."""
        return self._plan

    @property
    def goal(self) -> np.ndarray | None:
        """The goal of the plan in force, or None."""
        return self._goal

    def drop_plan(self) -> None:
        """Forget the plan and goal in force (nothing is checked until a new goal's plan).

        The counts stay.
        """
        self._plan = None
        self._goal = None
        self._plan_time = -math.inf

    def restart_progress(self, now: float) -> None:
        """Count the no-progress rule's time from now (the pose it measures from stays).

        For a caller that could not judge the robot's progress for a while (the planner node
        while its odometry was stale): that time is not time the robot stood.
        """
        if self._anchor is not None:
            self._anchor_time = now

    def plan_goal(self, planner: ReplanningPlanner, start: np.ndarray, goal: np.ndarray, *,
                  now: float) -> ReplanDecision:
        """Plan a new goal from start; on success the plan and goal are in force.

        Args:
            planner: The planner in force.
            start: The robot's pose (x, y, theta).
            goal: The goal pose (x, y, theta).
            now: The caller's time, seconds.

        Returns:
            PLANNED with the waypoints, or FAILED with the error (the plan in force stays).

        """
        return self._attempt(planner, start, goal, PlanTrigger.GOAL, now=now)

    def check(self, planner: ReplanningPlanner, start: np.ndarray, *, now: float,
              grid: EscapeGrid | None = None,
              local_obstacles: Sequence[ConvexPolygon] = ()) -> ReplanDecision:
        """Check the plan in force if a check is due, and re-plan it when it must be.

        Args:
            planner: The planner in force (its grid has the latest scans).
            start: The robot's pose (x, y, theta).
            now: The caller's time, seconds.
            grid: The grid a re-plan may escape on (None: no escape).
            local_obstacles: The obstacles the local controller holds (as sensed): a
                re-plan's turn at the start is one they allow, where there is such a plan
                (`RrtStarPlanner.replan`).

        Returns:
            NOT_DUE, CLEAR, or the re-plan's PLANNED or FAILED (trigger BLOCKED, PERIODIC
            or NO_PROGRESS).

        """
        settings = self.settings
        if (settings.check_period <= 0.0 or self._plan is None or self._goal is None
                or now - self._checked < settings.check_period - settings.slack):
            return ReplanDecision(ReplanOutcome.NOT_DUE)
        self._checked = now
        held = tuple(local_obstacles)
        problem = planner.rest_problem(self._plan, start)
        if problem is not None:
            return self._attempt(planner, start, self._goal, PlanTrigger.BLOCKED, now=now,
                                 grid=grid, problem=problem, held=held)
        if (settings.replan_period > 0.0
                and now - self._plan_time >= settings.replan_period - TIME_EPSILON):
            return self._attempt(planner, start, self._goal, PlanTrigger.PERIODIC, now=now,
                                 grid=grid, held=held)
        if self._no_progress(start, now):
            return self._attempt(planner, start, self._goal, PlanTrigger.NO_PROGRESS, now=now,
                                 grid=grid, held=held)
        return ReplanDecision(ReplanOutcome.CLEAR)

    def _no_progress(self, start: np.ndarray, now: float) -> bool:
        """Say whether the robot has stood for progress_timeout away from the goal."""
        settings = self.settings
        if settings.progress_timeout <= 0.0 or self._goal is None:
            return False
        pose = np.asarray(start, dtype=float)[:3]
        position = pose[:2]
        if self._anchor is None or self._progressed(pose):
            self._anchor, self._anchor_time = pose.copy(), now
            self._moved = True
            return False
        if not self._moved:
            return False  # not moved since the plan: its controller may not be up yet
        if float(np.hypot(*(position - self._goal[:2]))) <= settings.progress_radius:
            return False  # at the goal: standing is arriving
        if now - self._anchor_time < settings.progress_timeout - TIME_EPSILON:
            return False
        self._anchor_time = now  # once per progress_timeout, whatever the attempt gives
        return True

    def _progressed(self, pose: np.ndarray) -> bool:
        """Say whether pose is progress_radius, or progress_angle of turn, from the anchor."""
        settings, anchor = self.settings, self._anchor
        if float(np.hypot(*(pose[:2] - anchor[:2]))) >= settings.progress_radius:
            return True
        turned = abs(math.remainder(float(pose[2] - anchor[2]), math.tau))
        return settings.progress_angle > 0.0 and turned >= settings.progress_angle

    def _attempt(self, planner: ReplanningPlanner, start: np.ndarray, goal: np.ndarray,
                 trigger: PlanTrigger, *, now: float, grid: EscapeGrid | None = None,
                 problem: str | None = None,
                 held: tuple[ConvexPolygon, ...] = ()) -> ReplanDecision:
        start = np.array(start, dtype=float)
        goal = np.array(goal, dtype=float)
        started = time.perf_counter()
        try:
            if trigger is PlanTrigger.GOAL:
                waypoints = planner.plan(start, goal)
            else:
                waypoints = planner.replan(start, goal, failures=self.consecutive_failures,
                                           grid=grid,
                                           escape_distance=self.settings.escape_distance,
                                           local_obstacles=held)
        except Exception as err:  # PlanningError; a bug too: the caller decides
            seconds = time.perf_counter() - started
            if trigger is not PlanTrigger.GOAL:
                self.replan_failures += 1
                self.consecutive_failures += 1
            return ReplanDecision(ReplanOutcome.FAILED, trigger, start=start, goal=goal,
                                  problem=problem, error=err, planning_s=seconds)
        seconds = time.perf_counter() - started
        waypoints = np.asarray(waypoints, dtype=float)
        self._plan, self._goal, self._plan_time = waypoints, goal, now
        self._anchor, self._anchor_time = start[:3].copy(), now
        # a new goal's plan waits for its controller to move the robot; a re-plan replaces a
        # plan the controller was following, so standing from its start counts at once (a
        # robot that re-planned while moving may coast less than progress_radius past the
        # new plan's start and stand there, the plan behind it)
        self._moved = trigger is not PlanTrigger.GOAL
        if trigger is PlanTrigger.GOAL:
            self._checked = now
        else:
            self.replans += 1
        self.plans += 1
        self.consecutive_failures = 0
        return ReplanDecision(ReplanOutcome.PLANNED, trigger, waypoints=waypoints, start=start,
                              goal=goal, problem=problem, planning_s=seconds)
