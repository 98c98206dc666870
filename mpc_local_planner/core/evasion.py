# SPDX-License-Identifier: Apache-2.0
"""Step out of a walker's way when the MPC has no verified plan and stopping would be run into.

The paper's answer to "no verified plan" is to stop: among static obstacles a robot at rest
is safe, and the next step starts over from where it stands. Among obstacles that move it is
not. A walker coming at a standing robot runs into it (a *passive* contact, DynaBARN's word),
and the MPC, whose every plan must end at rest on the path within the horizon, often has no
plan exactly then: the predicted walkers close the path ahead.

`Evasion` gives the robot a move for that case, verified the way the MPC verifies its plans:

1. The stop is checked first: the states of the robot braking along its last plan (or
   standing), against every moving obstacle where its prediction puts it at each stage's time
   (core/moving_obstacles.py). When they stay clear over the horizon, the robot stops as
   before: nothing changes where no walker is predicted to reach it.
2. Otherwise a lattice of constant-input moves (each input from its lower to its upper
   bound, reached within max_accel) is rolled out with the MPC's model and hold over the
   MPC's horizon, with pivot-first moves beside them: a turn in place at the full turn rate
   for one to three stages, then straight ahead at one of the lattice's forward speeds. A
   constant input only gives arcs, and a robot facing a walker head-on (a forward-only one
   above all) steps aside by turning first and then driving off. A move is admissible only
   if it clears every static obstacle at every stage by the clearance its motion needs
   (`Clearance.margins_of_many`, the MPC's own check), so an evasion never risks a static
   contact; braking along it later stays on that checked curve (core/braking.py).
3. Of the admissible moves, one that meets no predicted walker over the whole horizon is
   taken if there is one: the one that ends nearest to where the path leads (the path point
   a horizon's travel beyond the robot's projection). Otherwise the ones that meet the
   predictions latest, and of them the one least deep, for the least time, in where the
   walkers could be if they turned any way (`heading_anywhere`: the move that gets away from
   them soonest and furthest); it is taken only if it meets the predictions later than the
   stop, or as late but with EVASION_GAIN less of that shortfall. Such a move can still be
   hit while it moves (an active contact): it is made because standing would be hit sooner.

Nothing of the paper's guarantee is claimed for these steps: the MPC starts over (its warm
start and Lyapunov record dropped) at the next step, as after any step without its plan.
"""

from __future__ import annotations

from dataclasses import dataclass
import itertools
from typing import NamedTuple

import numpy as np

from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.models import RobotModel
from mpc_local_planner.core.moving_obstacles import heading_anywhere, moving
from mpc_local_planner.core.mpc.candidate import Rollout
from mpc_local_planner.core.mpc.clearance import Clearance
from mpc_local_planner.core.obstacles import ObstacleSet

__all__ = ['EVASION_GAIN', 'EVASION_LEVELS', 'EvasiveMove', 'Evasion', 'first_conflict',
           'PIVOT_STAGES']

# Values per input in the lattice of moves, from its lower to its upper bound (odd: 0 is one).
EVASION_LEVELS = 9
# Stages a pivot-first move turns in place before it drives off straight (0.8 rad a stage for
# the Jackal at 4 rad/s and h = 0.2 s: up to a half turn).
PIVOT_STAGES = (1, 2, 3)
# How much less shortfall (m, summed over the stages) than the stop a move that meets the
# walkers as soon as the stop does must have to be taken: a few millimetres are no reason.
EVASION_GAIN = 0.05


class EvasiveMove(NamedTuple):
    """A move out of a predicted walker's way.

    Attributes:
        x: (N+1, nx) its states, x_0 the robot's.
        u: (N, nu) its inputs (knots of a first-order hold when the MPC's hold is one).
        conflict: the first stage that meets a predicted walker (N+1: none within the horizon).
        shortfall: how far it falls short of its clearance from where the walkers could be
            if they turned any way (`heading_anywhere`), summed over the stages (m); 0 for
            a move that meets no prediction.
        stop_conflict: the same as conflict for stopping instead.

    """

    x: np.ndarray
    u: np.ndarray
    conflict: int
    shortfall: float
    stop_conflict: int


def _summed_shortfall(margins: np.ndarray) -> float:
    """Return the sum over the stages of how far each falls short of its clearance (m)."""
    return float(np.sum(np.maximum(-np.asarray(margins), 0.0)))


def first_conflict(margins: np.ndarray) -> int:
    """Return the first stage (1..N) whose margin is negative, N+1 when none is."""
    hits = np.flatnonzero(np.asarray(margins) < 0.0)
    return int(hits[0]) + 1 if len(hits) else len(margins) + 1


