# SPDX-License-Identifier: Apache-2.0
"""THE closed loop without ROS: one controller, one model, one stop rule.

The experiments, the evaluation suites and the benchmark all run their closed loops here, so
they stop for the same reasons and write the same rows (the trajectory.csv format).

The controller is a local controller (core/local_controller.py: ``compute(pose, twist, t)``,
its `ControlOutput` recorded as a `ControlStep` by `control_step`), the paper's MPC as it
is (``solve(x) -> MpcSolution``, recorded by `solution_step`), or anything with
``step(x) -> ControlStep`` (the `RolloutController` protocol: the navigator). The plant is
the model's ``step(x, u, h)``.

Each step k, at t = k h: the controller answers for the state x_k, the row (t, x_k, its answer)
is recorded, then the stop rule is applied to x_k in this order:

1. COLLISION: a clearance function was given and the clearance at x_k is <= 0;
2. REACHED: position error <= position_tolerance and wrapped heading error
   |wrap_angle(theta - theta_goal)| <= heading_tolerance (inf: position only);
3. STALLED: |u| < stall_input for stall_steps consecutive steps (a local minimum);
4. TIME_LIMIT: t >= time_limit.

Otherwise u_k is applied: x_{k+1} = model.step(x_k, u_k, h). A controller that raises
PlanningError (it has no way to the goal) or commands a non-finite input ends the run as
STOPPED; its last row has a zero input.

The plant may instead be a real robot's base (sim/base.py `Base`, the model the
unicycle_simulator node runs): then the controller is called every h with what odometry
reports (noise and drift included), its command is sent to the base at that instant and acts
after the base's latency, lag and acceleration limits, and the rows hold the TRUE pose (the
stop rule and contacts judge the truth; the controller never sees it). h is then the control
period (1 / control_frequency), and stall_steps counts periods of stall_period seconds
(StopRule.stall_period), so that a stall lasts as long in seconds at any control rate.

In a world with moving obstacles the clearance depends on the time too: ``clearance_at(x, t)``
replaces ``clearance`` in rule 1, and the run's contact is told apart as the simulator tells
it (sim/moving.py): ACTIVE when the robot was moving into it (a real base's true velocity,
else the input applied since the last step), PASSIVE when it stood still and an obstacle ran
into it (`Rollout.contact`).

Odometry that drifts is not the pose in ``map``, where the plan and the obstacles are: the
nodes then compose it with a localizer's poses (perception/localization.py), and so does the
rollout given a `Localizer` (sim/localizer.py, the simulator's stand-in for AMCL): at each
control instant the odometry (and its twist) goes into a `LocalizedPose`, a localizer pose
due then (the TRUE pose with noise) updates its correction map <- odom at that instant, and
the controller gets the latest odometry through the correction: the pose in ``map``, as the
controller and planner nodes compute it with ``localization_topic``.

Nothing here reads a clock but to report step times. The MPCs of the evaluation suites bound
a step's solving by solver iterations (EVALUATION_BUDGET, SolverSettings.budget 'iterations'), not
by wall time as the robot does: the same command gives the same runs on any machine under any
load (with wall time, four runs of BARN with sensing at 2 m/s gave 95 to 98 successes).
"""

from __future__ import annotations

import enum
import math
import time
from typing import Any, Callable, NamedTuple, Protocol, Sequence, TYPE_CHECKING

import numpy as np

from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.local_controller import LocalController
from mpc_local_planner.core.mpc.compilation import compile_wait_seconds
from mpc_local_planner.core.paths import wrap_angle
from mpc_local_planner.evaluation.trajectory import trajectory_row
from mpc_local_planner.perception.localization import LocalizedPose
from mpc_local_planner.sim.moving import contact_kind, ContactKind

if TYPE_CHECKING:
    from mpc_local_planner.core.mpc import MpcSolution
    from mpc_local_planner.core.obstacles import ConvexPolygon
    from mpc_local_planner.sim.base import Base
    from mpc_local_planner.sim.localizer import Localizer

__all__ = [
    'circle_clearance',
    'Clearance',
    'control_step',
    'ControlStep',
    'EVALUATION_BUDGET',
    'Outcome',
    'polygon_clearance',
    'rollout',
    'Rollout',
    'RolloutController',
    'solution_step',
    'STALL_INPUT',
    'STALL_STEPS',
    'StopRule',
    'TimedClearance',
]

# The MPC budget of the evaluation suites (SolverSettings.budget): solver iterations, the
# wall budget's worth on a typical machine (MpcConfig.solve_iterations()), the same under any
# load. 'wall' gives the robot's conditions on this machine, as it is loaded now.
EVALUATION_BUDGET = 'iterations'
# A run whose commands stay below this (each component, absolute) for STALL_STEPS steps has
# stopped for good away from the goal.
STALL_INPUT = 1e-4
STALL_STEPS = 25
# Seconds of odometry kept for the localizer's stamps (the nodes' ODOM_HISTORY_S).
ODOM_HISTORY = 2.0

