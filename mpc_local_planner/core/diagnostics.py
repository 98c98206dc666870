# SPDX-License-Identifier: Apache-2.0
"""What the nodes report, as typed records with their keys defined once (no ROS here).

mpc_controller publishes one DiagnosticStatus per control step on ``mpc/diagnostics``; its
values are key/value strings. `ControllerDiagnostics` is that status as a record: the node
builds it with `ControllerDiagnostics.from_output` and publishes `to_values()`; analyze_bag,
closed_loop, mpc_bench and the tests read it back with `ControllerDiagnostics.from_values`.
The wire names are the values of `Key`, and each record field is its key's name in lower
case. The global planner reports the outcome of each goal the same way on
``planner/diagnostics`` (`PlannerKey`, `PlannerDiagnostics`), so that a supervisor learns
that no plan will come. `BagKey` names what a recorded bag's metadata says about its run.
"""

from __future__ import annotations

from enum import Enum, IntEnum
import math
from typing import Any, Iterable, Mapping, NamedTuple

import numpy as np

from mpc_local_planner.core.control_output import Blockage, ControlOutput, Reason
from mpc_local_planner.core.mpc import LyapunovCase, PlanSource

__all__ = [
    'BagKey',
    'CONTROLLER_DIAGNOSTICS_TOPIC',
    'ControllerDiagnostics',
    'Key',
    'Level',
    'level_of',
    'PLANNER_DIAGNOSTICS_TOPIC',
    'PlannerDiagnostics',
    'PlannerKey',
    'PlanTrigger',
]

# Topics (relative, as the nodes publish them).
CONTROLLER_DIAGNOSTICS_TOPIC = 'mpc/diagnostics'
PLANNER_DIAGNOSTICS_TOPIC = 'planner/diagnostics'


class Level(IntEnum):
    """Severity of a status, numbered as diagnostic_msgs/DiagnosticStatus numbers it."""

    OK = 0
    WARN = 1
    ERROR = 2


class Key(Enum):
    """The keys of the controller's DiagnosticStatus values, in the order published."""

    S = 's_k'  # path parameter s at the solve
    VALUE = 'V_N'  # the applied plan's cost
    SOLVE_MS = 'solve_ms'
    STATUS = 'status'  # the solver's return status
    SOURCE = 'source'  # 'solver', 'candidate', 'stop'; '' when the MPC did not run
    FAILURES = 'failures'  # consecutive steps without a fresh solver solution
    FAILURES_TOTAL = 'failures_total'
    TIMEOUTS_TOTAL = 'timeouts_total'  # steps whose solving ran out of its time budget
    LYAPUNOV_OK = 'lyapunov_ok'  # V_N decreased as the theorem says ('' = not checked)
    # whether the theorem covers that check: 'covered', or what changed (a LyapunovCase)
    LYAPUNOV_CASE = 'lyapunov_case'
    ITERATIONS = 'iterations'
    REASON = 'reason'  # a Reason's value
    DETAIL = 'detail'  # free text about the reason
    GOAL_REACHED = 'goal_reached'
    STATE_TIME = 'state_time'  # when the state was measured (s)
    X = 'x'
    Y = 'y'
    THETA = 'theta'
    V = 'v'  # the command published
    OMEGA = 'omega'
    PATH_BLOCKED = 'path_blocked'  # the remaining plan meets a grown obstacle
    BLOCKED_AT = 'blocked_at'  # metres along the plan from the robot's projection (nan)
    # the MPC solved at this control step; false between solves (control_frequency above
    # 1 / step: the step applied the held plan, and s_k, V_N, solve_ms... are that solve's)
    SOLVED = 'solved'


class PlannerKey(Enum):
    """The keys of the global planner's DiagnosticStatus values."""

    PLANNED = 'planned'  # 'true' if a plan was published for the latest goal
    DETAIL = 'detail'  # why not (or what was published)
    POSES = 'poses'
    LENGTH = 'length'  # metres
    WAITING = 'waiting'  # 'true' while the goal waits for input (a map): a plan may still come
    TRIGGER = 'trigger'  # what asked for this plan: a PlanTrigger value
    REPLANS = 'replans'  # re-plans since the node started (triggers blocked and periodic)