@dataclass
class Evasion:
    """Choose a verified move out of the predicted walkers' way (see the module docstring).

    Args:
        model: the MPC's robot model (its input bounds, its dynamics).
        config: the MPC's settings (horizon, step, max_accel, input hold).
        clearance: the MPC's clearance checks (its footprint, its margins).

    """

    model: RobotModel
    config: MpcConfig
    clearance: Clearance

    def __post_init__(self) -> None:
        self._rollout = Rollout(self.model)
        # (M, N, nu): every move's target inputs, fixed by the model and the settings
        self._move_targets = np.array(self._moves())

    def choose(self, x0: np.ndarray, stopping: np.ndarray, obstacles: ObstacleSet,
               toward: np.ndarray, before: np.ndarray | None = None) -> EvasiveMove | None:
        """Return the move to make instead of stopping, or None to stop.

        Args:
            x0: the robot's state.
            stopping: (N+1, nx) the states of the robot stopping (braking, or standing).
            obstacles: the obstacles the MPC holds (inflated as it inflates them).
            toward: (2,) where the path leads: of the moves that meet no walker, the one
                that ends nearest it is taken.
            before: the input in force (what a first-order hold and max_accel start from);
                None: zero.

        """
        walkers = ObstacleSet([o for o in obstacles.obstacles if moving(o)])
        if not len(walkers):
            return None
        n = self.config.horizon
        stop_margins = self.clearance.margins(stopping, np.zeros((n, self.model.nu)), walkers)
        stop_conflict = first_conflict(stop_margins)
        if stop_conflict > n:
            return None
        statics = ObstacleSet([o for o in obstacles.obstacles if not moving(o)])
        # where the walkers could be if they turned any way: what a move that cannot keep
        # clear of their predictions should get away from
        anywhere = ObstacleSet([heading_anywhere(o) for o in walkers.obstacles])
        stop_spread = _summed_shortfall(
            self.clearance.margins(stopping, np.zeros((n, self.model.nu)), anywhere))
        start = np.zeros(self.model.nu) if before is None else np.asarray(before, dtype=float)
        first = start if self.config.first_order_hold else None
        inputs = self._inputs(start, self._move_targets)
        states = np.array([self._rollout(np.asarray(x0, dtype=float), u, self.config.step, first)
                           for u in inputs])
        finite = np.all(np.isfinite(states), axis=(1, 2))
        states, inputs = states[finite], inputs[finite]
        # a move must clear every static obstacle at every stage, as a plan must
        clear = np.all(self.clearance.margins_of_many(states, inputs, statics) >= 0.0, axis=1)
        states, inputs = states[clear], inputs[clear]
        if not len(states):
            return None
        conflicts = np.array([first_conflict(m) for m in
                              self.clearance.margins_of_many(states, inputs, walkers)])
        free = conflicts > n
        if np.any(free):
            # clear of every prediction: the one that ends nearest where the path leads
            ends = np.hypot(*(states[free, -1, :2] - np.asarray(toward)).T)
            i = int(np.flatnonzero(free)[np.argmin(ends)])
            return EvasiveMove(states[i], inputs[i], int(conflicts[i]), 0.0, stop_conflict)
        # the latest conflict, then the least time and depth within where the walkers could
        # be (the move that gets away from them soonest and furthest)
        latest = np.flatnonzero(conflicts == np.max(conflicts))
        spread = np.array([_summed_shortfall(m) for m in self.clearance.margins_of_many(
            states[latest], inputs[latest], anywhere)])
        i = int(latest[np.argmin(spread)])
        move = EvasiveMove(states[i], inputs[i], int(conflicts[i]), float(np.min(spread)),
                           stop_conflict)
        if move.conflict > stop_conflict or (
                move.conflict == stop_conflict and move.shortfall < stop_spread - EVASION_GAIN):
            return move
        return None

    def _targets(self) -> list[np.ndarray]:
        """Return the lattice of constant inputs, every input from its lower to upper bound."""
        return [np.array(values) for values in itertools.product(*self._levels())]

    def _levels(self) -> list[np.ndarray]:
        """Return each input's EVASION_LEVELS values, from its lower to its upper bound."""
        return [np.linspace(lo, hi, EVASION_LEVELS)
                for lo, hi in zip(self.model.u_min, self.model.u_max, strict=True)]

    def _moves(self) -> list[np.ndarray]:
        """Return every move's (N, nu) target inputs: the lattice's, then the pivot-first ones.

        A pivot-first move turns in place (speed 0, the turn rate at a bound; inputs are
        (speed, turn rate), as the controller takes them) for PIVOT_STAGES stages, then
        drives straight at one of the lattice's forward speeds.
        """
        n, nu = self.config.horizon, self.model.nu
        moves = [np.tile(target, (n, 1)) for target in self._targets()]
        if nu != 2:
            return moves
        speeds = [v for v in self._levels()[0] if v > 0.0]
        for turn in (self.model.u_min[1], self.model.u_max[1]):
            for stages in PIVOT_STAGES:
                if stages >= n:
                    continue
                for speed in speeds:
                    targets = np.zeros((n, nu))
                    targets[:stages, 1] = turn
                    targets[stages:, 0] = speed
                    moves.append(targets)
        return moves

    def _inputs(self, start: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """Return the inputs that go from start towards each stage's target within max_accel.

        targets: (..., N, nu), one move's or many moves' at once; the inputs have its shape.
        """
        targets = np.asarray(targets, dtype=float)
        if self.config.max_accel is None:
            return targets.copy()
        limit = np.asarray(self.config.max_accel, dtype=float) * self.config.step
        u = np.empty_like(targets)
        current = np.broadcast_to(start, targets[..., 0, :].shape).astype(float)
        for k in range(targets.shape[-2]):
            current = current + np.clip(targets[..., k, :] - current, -limit, limit)
            u[..., k, :] = current
        return u
