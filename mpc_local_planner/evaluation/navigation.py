# SPDX-License-Identifier: Apache-2.0
"""The navigation stack without DDS: laser, perception, a re-planning planner, a local controller.

What ``closed_loop --sensing`` runs over DDS, in one process and deterministically, so that
suites of hundreds of worlds are affordable. Every control step (`Navigator.step`, the
rollout's controller):

1. the simulated laser scans the true world (known and unknown obstacles) from the TRUE
   pose (every ``scan_period``; with a real robot's `Base`, through its reality's
   `ScanChannel`: noise, NaN and -inf beams, lost scans), and the scan is placed with the
   pose the controller is given (odometry, which may be noisy and drift);
2. the scan goes into the planner's grid (map plus scans, `PlanningGrid`) and into the
   controller's obstacle memory (`ObstacleMemory`), both told the robot's footprint, as the
   nodes are (returns inside it are the robot itself); with ``track_moving`` the memory's
   tracker follows the scans' clusters and what a moving one built is forgotten, while the
   grid marks every return where it is now (later beams clear where a walker was);
3. the controller's obstacle memory takes the scan, and the map's and the memory's
   obstacles near the robot are assembled (`LocalObstacles`, as the controller node
   assembles them);
4. the planner follows the global_planner node's re-planning policy, through the same
   `Replanner` (core/replanning.py): every ``replan_check_period`` it checks the rest of its
   plan (`RrtStarPlanner.rest_problem`) and re-plans from the pose when it is blocked (and
   every ``replan_period``, if set), with a first turn those obstacles allow where it can;
   the first plan is made at the first step, on the map alone (before the first scan), as
   the node plans a goal that comes before the laser has shown anything;
5. the local controller gets those obstacles and answers; with `Recoveries`
   (core/recoveries.py, as the controller node runs them), a robot that makes no progress
   backs out along its trail, spins and waits for a re-plan instead.

The local controller is any `LocalController` (core/local_controller.py), built by name
(core/controllers.py): the paper's MPC (the `MpcController` the node runs), the tracking MPC
(it tracks the plan's end), pure pursuit (it follows the plan and ignores obstacles), Nav2's
regulated pure pursuit and the DWA. All see the same scans and follow the same re-planned
paths; each gets the obstacles within its reach at every step, and the measured twist when a
real base reports one.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import time
from typing import NamedTuple

import numpy as np

from mpc_local_planner.core.diagnostics import PlanTrigger
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.local_controller import LocalController
from mpc_local_planner.core.mpc.compilation import compile_wait_seconds
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import waypoints_to_poses
from mpc_local_planner.core.planner import RrtStarPlanner
from mpc_local_planner.core.recoveries import Recoveries
from mpc_local_planner.core.replanning import (
    PROGRESS_ANGLE,
    PROGRESS_RADIUS,
    PROGRESS_TIMEOUT,
    ReplanDecision,
    Replanner,
    ReplanOutcome,
    ReplanSettings,
)
from mpc_local_planner.evaluation.rollout import control_step, ControlStep
from mpc_local_planner.perception.grids import PlanningGrid
from mpc_local_planner.perception.local_obstacles import LocalObstacles
from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.perception.scan_obstacles import ObstacleMemory
from mpc_local_planner.perception.scans import Scan
from mpc_local_planner.perception.tracking import ScanTracker
from mpc_local_planner.sim.base import Base
from mpc_local_planner.sim.laser import JACKAL_FOV, SimulatedLaser
from mpc_local_planner.sim.moving import WorldClock
from mpc_local_planner.sim.scan_channel import ScanChannel
from mpc_local_planner.worlds.map_files import OccupancyMap

__all__ = [
    'NavigationLog',
    'NavigationSettings',
    'Navigator',
    'RecordedStep',
]


@dataclass(frozen=True)
class NavigationSettings:
    """The sensing and re-planning settings (the nodes' defaults).

    The re-planning ones map onto the node's (`replan_settings`): replan_check_period is
    1 / replan_check_rate, replan_period is replan_period, and sense off is a check rate of 0.

    Attributes:
        beams: Laser beams per scan (the simulator's scan.beams).
        fov: Laser field of view, radians (the Jackal's 270 degrees).
        range_max: Laser range, metres.
        memory_ttl: How long the controller remembers what the laser saw, seconds.
        replan_check_period: Seconds between two checks of the rest of the plan (the
            planner's 1 / replan_check_rate).
        replan_period: Re-plan the goal this often (seconds) even when the plan is clear;
            0 = only when blocked (the node's replan_period and its default).
        sensing_margin: Obstacles farther than the controller's reach plus this are left out.
        escape_distance: How far a re-plan may start from a robot standing within the
            planner's clearance (see PlanningGrid.escape_point).
        sense: The laser is on. Off, nothing but the map is known: no scans, no re-plans.
        scan_period: Seconds between two scans; None: one scan per control step.
        progress_timeout: Re-plan from where the robot stands when it has not moved
            progress_radius in this many seconds (the node's progress_timeout); 0 = never.
        progress_radius: Metres that count as progress (the node's progress_radius).
        progress_angle: Radians of turn that count as progress (the node's progress_angle).
        track_moving: The memory follows the scans' small clusters and forgets what moving
            ones built (perception/tracking.py): a walker leaves no trail. Off: the world
            is taken as static, as every suite before the dynamic one.

    """

    beams: int = 720
    fov: float = JACKAL_FOV
    range_max: float = 10.0
    memory_ttl: float = 5.0
    replan_check_period: float = 0.5
    replan_period: float = 0.0
    sensing_margin: float = 0.5
    escape_distance: float = 1.0
    sense: bool = True
    scan_period: float | None = None
    progress_timeout: float = PROGRESS_TIMEOUT
    progress_radius: float = PROGRESS_RADIUS
    progress_angle: float = PROGRESS_ANGLE
    track_moving: bool = False

    def replan_settings(self) -> ReplanSettings:
        """Return the re-planner's settings (without sensing the grid never changes: no checks).

        The navigator's steps land on the check period (k * h), so a check is due only once
        the whole period has passed, as the node's timer ticks once a period.
        """
        return ReplanSettings(
            check_period=self.replan_check_period if self.sense else 0.0,
            replan_period=self.replan_period, escape_distance=self.escape_distance,
            progress_timeout=self.progress_timeout, progress_radius=self.progress_radius,
            progress_angle=self.progress_angle)


class RecordedStep(NamedTuple):
    """What one control step gave the local controller, to replay it (mpc_bench's barn rows).

    Attributes:
        t: The step's time, seconds.
        x: The pose the controller was given.
        twist: The measured twist, or None (an ideal robot).
        scan: The scan taken at this step, or None (not due, lost, or no laser).
        plan: The poses of a plan adopted at this step, or None (the plan in force stayed).
        u: The command the step answered (v, omega).

    """

    t: float
    x: np.ndarray
    twist: np.ndarray | None
    scan: Scan | None
    plan: np.ndarray | None
    u: np.ndarray


@dataclass
class NavigationLog:
    """What the navigator did, for metrics and figures.

    Attributes:
        plans: (time, (M, 2) waypoints, trigger) of every plan published.
        replan_failures: re-plans that found no path (the plan in force stayed): the
            re-planner's count.
        plan_seconds: wall time of every planning attempt.
        control_seconds: wall time of each control step's perception and controller (what the
            controller node does per step: memory update, obstacle assembly, solve).
        sensed: (time, obstacles the controller avoided) every snapshot_period.

    """

    plans: list[tuple[float, np.ndarray, str]] = field(default_factory=list)
    replan_failures: int = 0
    plan_seconds: list[float] = field(default_factory=list)
    control_seconds: list[float] = field(default_factory=list)
    sensed: list[tuple[float, list[ConvexPolygon]]] = field(default_factory=list)

    @property
    def replans(self) -> int:
        """Plans after the first."""
        return max(len(self.plans) - 1, 0)


class Navigator:
    """The rollout's controller: laser, grid and memory, re-planning planner, local controller.

    Args:
        local: The local controller.
        reach: How far from the robot obstacles can matter to its next command, metres
            (core/controllers.py `Built.reach`): the obstacles it and the re-planner get
            are those within reach plus settings.sensing_margin.
        geometry: The true world (known and unknown obstacles) the laser scans; a
            `WorldClock` for a world whose obstacles move (scanned as they are at each t).
        grid: The planner's grid (the map the robot is given, empty for no prior map),
            inflated by the planner's robot_radius + clearance.
        planner: The planner on that grid (RrtStarPlanner.on_grid(grid, ...)).
        goal: The goal pose (x, y, theta).
        h: Control period, seconds.
        faces: Faces per obstacle the local controller takes (the NLP's).
        known_map: The map the controller takes rectangles from (None: no prior map).
        settings: Sensing and re-planning settings.
        snapshot_period: Seconds between two records of the sensed obstacles (figures).
        footprint: The robot's footprint: scan returns inside it are the robot itself, not
            obstacles (`classify_beams`), as the nodes read them; None: every return counts.
        base: The real robot's base the rollout drives (sim/base.py), or None: the
            laser scans from the pose step() is given (an ideal robot, whose odometry is
            its pose). With a base it scans from the base's true pose through the
            reality's ScanChannel, and step() gets what odometry says.
        recoveries: The recovery behaviours around the local controller (the node's), or
            None: the controller's answer always stands.
        record: Keep every step's inputs in `recorded` (scans included: memory grows with
            the run), so that the same states can be replayed through other controllers.

    """

    def __init__(self, local: LocalController, geometry: TrueGeometry | WorldClock,
                 grid: PlanningGrid,
                 planner: RrtStarPlanner, goal: np.ndarray, *, reach: float, h: float,
                 faces: int = 8,
                 known_map: OccupancyMap | None = None,
                 settings: NavigationSettings | None = None,
                 snapshot_period: float = 2.0,
                 footprint: Footprint | None = None,
                 base: Base | None = None,
                 recoveries: Recoveries | None = None,
                 record: bool = False) -> None:
        self.local = local
        self.recorded: list[RecordedStep] | None = [] if record else None
        self._adopted: np.ndarray | None = None
        self.recoveries = recoveries
        self.reach = float(reach)
        self.base = base
        self._channel = ScanChannel(base.reality) if base is not None else None
        self._next_scan = 0.0
        self.footprint = footprint
        self.settings = settings or NavigationSettings()
        self.grid = grid
        self.planner = planner
        self.goal = np.asarray(goal, dtype=float)
        self.h = float(h)
        self.laser = SimulatedLaser(geometry, fov=self.settings.fov, beams=self.settings.beams,
                                    range_max=self.settings.range_max)
        self.memory = ObstacleMemory(
            self.settings.memory_ttl,
            tracker=ScanTracker() if self.settings.track_moving else None)
        # the moving tracks as moving polygons for a controller that predicts them (the
        # MPC); the others get what the laser shows of them, as before tracking
        self.obstacles = LocalObstacles(faces, occupancy=known_map, memory=self.memory,
                                        predict_moving=bool(getattr(local, 'predicts_motion',
                                                                    False)))
        self.log = NavigationLog()
        self.replanner = Replanner(self.settings.replan_settings())
        self._snapshot_period = float(snapshot_period)
        self._k = 0

    @property
    def plan(self) -> np.ndarray | None:
        """The plan in force, (M, 2) waypoints."""
        return self.replanner.plan

    def lead_in(self, stamped_poses: np.ndarray) -> None:
        """Take the robot as having driven over stamped poses before the run starts (t = 0).

        A run resumed from a recorded state needs what the robot had when it got there: what
        its laser saw on the way (the planner's grid and the controller's memory, which
        forgets it after ``memory_ttl`` as in the run) and, with recoveries, its trail. Each
        pose is scanned at its time (the ideal laser, from that pose); the run's first step
        is then taken from where the rollout starts (normally the last pose's neighbourhood).

        Args:
            stamped_poses: (K, 4) rows [t, x, y, theta], oldest first, t < 0 (seconds
                before the run's start).

        Raises:
            ValueError: for rows that are not (K, 4), finite, with times increasing and
                negative, or after the first step.

        """
        rows = np.asarray(stamped_poses, dtype=float)
        if rows.ndim != 2 or rows.shape[1] != 4 or not np.all(np.isfinite(rows)):
            msg = f'lead-in rows must be finite [t, x, y, theta], got shape {rows.shape}'
            raise ValueError(msg)
        if len(rows) and (np.any(np.diff(rows[:, 0]) <= 0.0) or rows[-1, 0] >= 0.0):
            msg = 'lead-in times must increase and stay before the start (t < 0)'
            raise ValueError(msg)
        if self._k:
            msg = 'a lead-in comes before the first step'
            raise ValueError(msg)
        for t, *pose in rows:
            if self.settings.sense:
                scan = self.laser.scan(pose, stamp=t)
                self.grid.add_scan(scan, pose, body=self.footprint)
                self.memory.update(scan, pose, body=self.footprint)
            if self.recoveries is not None:
                self.recoveries.trail.record(np.array(pose))
        self.obstacles.scan_updated()

    def step(self, x: np.ndarray) -> ControlStep:
        """Sense, re-plan if needed, and answer for the state x (the rollout's call).

        Raises:
            PlanningError: if no first plan can be made (the rollout stops the run).

        """
        t = self._k * self.h
        self._k += 1
        if self.replanner.plan is None:  # the goal comes first, planned on the map alone
            self._adopt(self.replanner.plan_goal(self.planner, x, self.goal, now=t), x, t)
        scan = self._scan(x, t)
        if scan is not None:
            self.grid.add_scan(scan, x, body=self.footprint)
        started = time.perf_counter()
        if scan is not None:
            self.memory.update(scan, x, body=self.footprint)
            self.obstacles.scan_updated()
        nearby = self.obstacles.near(x[:2], self.reach + self.settings.sensing_margin, now=t)
        perceived = time.perf_counter() - started
        # a re-plan's first turn is one the controller's obstacles allow (Replanner.check)
        self._adopt(self.replanner.check(self.planner, x, now=t, grid=self.grid,
                                         local_obstacles=nearby), x, t)
        started = time.perf_counter() - perceived
        waited = compile_wait_seconds()  # a first use of an NLP on a fresh machine
        self.local.set_obstacles(nearby)
        # a real base reports its twist (an ideal robot's odometry has none)
        twist = self.base.twist() if self.base is not None else None
        pose = np.asarray(x, dtype=float)
        if self.recoveries is None:
            output = self.local.compute(pose, twist, t)
        else:
            self.recoveries.set_obstacles(nearby)
            output = self.recoveries.step(pose, twist, t,
                                          lambda: self.local.compute(pose, twist, t))
        answer = control_step(output)
        self.log.control_seconds.append(time.perf_counter() - started
                                        - (compile_wait_seconds() - waited))
        if not self.log.sensed or t >= self.log.sensed[-1][0] + self._snapshot_period:
            self.log.sensed.append((t, list(nearby)))
        if self.recorded is not None:
            self.recorded.append(RecordedStep(t, pose.copy(), twist, scan, self._adopted,
                                              np.array(answer.u, dtype=float)))
        self._adopted = None
        return answer

    def _scan(self, x: np.ndarray, t: float) -> Scan | None:
        """Return the scan due at t (None: the laser is off, not due, or the scan was lost)."""
        if not self.settings.sense:
            return None
        period = self.settings.scan_period
        if period is not None:
            if t < self._next_scan - 1e-9:
                return None
            self._next_scan = t + period
        if self.base is None:
            return self.laser.scan(x, stamp=t)
        assert self._channel is not None
        scan = self.laser.scan(self.base.pose, stamp=t)
        if self._channel.lost():
            return None
        return scan._replace(ranges=self._channel.corrupt(scan.ranges, scan.range_max))

    def _adopt(self, decision: ReplanDecision, x: np.ndarray, t: float) -> None:
        """Log the re-planner's decision and hand a new plan to the local controller.

        Raises:
            PlanningError: for the first plan; a failed re-plan keeps the plan in force.
            Exception: a planner error other than PlanningError (a bug stops the run).

        """
        if decision.attempted:
            self.log.plan_seconds.append(decision.planning_s)
        self.log.replan_failures = self.replanner.replan_failures
        if decision.outcome is ReplanOutcome.FAILED:
            assert decision.error is not None
            if decision.trigger is PlanTrigger.GOAL or not isinstance(decision.error,
                                                                       PlanningError):
                raise decision.error
            return
        if decision.outcome is not ReplanOutcome.PLANNED:
            return
        assert decision.waypoints is not None and decision.trigger is not None
        self.log.plans.append((t, decision.waypoints, decision.trigger.value))
        poses = waypoints_to_poses(decision.waypoints, float(x[2]), float(self.goal[2]))
        self.local.set_plan(poses)
        self._adopted = poses
        if self.recoveries is not None:
            self.recoveries.plan_changed(poses)