class BagKey(Enum):
    """Keys of a recorded bag's custom metadata (rosbag2 ``custom_data``)."""

    WORLD_FILE = 'mpc_local_planner.world_file'  # the world file's path when recorded
    WORLD = 'mpc_local_planner.world'  # its contents


_LEVELS = {
    Reason.TRACKING: Level.OK,
    Reason.GOAL_REACHED: Level.OK,
    Reason.ROTATE_TO_HEADING: Level.OK,
    Reason.ERROR: Level.ERROR,
    Reason.INVALID_ODOM: Level.ERROR,
    Reason.INVALID_PLAN: Level.ERROR,
    Reason.STOP: Level.ERROR,
}


def level_of(reason: Reason | None) -> Level:
    """Return the severity of a reason.

    OK while tracking, turning to the goal heading or at the goal, ERROR when refused input
    or a failure stops the robot, WARN otherwise (waiting for input, stale odometry, the
    shifted candidate).
    """
    return _LEVELS.get(reason, Level.WARN) if reason is not None else Level.WARN


class ControllerDiagnostics(NamedTuple):
    """One control step as mpc_controller reports it (fields: `Key` names in lower case).

    Numbers the step does not have (no solve, no state) are NaN, and source is None when the
    MPC did not run; reason is None only when read from a status that names no known Reason.
    """

    s: float = math.nan
    value: float = math.nan
    solve_ms: float = math.nan
    status: str = ''
    source: PlanSource | None = None
    failures: int = 0
    failures_total: int = 0
    timeouts_total: int = 0
    lyapunov_ok: bool | None = None
    lyapunov_case: LyapunovCase | None = None
    iterations: int = 0
    reason: Reason | None = None
    detail: str = ''
    goal_reached: bool = False
    state_time: float = math.nan
    x: float = math.nan
    y: float = math.nan
    theta: float = math.nan
    v: float = 0.0
    omega: float = 0.0
    path_blocked: bool = False
    blocked_at: float = math.nan
    solved: bool = False

    @classmethod
    def from_output(cls, output: ControlOutput, *, state: np.ndarray | None,
                    state_time: float | None, failures_total: int,
                    blockage: Blockage | None = None,
                    timeouts_total: int = 0) -> ControllerDiagnostics:
        """Describe a control step.

        Args:
            output: what the controller decided.
            state: the latest measured (x, y, theta), or None.
            state_time: when it was measured (seconds), or None.
            failures_total: the controller's count of steps without a fresh solution.
            blockage: where the remaining plan is blocked (MpcController.path_blockage);
                None: not blocked.
            timeouts_total: the controller's count of steps that ran out of solve time
                (MpcController.timeouts).

        """
        sol = output.solution
        x, y, theta = (math.nan,) * 3 if state is None else (float(v) for v in state[:3])
        return cls(
            s=float(sol.s) if sol else math.nan,
            value=float(sol.value) if sol else math.nan,
            solve_ms=1e3 * float(sol.solve_time_s) if sol else math.nan,
            status=str(sol.status) if sol else '',
            source=PlanSource(sol.source) if sol else None,
            failures=int(sol.failures) if sol else 0,
            failures_total=int(failures_total),
            timeouts_total=int(timeouts_total),
            lyapunov_ok=None if sol is None or sol.lyapunov_ok is None else bool(sol.lyapunov_ok),
            lyapunov_case=sol.lyapunov_case if sol is not None else None,
            iterations=int(sol.iterations) if sol else 0,
            reason=output.reason,
            detail=output.detail,
            goal_reached=output.reason is Reason.GOAL_REACHED,
            state_time=math.nan if state_time is None else float(state_time),
            x=x, y=y, theta=theta,
            v=float(output.u[0]), omega=float(output.u[1]),
            path_blocked=bool(blockage.blocked) if blockage else False,
            blocked_at=float(blockage.at) if blockage else math.nan,
            # a stop without a solve is fresh too, but carries no solution
            solved=bool(output.fresh and sol is not None),
        )

    @property
    def level(self) -> Level:
        """The status's severity."""
        return level_of(self.reason)

    @property
    def message(self) -> str:
        """The reason in words (': detail' appended): the status's message."""
        text = self.reason.text if self.reason is not None else 'unknown'
        return f'{text}: {self.detail}' if self.detail else text

    def to_values(self) -> list[tuple[str, str]]:
        """Return the (key, value) strings in `Key` order."""
        return _to_values(self, Key)

    @classmethod
    def from_values(cls, values: Mapping[str, str] | Iterable[tuple[str, str]]
                    ) -> ControllerDiagnostics:
        """Read a status's values back; missing or malformed entries keep their defaults."""
        return _from_values(cls, Key, values)


