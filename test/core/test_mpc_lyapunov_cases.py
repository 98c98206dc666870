# SPDX-License-Identifier: Apache-2.0
"""Which V_N checks the proof covers: the same problem, the state where the plan took it."""

from __future__ import annotations

from dataclasses import replace
import math

import numpy as np
import pytest

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import LyapunovCase, PathReferenceMPC
from mpc_local_planner.core.mpc.decision import LyapunovRecord, STATE_TOLERANCE
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import analytic_path
from mpc_local_planner.worlds.world import paper_world

WORLD = paper_world()
MODEL = Unicycle()
# the evaluation's budget: the same solves on any machine
CONFIG = MpcConfig(solving=SolverSettings(budget='iterations'))
H = CONFIG.step


def record(predicted: list[float], problem: tuple[int, int] = (3, 5)) -> LyapunovRecord:
    kept = LyapunovRecord()
    kept.keep(1.0, 0.1, predicted=np.array(predicted), problem=problem)
    return kept


def test_a_record_covers_a_state_within_the_tolerance_of_its_prediction_only() -> None:
    assert LyapunovRecord().case(np.zeros(3), (0, 0), 2) is None  # nothing applied yet
    kept = record([1.0, 2.0, 0.5])
    assert kept.case(np.array([1.0, 2.0, 0.5]), (3, 5), 2) is LyapunovCase.COVERED
    near = np.array([1.0 + 0.9 * STATE_TOLERANCE, 2.0, 0.5 - 0.9 * STATE_TOLERANCE])
    assert kept.case(near, (3, 5), 2) is LyapunovCase.COVERED
    # the heading compared modulo 2 pi
    assert kept.case(np.array([1.0, 2.0, 0.5 + 2 * math.pi]), (3, 5), 2) \
        is LyapunovCase.COVERED
    for off in ([1.0 + 2 * STATE_TOLERANCE, 2.0, 0.5], [1.0, 2.0, 0.5 + 2 * STATE_TOLERANCE],
                [1.0, math.nan, 0.5]):
        assert kept.case(np.array(off), (3, 5), 2) is LyapunovCase.STATE_OFF_PREDICTION


def test_a_changed_problem_is_named_before_the_state() -> None:
    kept = record([1.0, 2.0, 0.5])
    far = np.array([5.0, 2.0, 0.5])
    assert kept.case(far, (4, 5), 2) is LyapunovCase.OBSTACLES_CHANGED
    assert kept.case(far, (4, 6), 2) is LyapunovCase.SETTINGS_CHANGED
    assert kept.case(np.array([1.0, 2.0, 0.5]), (3, 6), 2) is LyapunovCase.SETTINGS_CHANGED
    assert str(LyapunovCase.COVERED) == 'covered'


def paper_mpc() -> PathReferenceMPC:
    return PathReferenceMPC(MODEL, CONFIG, obstacles=WORLD.obstacles,
                            path=analytic_path(WORLD.path))


def drive(mpc: PathReferenceMPC, x: np.ndarray, steps: int) -> np.ndarray:
    for _ in range(steps):
        x = MODEL.step(x, mpc.solve(x).u0, H)
    return x


def test_on_the_models_own_steps_every_check_is_covered_and_v_n_falls() -> None:
    mpc = paper_mpc()
    x = np.asarray(WORLD.start, dtype=float)
    solutions = []
    for _ in range(40):  # past the box
        solution = mpc.solve(x)
        solutions.append(solution)
        x = MODEL.step(x, solution.u0, H)
    assert solutions[0].lyapunov_case is None and solutions[0].lyapunov_ok is None
    assert all(s.lyapunov_case is LyapunovCase.COVERED for s in solutions[1:])
    assert all(s.lyapunov_ok for s in solutions[1:])


def test_the_classification_is_no_knife_edge_around_a_step() -> None:
    # the same step, its state perturbed (20 seeded perturbations at each scale): below the
    # tolerance covered, above it off the prediction; and V_N falls on both sides of it, so
    # whether a violation counts as a defect does not hang on the side a step falls
    rng = np.random.default_rng(0)
    start = drive(paper_mpc(), np.asarray(WORLD.start, dtype=float), 12)
    for scale, expected in ((1e-9, LyapunovCase.COVERED),
                            (0.3 * STATE_TOLERANCE, LyapunovCase.COVERED),
                            (3 * STATE_TOLERANCE, LyapunovCase.STATE_OFF_PREDICTION),
                            (1e-4, LyapunovCase.STATE_OFF_PREDICTION)):
        for _ in range(20):
            mpc = paper_mpc()
            x = drive(mpc, start, 1)
            solution = mpc.solve(x + scale * rng.choice([-1.0, 1.0], size=3))
            assert solution.lyapunov_case is expected
            if scale < 1e-4:
                assert solution.lyapunov_ok


def test_other_obstacles_take_the_step_out_of_the_proof_the_same_shapes_do_not() -> None:
    mpc = paper_mpc()
    x = drive(mpc, np.asarray(WORLD.start, dtype=float), 3)
    # the same shapes again, new objects: the same problem
    mpc.set_obstacles([ConvexPolygon(A=o.A.copy(), b=o.b.copy(), vertices=o.vertices.copy())
                       for o in WORLD.obstacles])
    solution = mpc.solve(x)
    assert solution.lyapunov_case is LyapunovCase.COVERED
    x = MODEL.step(x, solution.u0, H)
    mpc.set_obstacles([*WORLD.obstacles, ConvexPolygon.from_box(10.0, 10.0, 11.0, 11.0)])
    solution = mpc.solve(x)
    assert solution.lyapunov_case is LyapunovCase.OBSTACLES_CHANGED
    x = MODEL.step(x, solution.u0, H)
    assert mpc.solve(x).lyapunov_case is LyapunovCase.COVERED  # the new set, kept


@pytest.mark.parametrize('change', ['weights', 'path'])
def test_a_settings_change_is_named_and_a_new_path_starts_the_record_over(change) -> None:
    mpc = paper_mpc()
    x = drive(mpc, np.asarray(WORLD.start, dtype=float), 3)
    if change == 'weights':
        mpc.update_config(replace(CONFIG, weight_heading=0.2))
        solution = mpc.solve(x)
        assert solution.lyapunov_case is LyapunovCase.SETTINGS_CHANGED
        assert solution.lyapunov_ok is not None  # still checked, and counted apart
    else:
        mpc.set_path(analytic_path(WORLD.path))
        solution = mpc.solve(x)
        assert solution.lyapunov_case is None and solution.lyapunov_ok is None