Clearance = Callable[[np.ndarray], np.ndarray]
# The clearance of a pose (3,) at a time t, for a world whose obstacles move.
TimedClearance = Callable[[np.ndarray, float], float]


class Outcome(enum.Enum):
    """Why a rollout ended."""

    REACHED = 'reached'
    COLLISION = 'collision'
    STALLED = 'stalled'
    TIME_LIMIT = 'time limit'
    STOPPED = 'stopped'


class StopRule(NamedTuple):
    """When a rollout ends (see the module docstring for the order of the checks).

    Attributes:
        time_limit: seconds of simulated time; the last row is at t = ceil(time_limit / h) h.
        position_tolerance: metres to the goal position that count as reached.
        heading_tolerance: radians of wrapped heading error that count as reached; inf
            compares positions only (the BARN challenge).
        stall_input: a command with every |component| below this is standing still.
        stall_steps: consecutive standing-still steps that end the run as STALLED.
        stall_period: the step stall_steps counts, seconds (None: the rollout's h); a
            rollout at another control period stalls after the same time.

    """

    time_limit: float
    position_tolerance: float
    heading_tolerance: float = math.inf
    stall_input: float = STALL_INPUT
    stall_steps: int = STALL_STEPS
    stall_period: float | None = None

    def reached(self, x: np.ndarray, goal: np.ndarray) -> bool:
        """Say whether the pose x is within the tolerances of the goal (headings wrapped)."""
        position_error = math.hypot(float(x[0]) - float(goal[0]), float(x[1]) - float(goal[1]))
        if position_error > self.position_tolerance:
            return False
        if math.isinf(self.heading_tolerance):
            return True
        heading_error = abs(float(wrap_angle(float(x[2]) - float(goal[2]))))
        return heading_error <= self.heading_tolerance

    def steps(self, h: float) -> int:
        """Return the index of the last step within the time limit at step length h."""
        return int(math.ceil(self.time_limit / h - 1e-9))

    def still_steps(self, h: float) -> int:
        """Return the standing-still steps of length h that end a run as STALLED."""
        if self.stall_period is None:
            return self.stall_steps
        return max(int(math.ceil(self.stall_steps * self.stall_period / h - 1e-9)), 1)


class ControlStep(NamedTuple):
    """A controller's answer for one state.

    Attributes:
        u: (2,) input (v, omega) to apply now.
        s: path progress in [0, 1] (NaN where there is none).
        value: V_N, the cost of what is applied (NaN where there is none).
        solve_time_s: the controller's own solve time, seconds.
        success: the input is a fresh solver solution (counts solver failures).
        lyapunov_ok: whether V_N decreased as the theorem says (None: no check).
        prediction: (N+1, nx) predicted states, or None.
        detail: the controller's own record of the step: a local controller's
            ControlOutput, the paper's MPC's MpcSolution (`solution` reads either).

    """

    u: np.ndarray
    s: float = math.nan
    value: float = math.nan
    solve_time_s: float = math.nan
    success: bool = True
    lyapunov_ok: bool | None = None
    prediction: np.ndarray | None = None
    detail: Any = None

    @property
    def solution(self) -> Any:
        """The MPC's solution of the step (a local controller's or the MPC's own), or None."""
        if isinstance(self.detail, ControlOutput):
            return self.detail.solution
        return self.detail


class RolloutController(Protocol):
    """What the rollout needs of a controller."""

    def step(self, x: np.ndarray) -> ControlStep:
        """Return the controller's answer for the state x."""


def solution_step(solution: MpcSolution) -> ControlStep:
    """Return the record of a solve of the paper's MPC as it is (``solve(x)``)."""
    return ControlStep(
        u=np.asarray(solution.u0, dtype=float), s=float(solution.s),
        value=float(solution.value), solve_time_s=float(solution.solve_time_s),
        success=bool(solution.success), lyapunov_ok=solution.lyapunov_ok,
        prediction=solution.x_pred, detail=solution)