class PlanTrigger(str, Enum):
    """What asked the planner for a plan (a str, so diagnostics read the value)."""

    GOAL = 'goal'  # a new goal (the parameter or goal_pose)
    BLOCKED = 'blocked'  # the rest of the plan in force came too close to an obstacle
    PERIODIC = 'periodic'  # replan_period elapsed
    # the robot has not moved progress_radius in progress_timeout, away from the goal (Nav2's
    # progress checker): a plan from where it stands may be one it can follow
    NO_PROGRESS = 'no_progress'

    def __str__(self) -> str:
        return self.value


class PlannerDiagnostics(NamedTuple):
    """The outcome of the planner's latest attempt (fields: `PlannerKey` names in lower case)."""

    planned: bool = False
    detail: str = ''
    poses: int = 0
    length: float = math.nan
    waiting: bool = False
    trigger: PlanTrigger = PlanTrigger.GOAL
    replans: int = 0

    @property
    def level(self) -> Level:
        """OK for a plan; WARN while waiting or for a failed re-plan; ERROR for a lost goal.

        A failed re-plan leaves the plan in force; a failed goal leaves the robot no plan.
        """
        if self.planned:
            return Level.OK
        return Level.WARN if self.waiting or self.trigger is not PlanTrigger.GOAL else Level.ERROR

    @property
    def failed(self) -> bool:
        """No plan will come for this goal (a goal not planned, and not waiting for input).

        A failed re-plan is not: the plan in force stays, and the next check tries again.
        """
        return not self.planned and not self.waiting and self.trigger is PlanTrigger.GOAL

    def to_values(self) -> list[tuple[str, str]]:
        """Return the (key, value) strings in `PlannerKey` order."""
        return _to_values(self, PlannerKey)

    @classmethod
    def from_values(cls, values: Mapping[str, str] | Iterable[tuple[str, str]]
                    ) -> PlannerDiagnostics:
        """Read a status's values back; missing or malformed entries keep their defaults."""
        return _from_values(cls, PlannerKey, values)


def _format(value: Any) -> str:
    if value is None:
        return ''
    if isinstance(value, Enum):
        return str(value.value)
    if isinstance(value, (bool, np.bool_)):
        return 'true' if value else 'false'
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    return str(value)


def _parse(text: str, default: Any, name: str) -> Any:
    if name == 'reason':
        try:
            return Reason(text)
        except ValueError:
            return None
    if name == 'source':
        try:
            return PlanSource(text)
        except ValueError:
            return None
    if name == 'trigger':
        try:
            return PlanTrigger(text)
        except ValueError:
            return default
    if name == 'lyapunov_ok':
        return None if text == '' else text == 'true'
    if name == 'lyapunov_case':
        try:
            return LyapunovCase(text)
        except ValueError:
            return None
    if isinstance(default, bool):
        return text == 'true'
    try:
        if isinstance(default, int):
            return int(text)
        if isinstance(default, float):
            return float(text)
    except ValueError:
        return default
    return text


def _to_values(record: NamedTuple, keys: type[Enum]) -> list[tuple[str, str]]:
    return [(key.value, _format(getattr(record, key.name.lower()))) for key in keys]


def _from_values(cls: type, keys: type[Enum],
                 values: Mapping[str, str] | Iterable[tuple[str, str]]) -> Any:
    mapping = dict(values.items() if isinstance(values, Mapping) else values)
    fields = {}
    for key in keys:
        name = key.name.lower()
        if key.value in mapping:
            fields[name] = _parse(str(mapping[key.value]), cls._field_defaults[name], name)
    return cls(**fields)
