# Copyright 2026 mpc_local_planner developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.


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
   nodes are (returns inside it are the robot itself);
3. the controller's obstacle memory takes the scan, and the map's and the memory's
   obstacles near the robot are assembled (`LocalObstacles`, as the controller node
   assembles them);
4. the planner follows the global_planner node's re-planning policy, through the same
   `Replanner` (core/replanning.py): every ``replan_check_period`` it checks the rest of its
   plan (`RrtStarPlanner.rest_problem`) and re-plans from the pose when it is blocked (and
   every ``replan_period``, if set), with a first turn those obstacles allow where it can;
   the first plan is made at the first step, on the map alone (before the first scan), as
   the node plans a goal that comes before the laser has shown anything;
5. the local controller gets those obstacles and answers.

The local controllers are adapters (`LocalController`): the paper's MPC through the same
`MpcController` the node runs, the tracking MPC (it tracks the goal, not the plan), pure
pursuit (it follows the plan and ignores obstacles) and the DWA. All see the same scans and
follow the same re-planned paths.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import time
from typing import Any, Protocol, Sequence

import numpy as np

from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.diagnostics import PlanTrigger
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.mpc.compilation import compile_wait_seconds
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import waypoints_to_poses
from mpc_local_planner.core.planner import RrtStarPlanner
from mpc_local_planner.core.reality import Base, ScanChannel
from mpc_local_planner.core.replanning import (
    PROGRESS_ANGLE,
    PROGRESS_RADIUS,
    PROGRESS_TIMEOUT,
    ReplanDecision,
    Replanner,
    ReplanOutcome,
    ReplanSettings,
)
from mpc_local_planner.evaluation.rollout import ControlStep
from mpc_local_planner.perception.grids import PlanningGrid
from mpc_local_planner.perception.laser import JACKAL_FOV, SimulatedLaser
from mpc_local_planner.perception.local_obstacles import LocalObstacles
from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.perception.scan_obstacles import ObstacleMemory
from mpc_local_planner.perception.scans import Scan
from mpc_local_planner.worlds.map_files import OccupancyMap