def control_step(output: ControlOutput) -> ControlStep:
    """Return the record of a local controller's answer (the output is its detail).

    Between solves (not fresh) the MPC applies its verified plan and solves nothing: a
    success without a solve time (the solve statistics are over solves only). Without a
    solution, a command that is an input (a path follower's, the turn to the goal heading)
    or the goal reached is a success, any other stop a failure; s and the solve time are
    the controller's own (ControlOutput.progress, compute_time_s). A fresh solve succeeds
    when the solver's plan is applied (TRACKING).
    """
    solution = output.solution
    if not output.fresh and solution is not None:
        return ControlStep(u=output.u, s=float(solution.s), value=float(solution.value),
                           success=True, detail=output)
    if solution is None:
        done = output.reason.applies_input or output.reason is Reason.GOAL_REACHED
        return ControlStep(u=output.u, s=output.progress, solve_time_s=output.compute_time_s,
                           success=done, detail=output)
    return ControlStep(
        u=output.u, s=float(solution.s), value=float(solution.value),
        solve_time_s=float(solution.solve_time_s),
        success=output.reason is Reason.TRACKING, lyapunov_ok=solution.lyapunov_ok,
        prediction=solution.x_pred, detail=output)


Stepper = Callable[[np.ndarray, np.ndarray | None, float], ControlStep]


def _stepper(controller: Any) -> Stepper:
    """Return (x, twist, t) -> the controller's answer, for each kind the rollout drives.

    Raises:
        TypeError: if it has neither ``step``, ``compute`` (with the rest of the local
            controller's interface) nor ``solve``.

    """
    if callable(getattr(controller, 'step', None)):
        return lambda x, twist, t: controller.step(x)
    if isinstance(controller, LocalController):
        return lambda x, twist, t: control_step(controller.compute(x, twist, t))
    if callable(getattr(controller, 'solve', None)):
        return lambda x, twist, t: solution_step(controller.solve(x))
    msg = f'{type(controller).__name__} has no step(x), compute(pose, twist, t) or solve(x)'
    raise TypeError(msg)


class Rollout(NamedTuple):
    """What a closed-loop run produced.

    Attributes:
        outcome: why the run ended.
        rows: (n, 9) trajectory rows (trajectory.TRAJECTORY_COLUMNS), one per step.
        steps: the controller's answers, one per row (STOPPED: one fewer).
        step_times: wall time of each controller call, seconds (its record included; without
            a wait for an NLP's compilation, compilation.compile_wait_seconds).
        h: the step length, seconds.
        note: why the controller stopped (STOPPED), else ''.
        contact: who caused the contact that ended the run (COLLISION), else None.

    """

    outcome: Outcome
    rows: np.ndarray
    steps: tuple[ControlStep, ...]
    step_times: np.ndarray
    h: float
    note: str = ''
    contact: ContactKind | None = None

    @property
    def reached(self) -> bool:
        """The run ended at the goal."""
        return self.outcome is Outcome.REACHED

    @property
    def end_time(self) -> float:
        """Time of the last row, seconds."""
        return float(self.rows[-1, 0])

    @property
    def solve_times(self) -> np.ndarray:
        """Each step's solve time as the controller reports it, seconds."""
        return np.array([step.solve_time_s for step in self.steps], dtype=float)

    @property
    def solver_failures(self) -> int:
        """Steps whose input is not a fresh solver solution."""
        return sum(1 for step in self.steps if not step.success)

    @property
    def lyapunov_ok(self) -> list[bool | None]:
        """Per step, the controller's V_N check (None: no check)."""
        return [step.lyapunov_ok for step in self.steps]


