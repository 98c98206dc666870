# SPDX-License-Identifier: Apache-2.0
"""The controller behind the mpc_controller node, without ROS.

`MpcController` implements `LocalController`: it owns a `PathReferenceMPC`, the world's
obstacles and the plan, and decides what to command at each control step: the MPC's first
input, an in-place turn to the goal heading once at the goal position, or zero, with a
`Reason` (no plan, no, stale or invalid odometry, no or stale scan, invalid plan, goal
reached, solver stop, error). Arrival is Nav2's SimpleGoalChecker's (xy_goal_tolerance,
yaw_goal_tolerance, stateful: see `ControllerSettings`). The node only converts messages and
publishes, so everything that can go wrong is testable here without a DDS participant.

Safety rules kept here (see the README's "Safety behaviours"):
- a plan is refused unless it is finite, within MAX_COORDINATE, has two distinct positions and
  at most max_plan_poses poses; a plan through an obstacle is followed (the MPC stops in front
  of the obstacle or goes around it: its terminal state x_N = g_p(s) must be clear too), and
  `path_blockage` says where the remaining plan is first blocked;
- a state is refused unless it is finite and within MAX_COORDINATE;
- stale or missing inputs (`InputFreshness`, the caller's check) are answered with a stop
  (refuse_inputs);
- a speed limit (set_speed_limit) caps the MPC's v bounds, so every plan keeps within it;
- the proof's shifted candidate is applied for at most N consecutive solver failures: its
  inputs run out after N shifts, and then the robot stops;
- a robot the solver stopped, standing within twice its collision margin of an obstacle,
  solves with half the clearance it stands at as its margin until it is that far away again
  (`MarginRelief`: a base that slipped into its margin cannot plan out of the grown
  obstacles);
- a step's solving is bounded by the MPC's budget (SolverSettings.max_solve_time): past it the
  shifted candidate is applied (a failure as above), and `timeouts` counts those steps;
- every command is finite and within the model's bounds, else it is zero;
- the in-place turn to the goal heading is given only where it cannot touch an obstacle (a
  round robot sweeps nothing; a polygon's circumscribed disc must be clear), else the MPC
  steers there.
"""

from __future__ import annotations

import copy
from dataclasses import replace
import math
from typing import Sequence

import numpy as np

from mpc_local_planner.core.braking import Brake
from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.control_output import Blockage, ControlOutput, Reason
from mpc_local_planner.core.control_state import ControlState, Event, Mode
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.evasion import Evasion
from mpc_local_planner.core.goal_checker import GoalChecker
from mpc_local_planner.core.margin_relief import footprint_clearance_at, MarginRelief, standing
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import MpcSolution, PathReferenceMPC, PlanSource
from mpc_local_planner.core.mpc.backends import run_solver, SolverRunner
from mpc_local_planner.core.obstacles import (
    ConvexPolygon,
    first_blocked_segment,
    min_clearance,
    ObstacleSet,
)
from mpc_local_planner.core.paths import (
    ReferencePath,
    remaining_polyline,
    simplify_polyline,
    WaypointPath,
    wrap_angle,
)

__all__ = [
    'MAX_COORDINATE',
    'MpcController',
    'ROTATE_STEPS',
]


# Positions beyond this (metres from the origin) are refused as garbage: a local planner has
# no use for them, and the quartic cost of a coordinate near 1e77 overflows to inf.
MAX_COORDINATE = 1e6
# Control periods over which an in-place turn to the goal heading closes the heading error
# (omega = error / (ROTATE_STEPS step)): in one period a base that answers late overshoots.
ROTATE_STEPS = 2.0
# Tolerances of the Ramer-Douglas-Peucker pass that makes a long plan fit the solver's
# segment capacity, tried in order (metres).
_SIMPLIFY_TOLERANCES = (0.0, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2)