__all__ = [
    'LocalController',
    'MpcLocal',
    'NavigationSettings',
    'Navigator',
    'PathFollowerLocal',
    'TrackingLocal',
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


class LocalController(Protocol):
    """What the navigator needs of a local controller."""

    reach: float  # metres: obstacles farther from the robot cannot matter to the next step

    def follow(self, poses: np.ndarray) -> None:
        """Follow a new plan of (M, 3) poses from the robot's projection onto it."""

    def avoid(self, obstacles: Sequence[ConvexPolygon]) -> None:
        """Take the obstacles in force (as sensed, not inflated)."""

    def command(self, x: np.ndarray, t: float, velocity: np.ndarray | None = None
                ) -> ControlStep:
        """Return the input for state x at time t (velocity: the measured twist, if known)."""


class MpcLocal:
    """The paper's MPC through `MpcController`, as the controller node runs it."""

    def __init__(self, controller: MpcController) -> None:
        self.controller = controller
        self.reach = controller.config.reach(float(controller.model.u_max[0]))

    def follow(self, poses: np.ndarray) -> None:
        """Set the plan (s restarts at the projection)."""
        self.controller.set_plan(poses)

    def avoid(self, obstacles: Sequence[ConvexPolygon]) -> None:
        """Set the obstacles (the MPC grows them itself)."""
        self.controller.set_obstacles(obstacles)

    def command(self, x: np.ndarray, t: float, velocity: np.ndarray | None = None
                ) -> ControlStep:
        """Compute the command as the node does (stop reasons give a zero input)."""
        output = self.controller.compute(x, velocity, t)
        solution = output.solution
        if not output.fresh and solution is not None:
            # between solves (control_frequency): the verified plan's input, nothing solved
            # (solve_time_s NaN: the solve statistics are over solves only)
            return ControlStep(u=output.u, s=float(solution.s), value=float(solution.value),
                               success=True, detail=output)
        if solution is None:
            # no solve: a failure unless at the goal or turning in place to its heading
            done = output.reason in (Reason.GOAL_REACHED, Reason.ROTATE_TO_HEADING)
            return ControlStep(u=output.u, success=done, detail=output)
        return ControlStep(
            u=output.u, s=float(solution.s), value=float(solution.value),
            solve_time_s=float(solution.solve_time_s),
            success=output.reason is Reason.TRACKING, lyapunov_ok=solution.lyapunov_ok,
            prediction=solution.x_pred, detail=output)


class TrackingLocal:
    """The tracking MPC baseline: it tracks the goal (a target), so plans do not reach it."""

    def __init__(self, mpc: Any) -> None:
        self.mpc = mpc
        self.reach = mpc.config.reach(float(mpc.model.u_max[0]))

    def follow(self, poses: np.ndarray) -> None:
        """Ignore the plan: the baseline knows only its target."""

    def avoid(self, obstacles: Sequence[ConvexPolygon]) -> None:
        """Set the obstacles."""
        self.mpc.set_obstacles(obstacles)

    def command(self, x: np.ndarray, t: float, velocity: np.ndarray | None = None
                ) -> ControlStep:
        """Solve and apply what the MPC applies."""
        solution = self.mpc.solve(x)
        return ControlStep(
            u=np.asarray(solution.u0, dtype=float), value=float(solution.value),
            solve_time_s=float(solution.solve_time_s), success=bool(solution.success),
            lyapunov_ok=solution.lyapunov_ok, prediction=solution.x_pred, detail=solution)


class PathFollowerLocal:
    """A path follower with ``command(x) -> u`` (pure pursuit, DWA).

    Made for the first plan; later plans go to its ``set_path`` when it has one (the DWA
    keeps its current velocity across plans, pure pursuit its speed), else a new one is made.

    Args:
        make: waypoints (M, 2) -> the controller for that plan.
        reach: How far obstacles matter to it, metres (0: it ignores obstacles).
        uses_obstacles: Hand it the obstacles (its ``set_obstacles``) at every step.
        takes_velocity: Its ``command`` takes the measured twist (``velocity=``), as DWB
            reads odometry's; given only when a real base reports one.

    """

    def __init__(self, make: Any, *, reach: float = 0.0, uses_obstacles: bool = False,
                 takes_velocity: bool = False) -> None:
        self._make = make
        self._takes_velocity = takes_velocity
        self.reach = float(reach)
        self._uses_obstacles = uses_obstacles
        self.follower: Any = None
        self._obstacles: list[ConvexPolygon] = []

    def follow(self, poses: np.ndarray) -> None:
        """Hand the new plan over, or make the controller for it."""
        waypoints = np.asarray(poses, dtype=float)[:, :2]
        if self.follower is not None and callable(getattr(self.follower, 'set_path', None)):
            self.follower.set_path(waypoints)
            return
        self.follower = self._make(waypoints)
        if self._uses_obstacles:
            self.follower.set_obstacles(self._obstacles)

    def avoid(self, obstacles: Sequence[ConvexPolygon]) -> None:
        """Hand the obstacles on, if it uses them."""
        self._obstacles = list(obstacles)
        if self._uses_obstacles and self.follower is not None:
            self.follower.set_obstacles(self._obstacles)

    def command(self, x: np.ndarray, t: float, velocity: np.ndarray | None = None
                ) -> ControlStep:
        """Return its command (zero without a plan), timed; the DWA takes the measured twist."""
        if self.follower is None:
            return ControlStep(u=np.zeros(2), solve_time_s=0.0)
        start = time.perf_counter()
        if velocity is not None and self._takes_velocity:
            u = np.asarray(self.follower.command(x, velocity=velocity), dtype=float)
        else:
            u = np.asarray(self.follower.command(x), dtype=float)
        return ControlStep(u=u, solve_time_s=time.perf_counter() - start)


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
        geometry: The true world (known and unknown obstacles) the laser scans.
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
        base: The real robot's base the rollout drives (core/reality.py), or None: the
            laser scans from the pose step() is given (an ideal robot, whose odometry is
            its pose). With a base it scans from the base's true pose through the
            reality's ScanChannel, and step() gets what odometry says.

    """

    def __init__(self, local: LocalController, geometry: TrueGeometry, grid: PlanningGrid,
                 planner: RrtStarPlanner, goal: np.ndarray, *, h: float, faces: int = 8,
                 known_map: OccupancyMap | None = None,
                 settings: NavigationSettings | None = None,
                 snapshot_period: float = 2.0,
                 footprint: Footprint | None = None,
                 base: Base | None = None) -> None:
        self.local = local
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
        self.memory = ObstacleMemory(self.settings.memory_ttl)
        self.obstacles = LocalObstacles(faces, occupancy=known_map, memory=self.memory)
        self.log = NavigationLog()
        self.replanner = Replanner(self.settings.replan_settings())
        self._snapshot_period = float(snapshot_period)
        self._k = 0

    @property
    def plan(self) -> np.ndarray | None:
        """The plan in force, (M, 2) waypoints."""
        return self.replanner.plan

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
        nearby = self.obstacles.near(x[:2], self.local.reach + self.settings.sensing_margin)
        perceived = time.perf_counter() - started
        # a re-plan's first turn is one the controller's obstacles allow (Replanner.check)
        self._adopt(self.replanner.check(self.planner, x, now=t, grid=self.grid,
                                         local_obstacles=nearby), x, t)
        started = time.perf_counter() - perceived
        waited = compile_wait_seconds()  # a first use of an NLP on a fresh machine
        self.local.avoid(nearby)
        if self.base is None:
            answer = self.local.command(np.asarray(x, dtype=float), t)
        else:  # a real base reports its twist: the controllers that use it get it
            answer = self.local.command(np.asarray(x, dtype=float), t, self.base.twist())
        self.log.control_seconds.append(time.perf_counter() - started
                                        - (compile_wait_seconds() - waited))
        if not self.log.sensed or t >= self.log.sensed[-1][0] + self._snapshot_period:
            self.log.sensed.append((t, list(nearby)))
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
        self.local.follow(waypoints_to_poses(decision.waypoints, float(x[2]),
                                             float(self.goal[2])))