def rollout(
    controller: Any,
    model: Any,
    start: np.ndarray,
    goal: np.ndarray,
    *,
    h: float,
    rule: StopRule,
    clearance: Clearance | None = None,
    localizer: Localizer | None = None,
    clearance_at: TimedClearance | None = None,
) -> Rollout:
    """Run controller and model in closed loop until the stop rule ends the run.

    Args:
        controller: a local controller, the paper's MPC (``solve(x)``) or a
            RolloutController (see the module docstring).
        model: the plant: ``model.step(x, u, h) -> x_next``, or a real robot's `Base`
            (sim/base.py; it holds the start pose: start is not used).
        start: the initial state.
        goal: the goal pose (x, y, theta).
        h: the step length, seconds.
        rule: when to stop.
        clearance: poses (n, 3) -> clearance of the robot's footprint from the true
            obstacles (<= 0 is contact), or None to ignore collisions (measure them from the
            rows instead).
        localizer: with a real base, the localizer whose poses correct odometry (the
            controller gets the pose in map, see the module docstring); None: the controller
            gets odometry as it is.
        clearance_at: (pose (3,), t) -> clearance at time t, for a world whose obstacles
            move; replaces clearance in the stop rule.

    Returns:
        The outcome, the rows and the controller's answers.

    Raises:
        ValueError: for a localizer without a real base (an ideal plant has no odometry).

    """
    base = model if callable(getattr(model, 'advance', None)) else None
    if localizer is not None and base is None:
        msg = 'a localizer corrects odometry: it needs a real base as the plant'
        raise ValueError(msg)
    stepper = _stepper(controller)
    goal = np.asarray(goal, dtype=float)
    x = np.asarray(start, dtype=float).copy() if base is None else base.pose.copy()
    located = LocalizedPose(ODOM_HISTORY, localized=True, source='localizer') \
        if localizer is not None else None
    last = rule.steps(h)
    still_needed = rule.still_steps(h)
    rows: list[np.ndarray] = []
    steps: list[ControlStep] = []
    step_times: list[float] = []
    still = 0
    outcome, note, kind = Outcome.TIME_LIMIT, '', None
    moved = np.zeros(2)  # the input that brought the ideal plant to x (none at the start)
    for k in range(last + 1):
        t = k * h
        measured = x if base is None else _measure(base, t, localizer, located)
        started = time.perf_counter()
        waited = compile_wait_seconds()  # a first use of an NLP on a fresh machine
        try:
            answer = stepper(measured, None if base is None else base.twist(), t)
        except PlanningError as err:
            outcome, note = Outcome.STOPPED, f'{type(err).__name__}: {err}'
            rows.append(trajectory_row(t, x))
            break
        step_times.append(time.perf_counter() - started
                          - (compile_wait_seconds() - waited))
        u = np.asarray(answer.u, dtype=float)
        if not np.all(np.isfinite(u)):
            outcome, note = Outcome.STOPPED, f'non-finite input {u.tolist()}'
            rows.append(trajectory_row(t, x))
            break
        steps.append(answer)
        rows.append(trajectory_row(t, x, u, s=answer.s, value=answer.value,
                                   solve_ms=answer.solve_time_s * 1e3))
        touching = (clearance_at(x[:3], t) <= 0.0 if clearance_at is not None
                    else clearance is not None and clearance(x[None, :3])[0] <= 0.0)
        if touching:
            outcome = Outcome.COLLISION
            v, omega = (float(c) for c in (base.velocity if base is not None else moved))
            kind = contact_kind(v, omega)
            break
        if rule.reached(x, goal):
            outcome = Outcome.REACHED
            break
        # a real base may still be moving on a zero command: it has stalled once it stands
        moving = base is not None and float(np.max(np.abs(base.velocity))) >= rule.stall_input
        still = still + 1 if float(np.max(np.abs(u))) < rule.stall_input and not moving \
            else 0
        if still >= still_needed:
            outcome = Outcome.STALLED
            break
        if k == last:
            break
        if base is None:
            x = np.asarray(model.step(x, u, h), dtype=float)
            moved = u
        else:
            base.command(u, t)
            base.advance(t + h)
            x = base.pose.copy()
    return Rollout(outcome=outcome, rows=np.array(rows, dtype=float), steps=tuple(steps),
                   step_times=np.array(step_times, dtype=float), h=float(h), note=note,
                   contact=kind)


def _measure(base: Base, t: float, localizer: Localizer | None,
             located: LocalizedPose | None) -> np.ndarray:
    """Return the pose the controller gets at t: odometry, or in map through the localizer."""
    odom, twist = base.odometry()
    if localizer is None or located is None:
        return odom
    located.add_odometry(t, odom, twist)
    fix = localizer.measure(t, base.pose)
    if fix is not None:
        located.add_localizer(t, fix)
    pose = located.pose(odom)
    if pose is None:  # the localizer's first pose is due at 0: never without a correction
        msg = located.problem or 'no localizer pose'
        raise RuntimeError(msg)
    return pose


def polygon_clearance(obstacles: Sequence[ConvexPolygon], robot_radius: float) -> Clearance:
    """Return poses (n, 2+) -> clearance of a robot circle from convex polygons (m).

    A centre inside a polygon has clearance -1 - robot_radius; no obstacles: inf.
    """
    obstacles = tuple(obstacles)

    def clearance(points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=float)[:, :2]
        if not obstacles:
            return np.full(len(points), math.inf)
        distance = np.min(np.stack([o.distance(points) for o in obstacles]), axis=0)
        inside = np.zeros(len(points), dtype=bool)
        for o in obstacles:
            inside |= o.contains(points)
        return np.where(inside, -1.0, distance) - robot_radius
    return clearance


def circle_clearance(centres: np.ndarray, radius: float, robot_radius: float) -> Clearance:
    """Return poses (n, 2+) -> clearance of a robot circle from circles (BARN's cylinders)."""
    centres = np.asarray(centres, dtype=float).reshape(-1, 2)
    gap = radius + robot_radius

    def clearance(points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=float)[:, :2]
        if len(centres) == 0:
            return np.full(len(points), math.inf)
        d = np.linalg.norm(points[:, None, :] - centres[None, :, :], axis=2)
        return np.min(d, axis=1) - gap
    return clearance