class MpcController:
    """The paper's MPC with the bookkeeping a robot needs around it.

    Args:
        model: the unicycle (its bounds are the command bounds).
        config: MPC settings.
        obstacles: the world's obstacles as described (the MPC inflates them).
        settings: goal tolerances, odometry timeout and plan handling.
        runner: what runs the MPC's NLP solvers (backends.run_solver; see `runner`).

    """

    # a MovingPolygon among the obstacles is predicted over the horizon (moving_obstacles.py)
    predicts_motion = True

    def __init__(self, model: Unicycle | None = None, config: MpcConfig | None = None, *,
                 obstacles: Sequence[ConvexPolygon] = (),
                 settings: ControllerSettings | None = None,
                 runner: SolverRunner = run_solver) -> None:
        # the model as set, and the one in force: its v bounds capped by the speed limit
        self._given_model = model or Unicycle()
        self._speed_limit: float | None = None
        self._model = self._given_model
        self._config = config or MpcConfig()
        self._obstacles = list(obstacles)
        settings = settings or ControllerSettings()
        self._brake = Brake(settings.max_decel)
        self._goal_checker = GoalChecker(settings)
        self.settings = settings
        self._mpc = PathReferenceMPC(self._model, self._config, obstacles=self._obstacles,
                                     runner=runner)
        self._path: ReferencePath | None = None
        self._solved_last_step = False
        self._solver_failures = 0
        self._timeouts = 0
        # the plan as a polyline (x, y) for path_blockage, and the segment of the robot's
        # latest projection onto it (projections only move forward along a plan)
        self._polyline: np.ndarray | None = None
        self._projection_segment = 0
        # what the last step left in force: a plan's input or the solver's stop, held until
        # the next step's instant (control_frequency), or a turn to the goal heading
        self._state = ControlState()
        self._last_call: float | None = None
        # the latest command and measured twist (the MPC's rate bounds start from them)
        self._last_u = np.zeros(2)
        self._velocity: np.ndarray | None = None
        # the MPC solves with the collision margin, or (MarginRelief) without it
        self._relief = MarginRelief()
        # moves out of a predicted moving obstacle's way (built for the MPC in force)
        self._evasion: Evasion | None = None

    # ------------------------------------------------------------------ configuration
    @property
    def settings(self) -> ControllerSettings:
        """The checks around the MPC in force; a new value applies from the next call."""
        return self._settings

    @settings.setter
    def settings(self, settings: ControllerSettings) -> None:
        # the brake keeps its own copy of the deceleration limits: a change at run time (the
        # node's max_decel parameter) must reach it, or stops would brake with the old ones
        self._settings = settings
        self._brake.max_decel = np.asarray(settings.max_decel, dtype=float)
        self._goal_checker.settings = settings

    @property
    def model(self) -> Unicycle:
        """The robot model as set (set_model); its v bounds are capped by speed_limit."""
        return self._given_model

    @property
    def runner(self) -> SolverRunner:
        """What runs the MPC's NLP solvers; a new one solves from the next step.

        A test's failing solver, or a benchmark's instrumented one; it stays through
        rebuilds (set_model, set_speed_limit).
        """
        return self._mpc.runner

    @runner.setter
    def runner(self, runner: SolverRunner) -> None:
        self._mpc.runner = runner

    @property
    def mode(self) -> Mode:
        """What the last step left in force: a plan's input, the solver's stop, a turn."""
        return self._state.mode

    @property
    def speed_limit(self) -> float | None:
        """The cap on |v| in force (m/s, set_speed_limit), or None."""
        return self._speed_limit

    @property
    def config(self) -> MpcConfig:
        """The MPC settings in force."""
        return self._config

    @property
    def path(self) -> ReferencePath | None:
        """The reference path in force, or None."""
        return self._path

    @property
    def mpc(self) -> PathReferenceMPC:
        """The underlying MPC (for inspection)."""
        return self._mpc

    @property
    def obstacles(self) -> tuple[ConvexPolygon, ...]:
        """The obstacles as described (the world's), not inflated."""
        return tuple(self._obstacles)

    @property
    def grown_obstacles(self) -> tuple[ConvexPolygon, ...]:
        """The obstacles as the MPC sees them: grown by robot radius plus collision margin."""
        return self._mpc.inflated_obstacles

    @property
    def active_obstacles(self) -> tuple[ConvexPolygon, ...]:
        """The grown obstacles the last solve held in its NLP (Farkas constraints)."""
        return self._mpc.last_active_obstacles

    @property
    def solver_failures(self) -> int:
        """Control steps since construction whose input is not a fresh solver solution.

        Counted as analyze_bag counts solver failures (source other than 'solver'), plus
        solves that raised. The MPC's own count (MpcSolution.failures) is of consecutive
        failures and restarts at every success; this total is what an operator wants to see
        grow in the diagnostics.
        """
        return self._solver_failures

    @property
    def timeouts(self) -> int:
        """Control steps since construction whose solving ran out of its time budget.

        Counted from MpcSolution.timed_out: the budget (SolverSettings.max_solve_time, half the
        period by default) cut a solve or left a retry out. Such a step applies the verified
        shifted candidate (counted in solver_failures too), or rarely a solver plan found
        before the cut; a count that grows says the machine is too slow (or too loaded) for
        the period.
        """
        return self._timeouts

    def update_config(self, config: MpcConfig) -> None:
        """Use new MPC settings from the next solve on (a shape change rebuilds there)."""
        self._config = config
        self._relief = MarginRelief()
        self._mpc.update_config(config)
        self._state.on(Event.DROP)

    def set_model(self, model: Unicycle) -> None:
        """Use new input bounds (capped by speed_limit): the NLP is rebuilt at the next solve."""
        self._given_model = model
        self._use_model(_capped(model, self._speed_limit))

    def set_speed_limit(self, v_max: float | None) -> None:
        """Cap |v| at v_max (m/s, > 0) from the next compute; None lifts the cap.

        The cap enters the MPC as its v bounds (the NLP is rebuilt for them, as for any new
        bounds, when they change), so every verified plan and every command keeps within it;
        obstacles are grown by the margin of the capped speed (v_max h / 2 by default).

        Raises:
            ValueError: if v_max is not None and not a finite number > 0.

        """
        if v_max is not None:
            v_max = float(v_max)
            if not (math.isfinite(v_max) and v_max > 0):
                msg = f'a speed limit must be > 0 and finite (None lifts it), got {v_max}'
                raise ValueError(msg)
        self._speed_limit = v_max
        model = _capped(self._given_model, v_max)
        if model != self._model:
            self._use_model(model)

    def _use_model(self, model: Unicycle) -> None:
        self._model = model
        self._relief = MarginRelief()
        self._mpc = PathReferenceMPC(model, self._config, obstacles=self._obstacles,
                                     path=self._path, runner=self._mpc.runner)
        self._state.on(Event.DROP)

    def set_obstacles(self, obstacles: Sequence[ConvexPolygon]) -> None:
        """Replace the obstacles (as described, not inflated); cheap enough for every step.

        Nothing is rebuilt and the warm start and the Lyapunov history are kept: the next
        solve verifies the shifted candidate against the obstacles now in force (the MPC
        checks every reachable obstacle geometrically and activates lazily), so a candidate
        that an obstacle seen since blocks is not applied. The same obstacles again (the
        same objects, as when no new scan or map came) change nothing.

        Raises:
            ValueError: if an obstacle has more faces than config.solving.faces_per_obstacle (see
                within_faces).

        """
        new = list(obstacles)
        if len(new) == len(self._obstacles) and all(
                a is b for a, b in zip(new, self._obstacles, strict=True)):
            return
        self._mpc.set_obstacles(new)
        self._obstacles = new

    def set_path(self, path: ReferencePath) -> None:
        """Follow path (an analytic path, or a WaypointPath built elsewhere)."""
        self._mpc.set_path(path)
        self._path = path
        self._solved_last_step = False
        if isinstance(path, WaypointPath):
            polyline = path.knots[:, :2]
        else:
            polyline = path.sample()[1][:, :2]
        self._polyline = np.asarray(polyline, dtype=float)
        self._projection_segment = 0
        self._goal_checker.reset()
        self._state.on(Event.NEW_PLAN)

    def set_plan(self, poses: np.ndarray) -> WaypointPath:
        """Follow a global plan of (M, 3) poses (x, y, yaw), as a nav_msgs/Path carries.

        The first and last headings become turn-in-place segments at the ends; a plan with
        more corners than the solver's capacity is simplified (Ramer-Douglas-Peucker with
        growing tolerance) until it fits. The plan in force is kept if this one is refused.

        Returns:
            The path now followed.

        Raises:
            ValueError: saying what is wrong (Reason.INVALID_PLAN's detail) if poses is
                not (M, 3) finite numbers within MAX_COORDINATE with two distinct
                positions, or has more than max_plan_poses rows. A plan through an obstacle
                is not refused: the MPC keeps the robot out of the obstacle (it stops in
                front of it, or goes around where the horizon reaches past it), and
                path_blockage says where the plan is blocked, for a planner to re-plan.

        """
        arr = np.asarray(poses, dtype=float)
        if arr.ndim != 2 or arr.shape[1] != 3:
            msg = f'poses must have shape (M, 3), got {arr.shape}'
            raise ValueError(msg)
        if len(arr) < 2:
            msg = f'needs at least two poses, got {len(arr)}'
            raise ValueError(msg)
        if len(arr) > self.settings.max_plan_poses:
            msg = (f'{len(arr)} poses, more than max_plan_poses '
                   f'({self.settings.max_plan_poses})')
            raise ValueError(msg)
        if not np.all(np.isfinite(arr)):
            msg = 'poses contain NaN or inf'
            raise ValueError(msg)
        if np.max(np.abs(arr[:, :2])) > MAX_COORDINATE:
            msg = (f'a position is more than {MAX_COORDINATE:g} m from '
                   'the origin')
            raise ValueError(msg)
        points = arr[:, :2]
        for tolerance in _SIMPLIFY_TOLERANCES:
            simplified = simplify_polyline(points, tolerance) if tolerance > 0 else points
            # straight segments + corners + the two end turns
            if 2 * len(simplified) - 1 <= self.settings.capacity:
                break
        else:
            msg = (f'{len(points)} poses do not fit '
                   f'{self.settings.capacity} segments even simplified at '
                   f'{_SIMPLIFY_TOLERANCES[-1]} m')
            raise ValueError(msg)
        try:
            path = WaypointPath(simplified, start_heading=float(arr[0, 2]),
                                goal_heading=float(arr[-1, 2]),
                                turn_length=self.settings.turn_length,
                                capacity=self.settings.capacity)
        except ValueError as err:
            msg = str(err)
            raise ValueError(msg) from None
        self.set_path(path)
        return path

    def check_state(self, state: np.ndarray) -> np.ndarray:
        """Return state as a float (3,) array if it is a usable measurement.

        Raises:
            ValueError: if it is not three finite numbers with a position within
                MAX_COORDINATE of the origin.

        """
        x = np.asarray(state, dtype=float).reshape(-1)
        if x.shape != (3,) or not np.all(np.isfinite(x)):
            msg = f'the state must be three finite numbers (x, y, yaw), got {x}'
            raise ValueError(msg)
        if max(abs(x[0]), abs(x[1])) > MAX_COORDINATE:
            msg = (f'the position ({x[0]:g}, {x[1]:g}) is more than {MAX_COORDINATE:g} m from '
                   'the origin')
            raise ValueError(msg)
        return x

    def prepare(self) -> None:
        """Build the NLPs a run will need now, so that no control step waits for a build.

        Uses the MPC's prepare() when it has one: up to config.solving.obstacle_slots obstacles in
        reach, boxes and sensed polygons alike (the laser's obstacles come later); else
        solves nothing and the first control step builds.
        """
        prepare = getattr(self._mpc, 'prepare', None)
        if prepare is None or self._path is None:
            return
        prepare(self._config.solving.obstacle_slots)

    def clear_path(self) -> None:
        """Forget the plan: the controller commands zero until a new one comes."""
        self._path = None
        self._polyline = None
        self._goal_checker.reset()
        self._state.on(Event.NEW_PLAN)
        self._brake.stop()
        self._mpc.reset()

    def reset(self) -> None:
        """Forget the run: the plan, arrival, held inputs and the MPC's candidate and history.

        What a new controller would know, but the obstacles, settings, speed limit and the
        counters since construction (solver_failures, timeouts) stay.
        """
        self.clear_path()
        self._projection_segment = 0
        self._solved_last_step = False
        self._last_call = None
        self._last_u = np.zeros(2)
        self._velocity = None

    def path_blockage(self, state: np.ndarray | None) -> Blockage:
        """Say where the remaining plan first meets an obstacle grown as the MPC grows it.

        The remaining plan is the plan's polyline from the robot's projection onto it (the
        nearest point, on the segment of the last projection or a later one) to its end.

        Args:
            state: the robot's (x, y, yaw), or None (then: not blocked, NaN).

        """
        polyline = self._polyline
        if polyline is None or state is None:
            return Blockage()
        try:
            position = self.check_state(state)[:2]
        except ValueError:
            return Blockage()
        remaining, self._projection_segment = remaining_polyline(
            polyline, position, forward_from=self._projection_segment)
        grown = self.grown_obstacles
        if not grown or len(remaining) < 2:
            return Blockage()
        hits = ObstacleSet(grown).segment_hits(remaining[:-1], remaining[1:], grazing=False)
        blocked = np.flatnonzero(np.any(hits, axis=1))
        if not len(blocked):
            return Blockage()
        i = int(blocked[0])
        lengths = np.hypot(*np.diff(remaining, axis=0).T)
        return Blockage(True, float(np.sum(lengths[:i]))
                        + _entry(remaining[i], remaining[i + 1],
                                 [o for o, hit in zip(grown, hits[i], strict=True) if hit]))

    # ------------------------------------------------------------------ control
    def goal_error(self, state: np.ndarray) -> tuple[float, float]:
        """Return (position, |heading|) error of state to the end of the path."""
        if self._path is None:
            return math.inf, math.inf
        return GoalChecker.errors(state, self._path.goal)

    def compute(self, pose: np.ndarray | None, twist: np.ndarray | None,
                now: float) -> ControlOutput:
        """Return the command for the measured pose at time now.

        Never raises: anything unexpected becomes a zero command with Reason.ERROR. At the
        goal position (xy_goal_tolerance) and off its heading the robot turns in place
        (Reason.ROTATE_TO_HEADING); arrived, the command is zero (Reason.GOAL_REACHED), and
        with settings.stateful it stays so, whatever the pose, until a new plan. The MPC
        solves once per step h; a call sooner than that after a solve that gave an input
        (settings.control_frequency) returns that input again, after the same checks
        (ControlOutput.fresh False). A stop of a moving robot brakes along the last verified
        plan within settings.max_decel (`Brake`). The inputs' ages are the caller's to check
        (`InputFreshness`, then refuse_inputs).

        Args:
            pose: (3,) measured (x, y, yaw), or None when no odometry has come.
            twist: the measured twist (v, omega), if known: with MpcConfig.max_accel the
                MPC's first input starts from it after a step without a plan's input (the
                base may still be moving); while plans are applied, from the input commanded.
            now: the current time (seconds).

        """
        self._velocity = twist
        output = self._compute(pose, now)
        self._last_call = now
        self._last_u = np.asarray(output.u, dtype=float)
        return output

    def refuse_inputs(self, reason: Reason, now: float) -> ControlOutput:
        """Return the stop for inputs the caller found stale or missing (`InputFreshness`).

        The control call compute would be for a pose it cannot trust: no plan and arrival
        answer first (as in compute), else a moving robot brakes within settings.max_decel.
        """
        if self._path is None:
            output = self._idle(Reason.NO_PLAN)
        elif self.settings.stateful and self._goal_checker.arrived:
            output = self._idle(Reason.GOAL_REACHED)
        else:
            output = self._idle(reason, now=now)
        self._last_call = now
        self._last_u = np.asarray(output.u, dtype=float)
        return output

    def _compute(self, pose: np.ndarray | None, now: float) -> ControlOutput:
        if self._path is None:
            return self._idle(Reason.NO_PLAN)
        if self.settings.stateful and self._goal_checker.arrived:
            # arrived once: the plan is done, whatever the measured pose does now
            return self._idle(Reason.GOAL_REACHED)
        if pose is None:
            return self._idle(Reason.NO_ODOM, now=now)
        try:
            x = self.check_state(pose)
        except ValueError as err:
            return self._idle(Reason.INVALID_ODOM, str(err), now=now)
        try:
            position_met, arrived = self._goal_checker.check(x, self._path.goal)
            if arrived:
                return self._idle(Reason.GOAL_REACHED)
            if position_met:
                turn = self._rotate_to_heading(x)
                if turn is not None:
                    self._drop_warm_start()
                    self._state.on(Event.ROTATE)
                    self._brake.stop()
                    return ControlOutput(turn, None, Reason.ROTATE_TO_HEADING)
            in_force = self._state
            # (a clock that jumped back solves at once: the held plan's time is not now's)
            held = in_force.holding(Mode.PLAN, now, self._hold_period())
            if held is not None:
                return held._replace(u=self._planned_input(held.solution,
                                                           now - in_force.since),
                                     fresh=False)
            stopped = in_force.holding(Mode.STOP, now, self._hold_period())
            if stopped is not None:
                # the solver found no verified input at this step: keep braking (or
                # standing) until the next step's instant, as a plan is kept for its step
                return self._idle(Reason.STOP, stopped.detail, now=now,
                                  solution=stopped.solution,
                                  keep_warm_start=True)._replace(fresh=False)
            self._relieve_margin(x)
            if self._config.max_accel is None:
                solution = self._mpc.solve(x)
            else:
                solution = self._mpc.solve(x, previous_input=self._input_before(now))
        except Exception as err:  # a controller must not die: stop instead
            self._solver_failures += 1
            return self._idle(Reason.ERROR, f'{type(err).__name__}: {err}', now=now)
        self._solved_last_step = True
        if not solution.success:
            self._solver_failures += 1
        if solution.timed_out:
            self._timeouts += 1
        source = PlanSource(solution.source)
        if source is PlanSource.STOP:
            evasive = self._evade(x, now, solution)
            if evasive is not None:
                return evasive
            # no verified input: the MPC keeps its own state (failure count, the plan it
            # carries) for the next step, as it decides what to try from there
            output = self._idle(Reason.STOP, now=now, solution=solution, keep_warm_start=True)
            self._state.on(Event.SOLVER_STOP, now=now, output=output)
            return output
        if source is PlanSource.CANDIDATE and solution.failures > self._config.horizon:
            # the shifted candidate has run out (N shifts leave only steady-state inputs):
            # stop, and let the next step start over from the measured state
            return self._idle(Reason.STOP, 'the shifted candidate ran out', now=now,
                              solution=solution)
        u = self._planned_input(solution, 0.0)
        if u.shape != (2,) or not np.all(np.isfinite(u)):
            return self._idle(Reason.ERROR, f'non-finite input {u}', now=now,
                              solution=solution)
        u = np.clip(u, self._model.u_min, self._model.u_max)
        reason = Reason.TRACKING if solution.success else Reason.CANDIDATE
        detail = 'collision margin relieved: standing within it' if self._relief.active else ''
        output = ControlOutput(u, solution, reason, detail)
        self._state.on(Event.SOLVED, now=now, output=output)
        self._brake.stop()
        return output

    def _evade(self, x: np.ndarray, now: float, solution: MpcSolution) -> ControlOutput | None:
        """Return a move out of a moving obstacle's way instead of the solver's stop, or None.

        Only when the MPC holds a moving obstacle and the stop (braking along the last plan,
        or standing) is predicted to meet one within the horizon (core/evasion.py). The MPC
        starts over at the next step, as after any step without its plan.
        """
        mpc = self._mpc
        if not mpc.holds_moving_obstacles:
            return None
        evasion = self._evasion
        if evasion is None or evasion.clearance is not mpc.clearance \
                or evasion.config != mpc.config or evasion.model != mpc.model:
            evasion = self._evasion = Evasion(mpc.model, mpc.config, mpc.clearance)
        brake = copy.deepcopy(self._brake)
        self._start_braking(brake, now)
        stopping = brake.preview(x, self._model, self._config.step, self._config.horizon)
        before = self._input_before(now) if self._config.max_accel is not None else None
        move = evasion.choose(x, stopping, ObstacleSet(mpc.reachable_obstacles(x)),
                              self._path_ahead(x), before)
        if move is None:
            return None
        plan = solution._replace(
            u0=move.u[0], x_pred=move.x, u_pred=move.u, source=PlanSource.EVASION,
            u_before=before if self._config.first_order_hold else None,
            status=f'{solution.status}; evading a moving obstacle')
        self._drop_warm_start()
        u = np.clip(self._planned_input(plan, 0.0), self._model.u_min, self._model.u_max)
        detail = (f'stopping would meet a moving obstacle in '
                  f'{move.stop_conflict * self._config.step:.1f} s')
        output = ControlOutput(u, plan, Reason.EVADE, detail)
        self._state.on(Event.SOLVED, now=now, output=output)
        self._brake.stop()
        return output

    def _path_ahead(self, x: np.ndarray) -> np.ndarray:
        """Return the path's position a horizon's travel at full speed beyond x's projection."""
        assert self._path is not None
        ahead = float(self._model.u_max[0]) * self._config.step * self._config.horizon
        s = self._path.project(x) + ahead / max(self._path.length(), 1e-9)
        return np.asarray(self._path.pose(min(s, 1.0)), dtype=float)[:2]

    def _relieve_margin(self, x: np.ndarray) -> None:
        """Give the MPC the obstacles grown by the margin, or by the relieved one (MarginRelief).

        Only a step after the solver's stop can start the relief, and only a relieved step
        can end it, so the clearance is computed on those steps alone.
        """
        margin = self._config.collision_margin or 0.0
        stopped = self._state.mode is Mode.STOP
        if margin <= 0 or not (stopped or self._relief.active):
            return
        was = self._relief.active
        twist = self._velocity if self._velocity is not None else self._last_u
        clearance = footprint_clearance_at(self._config.robot_footprint, x, self._obstacles)
        if self._relief.update(margin=margin, clearance=clearance, solver_stopped=stopped,
                               is_standing=standing(twist)) != was:
            self._mpc.update_config(replace(self._config, collision_margin=self._relief.margin)
                                    if self._relief.active else self._config)

    def _planned_input(self, solution: MpcSolution | None, elapsed: float) -> np.ndarray:
        """Return the command elapsed seconds after the solve of solution.

        A zero hold: its first input (the plan holds it over the step). A first-order hold
        (solution.u_before set): the plan's velocity ramp at elapsed + actuation_delay, led
        by the base's latency and lag so that the base's velocity follows the ramp.
        """
        assert solution is not None
        if solution.u_before is None:
            return np.asarray(solution.u0, dtype=float).reshape(-1)
        u = solution.velocity_at(elapsed + self.settings.actuation_delay, self._config.step)
        return np.clip(u, self._model.u_min, self._model.u_max)

    def _input_before(self, now: float) -> np.ndarray | None:
        """Return what the MPC's rate bounds start from (MpcConfig.max_accel).

        The input of the plan in force now (the proof's candidate follows it): a zero hold's
        first input, held over the step; a first-order hold's velocity ramp where it is
        now, not where it began (an evasion, after which the MPC has no plan of its own to
        start from, began each next one from its ramp's start: the robot fell back to rest
        at every step and a walker behind it caught up). After a stop or a turn, the
        measured twist if there is one (the base may still be moving), else what was
        commanded.
        """
        held = self._state.plan()
        if held is not None:
            solution = held.solution
            if solution is not None and solution.u_before is not None:
                elapsed = max(now - self._state.since, 0.0)
                return np.clip(solution.velocity_at(elapsed, self._config.step),
                               self._model.u_min, self._model.u_max)
            return held.u
        if self._velocity is not None:
            return np.asarray(self._velocity, dtype=float)
        return self._last_u

    def _hold_period(self) -> float:
        """Seconds after a solve during which calls apply its input instead of solving.

        Half a control period short of h, so that the call nearest to the next step's
        instant solves even when the timer fires a little early.
        """
        return self._config.step - 0.5 / self.settings.control_frequency

    def stop(self, reason: Reason, detail: str = '', *, now: float | None = None
             ) -> ControlOutput:
        """Return the stop command with reason (the node's verdict on refused input).

        With now, a moving robot brakes along its last verified plan (settings.max_decel);
        the call counts as a control call (the braking's clock). The warm start is dropped
        as after any step without an MPC input, so that the next solve starts from the
        measured state instead of a shift of a plan never applied.
        """
        output = self._idle(reason, detail, now=now)
        if now is not None:
            self._last_call = now
        return output

    def _idle(self, reason: Reason, detail: str = '', *, now: float | None = None,
              solution: MpcSolution | None = None,
              keep_warm_start: bool = False) -> ControlOutput:
        """Return a stop: zero, or with now the braking command along the last plan.

        Arrival and the end of a plan are not braked (the robot is slow at the goal, and a
        cancelled plan is Nav2's zero); everything else that stops a moving robot is.
        """
        u = np.zeros(2)
        if now is None or reason in (Reason.NO_PLAN, Reason.GOAL_REACHED):
            self._brake.stop()
        else:
            self._start_braking(self._brake, now)
            last = self._last_call if self._last_call is not None else now
            u = np.clip(self._brake.command(now - last), self._model.u_min, self._model.u_max)
        if keep_warm_start:
            self._state.on(Event.END_PLAN)
        else:
            self._drop_warm_start()
        return ControlOutput(u, solution, reason, detail)

    def _start_braking(self, brake: Brake, now: float) -> None:
        """Start brake along the plan in force at now, unless it brakes already (or none is)."""
        held = self._state.plan()
        if not brake.active and held is not None and held.solution is not None:
            plan = held.solution
            lead = 0.0 if plan.u_before is None else self.settings.actuation_delay
            brake.start(plan.u_pred, self._config.step, now - self._state.since + lead,
                        plan.u_before)

    def _drop_warm_start(self) -> None:
        # The shifted warm start assumes its first input was applied: after a step without
        # one, start the MPC over (s restarts at the projection).
        self._state.on(Event.DROP)
        if self._solved_last_step:
            self._mpc.reset()
            self._solved_last_step = False

    def _rotate_to_heading(self, state: np.ndarray) -> np.ndarray | None:
        """Return the input that turns the robot in place towards the plan's last heading.

        omega closes the heading error over ROTATE_STEPS control periods (within the
        bounds), so that a lagging base does not overshoot much. A round robot sweeps nothing
        turning in place; a polygon sweeps the disc of its circumscribed radius, so the turn
        is given only when that disc is clear of the obstacles grown as the MPC grows them.

        Returns:
            (v, omega) with v = 0, or None when the turn could touch an obstacle (the MPC
            steers to the heading then).

        """
        footprint = self._config.robot_footprint
        if not footprint.is_circle:
            reach = footprint.radius + self._config.inflation(float(self._model.u_max[0]))
            point = state[None, :2]
            near = [o for o in self._obstacles
                    if o.signed_distance_lower_bound(point)[0] <= reach]
            if min_clearance(near, point) <= reach:
                return None
        error = float(wrap_angle(self._path.goal[2] - state[2]))
        omega = error / (ROTATE_STEPS * self._config.step)
        return np.clip(np.array([0.0, omega]), self._model.u_min, self._model.u_max)


def _capped(model: Unicycle, v_max: float | None) -> Unicycle:
    """Return model with |v| capped at v_max (None, or a cap above its bounds: model)."""
    if v_max is None:
        return model
    v_min = float(model.u_min[0])
    new_max, new_min = min(model.v_max, v_max), max(v_min, -v_max)
    if new_max == model.v_max and new_min == v_min:
        return model
    if model.v_min is None and new_min == -new_max:
        return replace(model, v_max=new_max)
    return replace(model, v_max=new_max, v_min=new_min)


def _entry(a: np.ndarray, b: np.ndarray, obstacles: list[ConvexPolygon]) -> float:
    """Return the distance from a along the segment to b at which it first meets obstacles.

    Bisection on `first_blocked_segment` (grazing does not count, as in path_blockage)
    over the segment's first part: 40 halvings put it within 1e-12 of the length.
    """
    length = float(np.hypot(*(b - a)))
    if first_blocked_segment(obstacles, np.array([a, a])) is not None:
        return 0.0
    lo, hi = 0.0, 1.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if first_blocked_segment(obstacles, np.array([a, a + mid * (b - a)])) is not None:
            hi = mid
        else:
            lo = mid
    return hi * length
