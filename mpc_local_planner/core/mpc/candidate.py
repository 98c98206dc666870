# SPDX-License-Identifier: Apache-2.0
"""The plans a step starts from: the proof's shifted candidate and the guided start.

The proof compares the optimum at k+1 with a candidate: the previous plan shifted by one
step, with the terminal steady state appended (shifted_candidate). It is feasible by
construction when the robot carried out the previous plan's first input. The guided start
(guided_guess) is infeasible but informative: the motion in hand, ended on the path.

Plans are values: nothing here changes a plan it is given; a plan with other multipliers or
another value is a new one (dataclasses.replace).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Callable

import casadi as ca
import numpy as np

from mpc_local_planner.core.models import RobotModel
from mpc_local_planner.core.mpc.nlp_values import rate_limited_inputs

__all__ = ['Plan', 'PROGRESS_TOLERANCE', 'Rollout', 'STANDING_INPUT', 'guided_guess',
           'path_following_inputs', 'plan_moves', 'rate_start', 'shifted_candidate']

# Inputs below this (m/s, rad/s) stand still: a solver that converged to "wait" leaves
# 1e-9, not zeros; and a gain of path progress s below PROGRESS_TOLERANCE is none (see
# plan_moves).
STANDING_INPUT = 1e-3
PROGRESS_TOLERANCE = 1e-6

# The path progress nearest the pose of a state, at least s_min (nan without a path).
Progress = Callable[[np.ndarray, float], float]
# The terminal steady state g_p(s) (None when it is free).
TerminalState = Callable[[float], 'np.ndarray | None']


@dataclass(frozen=True)
class Plan:
    """A predicted trajectory with everything needed to shift it (s is nan without a path)."""

    x: np.ndarray  # (N+1, nx)
    u: np.ndarray  # (N, nu)
    s: float
    mu: np.ndarray  # flat multipliers
    value: float


def plan_moves(plan: Plan | None, progress: float) -> bool:
    """Say whether the plan in force moves the robot on: it drives now, or it advances s.

    A plan that neither drives now (|v_0| <= STANDING_INPUT) nor advanced the path progress
    beyond the plan before it (progress, the gain in s; a turn in place along the path
    advances it) waits, and counts as standing: warm starts from it can hold the solver at
    "wait" for good. At rest the unicycle's linearisation cannot move sideways, so where the
    path's steady state g_p(s) leaves the robot's heading (a rounded turn-in-place knot) the
    solver reports success with s frozen, the robot turning to and fro on the spot or not at
    all, the motion put off to the horizon's end; each step's shifted candidate puts it off
    again, V_N constant, and the robot stands in open space (see docs/design/mpc.md, section
    "A waiting plan counts as standing (plan_moves)"). Counted as standing, the plan gets the
    cold tries of tries.py, which leave that point. Without a path (progress NaN, the
    tracking baseline) any input above STANDING_INPUT moves.
    """
    if plan is None or not len(plan.u):
        return False
    first = np.abs(plan.u[0])
    if math.isnan(progress):
        return bool(np.any(first > STANDING_INPUT))
    return bool(first[0] > STANDING_INPUT or (progress > PROGRESS_TOLERANCE
                                              and np.any(first > STANDING_INPUT)))


class Rollout:
    """Simulate the model over a horizon, one call of a mapaccum'ed step per rollout.

    Args:
        model: the robot model.

    """

    def __init__(self, model: RobotModel) -> None:
        self._model = model
        self._maps: dict[tuple[float, int, bool], ca.Function] = {}

    def __call__(self, x0: np.ndarray, u: np.ndarray, step: float,
                 first: np.ndarray | None = None) -> np.ndarray:
        """Return the (len(u)+1, nx) states from x0 under the inputs u, each held for step s.

        With first (a first-order hold, MpcConfig.input_hold): the input ramps over each step
        from the one before it (first before u_0) to u_l (model.discrete_ramp).
        """
        u = np.asarray(u, dtype=float)
        key = (step, len(u), first is not None)
        rollout = self._maps.get(key)
        if rollout is None:
            if first is None:
                discrete = self._model.discrete(step)
            else:
                nu = self._model.nu
                x, qu = ca.SX.sym('x', self._model.nx), ca.SX.sym('qu', 2 * nu)
                discrete = ca.Function('F', [x, qu], [self._model.discrete_ramp(step)(
                    x, qu[:nu], qu[nu:])])
            rollout = self._maps[key] = discrete.mapaccum('rollout', len(u))
        if first is None:
            columns = u.T
        else:
            before = np.vstack([np.asarray(first, dtype=float).reshape(1, -1), u[:-1]])
            columns = np.hstack([before, u]).T
        xs = np.asarray(rollout(x0, columns)).T
        return np.vstack([x0, xs])


def shifted_candidate(model: RobotModel, previous: Plan | None, x0: np.ndarray, *,
                      horizon: int, step: float, rollout: Rollout, progress: Progress,
                      terminal_state: TerminalState, first_order: bool = False) -> Plan:
    """Return the proof's candidate: shift the last plan and append the terminal steady state.

    Without a last plan: stand still, and end in the steady state of the initial s. The
    candidate has no multipliers (they depend on the obstacles an NLP holds) and no value
    (inf) yet. With first_order (a first-order hold) the shifted knots are rolled out from
    the last plan's first knot, u_0: the velocity that plan gives for now.
    """
    if previous is None:
        s0 = progress(x0, 0.0)
        u = np.zeros((horizon, model.nu))
        x = np.tile(x0, (horizon + 1, 1))
        x_s = terminal_state(s0)
        x[-1] = x_s if x_s is not None else x0
        return Plan(x=x, u=u, s=s0, mu=np.zeros(0), value=math.inf)
    _, u_s = model.steady_state(previous.x[-1, :3])
    u = np.vstack([previous.u[1:], np.asarray(u_s, dtype=float).reshape(1, -1)])
    first = previous.u[0] if first_order else None
    return Plan(x=rollout(x0, u, step, first), u=u, s=previous.s, mu=np.zeros(0),
                value=math.inf)


def guided_guess(model: RobotModel, x0: np.ndarray, carried: np.ndarray | None, *,
                 horizon: int, step: float, rollout: Rollout, progress: Progress,
                 terminal_state: TerminalState,
                 rate_bounds: tuple[np.ndarray, np.ndarray] | None = None,
                 first_order: bool = False) -> Plan:
    """Return an infeasible but informative start: the motion in hand, ended on the path.

    After a new path, carried holds the inputs of the last plan on the old one: they are
    shifted by a step (the robot was carrying them out, and they avoid what the old plan
    avoided); else drive forward at half speed. rate_bounds, (the input before, max_accel h)
    if given, then moves the inputs into the rate bounds (nlp_values.rate_limited_inputs: a
    base at rest does not jump to half speed, and the plan must end at rest). They are rolled
    out from x0, and the last state replaced by the steady state on the path nearest it. No
    multipliers yet. With first_order (a first-order hold; rate_bounds required) the inputs
    are knots ramped from the input before, and the last one is 0; and without carried
    inputs the start follows the path (path_following_inputs) instead of driving straight
    ahead: a robot standing off the path's heading (after a stop, or a re-plan whose path
    begins with a turn) drove the straight start off the path, among obstacles the plan
    never passes, and IPOPT from it ran out of every step's budget or declared the NLP
    infeasible (laser-only BARN world 62 on the real base, docs/design/mpc.md).
    """
    u = np.zeros((horizon, model.nu))
    if carried is not None and len(carried) == horizon:
        u[:-1] = carried[1:]
    elif first_order and rate_bounds is not None and not math.isnan(progress(x0, 0.0)):
        u = path_following_inputs(model, x0, rate_bounds, horizon=horizon, step=step,
                                  rollout=rollout, progress=progress,
                                  terminal_state=terminal_state)
    else:
        u[:, 0] = 0.5 * model.u_max[0]
    if rate_bounds is not None:
        u = rate_limited_inputs(u, *rate_bounds, first_order=first_order)
    x = rollout(x0, u, step, rate_bounds[0] if first_order and rate_bounds else None)
    s = progress(x[-1], progress(x0, 0.0))
    terminal = terminal_state(s)
    if terminal is not None:
        x[-1] = terminal
    return Plan(x=x, u=u, s=s, mu=np.zeros(0), value=math.inf)


# How far ahead along the path (metres, turns counted at 0.25 m per radian) the path-following
# start aims, and the distance below which it aims at the path's heading rather than at the
# point (a turn in place).
FOLLOW_LOOKAHEAD = 0.3
FOLLOW_AIM_DISTANCE = 0.05
# Heading error (rad) beyond which the path-following start turns in place before it drives.
FOLLOW_TURN_FIRST = 0.5


def _ahead(terminal_state: TerminalState, s: float) -> np.ndarray:
    """Return the steady state g_p(s') FOLLOW_LOOKAHEAD along the path from g_p(s)."""
    here = terminal_state(s)
    assert here is not None
    ds, ahead = 1e-3, here
    while s < 1.0:
        ahead = terminal_state(min(s + ds, 1.0))
        assert ahead is not None
        gap = (float(np.hypot(*(ahead[:2] - here[:2])))
               + 0.25 * abs(float(ahead[2] - here[2])))
        if gap >= FOLLOW_LOOKAHEAD or s + ds >= 1.0:
            break
        ds *= 2.0
    return ahead


def path_following_inputs(model: RobotModel, x0: np.ndarray,
                          rate_bounds: tuple[np.ndarray, np.ndarray], *, horizon: int,
                          step: float, rollout: Rollout, progress: Progress,
                          terminal_state: TerminalState) -> np.ndarray:
    """Return first-order-hold knots that follow the path from x0, within the rate bounds.

    A pure-pursuit rollout on the model: at each step aim at the path FOLLOW_LOOKAHEAD
    ahead of the robot's projection (at its point, or at its heading when the point is
    within FOLLOW_AIM_DISTANCE: a turn in place), turn towards it, and drive at half speed
    once the heading error is below FOLLOW_TURN_FIRST. Each knot is clipped within max_accel
    h of the one before (from the input before, rate_bounds[0]); the caller ends them at
    rest (nlp_values.rate_limited_inputs).
    """
    before = np.asarray(rate_bounds[0], dtype=float).reshape(-1)
    rate = np.asarray(rate_bounds[1], dtype=float).reshape(-1)
    u_min, u_max = np.asarray(model.u_min, dtype=float), np.asarray(model.u_max, dtype=float)
    k_angle = model.angle_index
    u = np.zeros((horizon, model.nu))
    x = np.asarray(x0, dtype=float).copy()
    s = progress(x, 0.0)
    for k in range(horizon):
        s = progress(x, s)
        target = _ahead(terminal_state, s)
        offset = target[:2] - x[:2]
        aim = (math.atan2(offset[1], offset[0]) if float(np.hypot(*offset)) > FOLLOW_AIM_DISTANCE
               else float(target[2]))
        error = math.remainder(aim - float(x[k_angle]), 2.0 * math.pi)
        wanted = np.zeros(model.nu)
        wanted[0] = 0.5 * u_max[0] * math.cos(error) if abs(error) < FOLLOW_TURN_FIRST else 0.0
        wanted[1] = error / (2.0 * step)
        u[k] = np.clip(np.clip(wanted, before - rate, before + rate), u_min, u_max)
        x = rollout(x, u[k:k + 1], step, before)[-1]
        before = u[k]
    return u


def rate_start(model: RobotModel, previous_input: np.ndarray | None,
               plan: Plan | None) -> np.ndarray:
    """Return the input max_accel's rate bounds start from.

    The input the robot was last given (clipped into the model's bounds) when it is a
    finite (nu,) vector; else the plan in force's first input; else rest.
    """
    if previous_input is not None:
        u = np.asarray(previous_input, dtype=float).reshape(-1)
        if u.shape == (model.nu,) and np.all(np.isfinite(u)):
            return np.clip(u, model.u_min, model.u_max)
    if plan is not None:
        return np.asarray(plan.u[0], dtype=float).copy()
    return np.zeros(model.nu)
