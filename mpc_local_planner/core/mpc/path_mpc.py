# SPDX-License-Identifier: Apache-2.0
"""The paper's MPC: MpcBase with the terminal condition x_N = g_p(s_k) on a reference path."""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.models import RobotModel
from mpc_local_planner.core.mpc.backends import run_solver, SolverRunner
from mpc_local_planner.core.mpc.candidate import Plan, plan_moves
from mpc_local_planner.core.mpc.formulation import path_terminal, TerminalCondition
from mpc_local_planner.core.mpc.step import MpcBase
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import ReferencePath

__all__ = ['PathReferenceMPC']


class PathReferenceMPC(MpcBase):
    """The paper's MPC: the prediction ends in a steady state on the path, x_N = g_p(s_k).

    Args:
        model: the robot model.
        config: settings (MpcConfig()).
        obstacles: convex obstacles as described; inflated here by config.inflation().
        path: the reference path p(s); p(0) should be the robot's start pose.
        runner: what runs an NLP's solver (see MpcBase).

    """

    def __init__(self, model: RobotModel, config: MpcConfig | None = None, *,
                 obstacles: Sequence[ConvexPolygon] = (),
                 path: ReferencePath | None = None,
                 runner: SolverRunner = run_solver) -> None:
        self._path = path
        super().__init__(model, config, obstacles=obstacles, runner=runner)

    @property
    def path(self) -> ReferencePath | None:
        """The reference path in force (None before one is set)."""
        return self._path

    def set_path(self, path: ReferencePath, carried_inputs: np.ndarray | None = None) -> None:
        """Use a new reference path; s restarts at the robot's projection onto it.

        The proof's candidate does not carry over (the old plan does not end on the new
        path), but the old plan's inputs do, as the guided start (_guided_guess): a robot
        re-planned at speed is carrying them out.

        Args:
            path: the new reference path.
            carried_inputs: the inputs (N x nu) the robot is carrying out, for the guided
                start; None: the old plan's if it moves (a recorded state gives its own).

        """
        previous = self._plan
        same_path = (self._path is not None and self._path.family == path.family
                     and np.array_equal(self._path.parameters(), path.parameters()))
        spot = self._spot
        self._path = path
        self.reset()
        if same_path:
            # the same path again (a re-plan that found it anew): what the solver tried where
            # the robot stands was tried on this very problem, and a cut solve goes on
            self._spot = spot
        if carried_inputs is not None:
            self._carried_inputs = np.array(carried_inputs, dtype=float)
        elif previous is not None and plan_moves(previous, math.inf):
            self._carried_inputs = previous.u.copy()

    def _require_path(self) -> ReferencePath:
        if self._path is None:
            msg = 'no reference path: call set_path() first'
            raise RuntimeError(msg)
        return self._path

    def _terminal_condition(self) -> TerminalCondition:
        return path_terminal(self._model, self._require_path())

    def _terminal_parameters(self) -> np.ndarray:
        return self._require_path().parameters()

    def _progress(self, x: np.ndarray, s_min: float = 0.0) -> float:
        return self._require_path().project(x[:3], s_min=s_min)

    def _terminal_state(self, s: float) -> np.ndarray | None:
        x_s, _ = self._model.steady_state(self._require_path().pose(s))
        return np.asarray(x_s, dtype=float).reshape(-1)

    def _reference_value(self, plan: Plan) -> np.ndarray:
        return np.array([plan.s])

    def _progress_of(self, r: np.ndarray) -> float:
        return float(r[0])

    def _heading_reference(self, x: np.ndarray) -> float:
        path = self._require_path()
        return float(path.pose(path.project(x[:3]))[2])
