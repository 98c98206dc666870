# SPDX-License-Identifier: Apache-2.0
"""The tracking MPC of Limon et al. (2018), the baseline the paper improves on.

It is problem (6) with another terminal condition: the artificial steady state may be any
steady state (not one on a path), and the offset cost measures its distance to the target.
Everything else (model, stage cost, constraints, candidate, verification) is the paper's MPC,
so a comparison shows the effect of the terminal condition alone. With a non-convex free space
its convergence argument does not apply: it stops in front of the paper's obstacle.
"""

from __future__ import annotations

from typing import Sequence

import casadi as ca
import numpy as np

from mpc_local_planner.core.baselines.common import limited, speed_limit
from mpc_local_planner.core.config import CostWeights, MpcConfig
from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.models import RobotModel
from mpc_local_planner.core.mpc.backends import run_solver, SolverRunner
from mpc_local_planner.core.mpc.candidate import Plan
from mpc_local_planner.core.mpc.formulation import TerminalCondition
from mpc_local_planner.core.mpc.step import MpcBase
from mpc_local_planner.core.obstacles import ConvexPolygon

__all__ = ['TrackingMPC', 'target_terminal']


def target_terminal(model: RobotModel) -> TerminalCondition:
    """Return Limon et al.'s terminal condition: x_N = x_s, any steady state in the bounds.

    The reference variable r is x_s itself; the parameters are the target pose. The offset
    cost is the squared distance of x_s's pose to the target, the heading weighted by
    weights.heading.
    """

    def steady_state(r: ca.SX, params: ca.SX) -> ca.SX:
        return r

    def condition(x_n: ca.SX, steady: ca.SX, r: ca.SX, params: ca.SX,
                  weights: CostWeights) -> tuple[ca.SX, ca.SX]:
        # x_N = x_s, and x_s is a steady state: x_s = g(pose of x_s)
        x_s, _ = model.steady_state(r[:3])
        err = r[:3] - params
        return (ca.vertcat(x_n - r, r - x_s),
                err[0] ** 2 + err[1] ** 2 + weights.heading * err[2] ** 2)

    return TerminalCondition(family='target', dim=model.nx, num_params=3,
                             lower=model.x_min, upper=model.x_max,
                             steady_state=steady_state, condition=condition)


class TrackingMPC(MpcBase):
    """Baseline (Limon et al. 2018): an artificial steady state anywhere, offset to the target.

    Args:
        model: the robot model.
        config: settings (MpcConfig()); offset_weight weighs the distance to the target.
        obstacles: convex obstacles as described; inflated here by config.inflation().
        target: the target pose [x, y, theta].
        runner: what runs an NLP's solver (see MpcBase).

    """

    def __init__(self, model: RobotModel, config: MpcConfig | None = None, *,
                 obstacles: Sequence[ConvexPolygon] = (),
                 target: np.ndarray | None = None,
                 runner: SolverRunner = run_solver) -> None:
        self._target = None if target is None else np.asarray(target, dtype=float)
        self._speed_limit: float | None = None
        super().__init__(model, config, obstacles=obstacles, runner=runner)

    def set_target(self, target: np.ndarray) -> None:
        """Set the target pose [x, y, theta]."""
        self._target = np.asarray(target, dtype=float)
        self.reset()

    # --- the local-controller interface (core/local_controller.py) -------------------------

    def set_plan(self, poses: np.ndarray) -> None:
        """Track the plan's last pose: the baseline knows its target, not the way there.

        A plan ending where the target already is changes nothing (a re-plan to the same
        goal keeps the warm start); a new target starts the MPC over (set_target).

        Raises:
            ValueError: if poses is not (M >= 1, 3) or its last pose is not finite.

        """
        points = np.asarray(poses, dtype=float)
        if points.ndim != 2 or points.shape[1] < 3 or len(points) < 1:
            msg = f'a plan is (M, 3) poses, got shape {points.shape}'
            raise ValueError(msg)
        target = points[-1, :3]
        if not np.all(np.isfinite(target)):
            msg = f'the plan ends at a non-finite pose {target.tolist()}'
            raise ValueError(msg)
        if self._target is None or not np.array_equal(target, self._target[:3]):
            self.set_target(target)

    def compute(self, pose: np.ndarray | None, twist: np.ndarray | None,
                now: float) -> ControlOutput:
        """Solve for pose and return what the MPC applies (the twist is not used).

        TRACKING when the applied plan is the solver's, else CANDIDATE (the shifted
        candidate, or the stop when nothing verified: solution.source says which).
        """
        if pose is None:
            return ControlOutput(np.zeros(2), None, Reason.NO_ODOM)
        if self._target is None:
            return ControlOutput(np.zeros(2), None, Reason.NO_PLAN)
        solution = self.solve(np.asarray(pose, dtype=float))
        u = limited(np.asarray(solution.u0, dtype=float), self._speed_limit)
        return ControlOutput(u, solution,
                             Reason.TRACKING if solution.success else Reason.CANDIDATE)

    def set_speed_limit(self, v_max: float | None) -> None:
        """Cap the applied |v| at v_max from the next compute (the prediction knows no cap)."""
        self._speed_limit = speed_limit(v_max)

    def _require_target(self) -> np.ndarray:
        if self._target is None:
            msg = 'no target: call set_target() first'
            raise RuntimeError(msg)
        return self._target

    def _terminal_condition(self) -> TerminalCondition:
        return target_terminal(self._model)

    def _terminal_parameters(self) -> np.ndarray:
        return self._require_target()[:3]

    def _progress(self, x: np.ndarray, s_min: float = 0.0) -> float:
        return float('nan')

    def _terminal_state(self, s: float) -> np.ndarray | None:
        return None

    def _reference_value(self, plan: Plan) -> np.ndarray:
        return plan.x[-1]

    def _progress_of(self, r: np.ndarray) -> float:
        return float('nan')

    def _heading_reference(self, x: np.ndarray) -> float:
        return float(self._require_target()[2])
