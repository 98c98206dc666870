# SPDX-License-Identifier: Apache-2.0
"""The NLPs the MPCs of one process share (built_nlps.py): what is shared, what is each one's.

An MPC of a problem built before gets its solvers at once, in a record of its own: the same
closed loop as a fresh build, its own time per iteration, its own deadline per thread. A
problem that differs in anything a build reads (the model's bounds, an analytic path's
numbers, the compile cache) is built anew.
"""

from __future__ import annotations

import math
import threading

import casadi as ca
import numpy as np
import pytest

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import PathReferenceMPC
from mpc_local_planner.core.mpc.built_nlps import clear_shared_nlps, problem_key
from mpc_local_planner.core.mpc.formulation import path_terminal
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import AnalyticPath, paper_sinusoid

H = 0.2
BOX = ConvexPolygon.from_box(1.0, -1.0, 1.5, 1.0)
# an iteration budget: the closed loop is the same on any machine and under any load
BY_ITERATIONS = MpcConfig(solving=SolverSettings(budget='iterations', compile=False))


def sinusoid(amplitude: float) -> AnalyticPath:
    """The paper's path shape with another amplitude, under one name."""
    return AnalyticPath('sinusoid', lambda s: ca.vertcat(
        2.5 * s, amplitude * ca.sin(ca.pi * s),
        ca.atan(amplitude * ca.pi * ca.cos(ca.pi * s) / 2.5)))


def paper_mpc(model: Unicycle | None = None, path: AnalyticPath | None = None
              ) -> PathReferenceMPC:
    return PathReferenceMPC(model or Unicycle(), BY_ITERATIONS, obstacles=[BOX],
                            path=path or paper_sinusoid())


def drive(mpc: PathReferenceMPC, steps: int) -> np.ndarray:
    """Return the inputs applied over steps control steps from the path's start."""
    x = mpc.path.start.copy()
    inputs = []
    for _ in range(steps):
        u = mpc.solve(x).u0
        inputs.append(u)
        x = mpc.model.step(x, u, H)
    return np.array(inputs)


def test_a_second_mpc_of_one_problem_gets_the_built_solvers_in_a_record_of_its_own() -> None:
    first, second = paper_mpc(), paper_mpc()
    a, b = first.nlp_for(1, 4), second.nlp_for(1, 4)
    assert a is not b
    assert a.solver is b.solver and a.formulation is b.formulation
    # the IPOPTs are built once, at the first record's first use
    assert a.fallback is None and b.fallback is None
    assert a.fallback_solver() is b.fallback_solver() is not None
    assert a.cold_solver() is b.cold_solver() is not None
    # the bounds every record reads cannot be written by one of them
    with pytest.raises(ValueError, match='read-only'):
        a.formulation.lbw[0] = 0.0
    # each measures its own time per iteration
    drive(first, 2)
    assert first.last_nlp.iteration_time > 0.0
    assert second.nlp_for(*shape_of(first)).iteration_time == 0.0


def shape_of(mpc: PathReferenceMPC) -> tuple[int, int]:
    nlp = mpc.last_nlp
    return nlp.formulation.slots, nlp.formulation.faces


def test_an_mpc_on_shared_solvers_drives_as_one_on_solvers_built_for_it() -> None:
    clear_shared_nlps()
    built = drive(paper_mpc(), 6)
    shared = drive(paper_mpc(), 6)
    np.testing.assert_array_equal(shared, built)


def test_other_bounds_or_another_paths_numbers_are_another_problem() -> None:
    reference = paper_mpc().nlp_for(0, 0)
    assert paper_mpc(Unicycle(v_max=1.0)).nlp_for(0, 0).solver is not reference.solver
    assert paper_mpc(Unicycle()).nlp_for(0, 0).solver is reference.solver
    # an analytic path's expression is in the NLP: one name, other numbers, other solvers
    low, high = sinusoid(0.5), sinusoid(1.1)
    assert low.family != high.family and sinusoid(0.5).family == low.family
    mpc = paper_mpc(path=low)
    on_low = mpc.nlp_for(0, 0)
    mpc.set_path(high)
    assert mpc.nlp_for(0, 0).solver is not on_low.solver
    # the solver's predicted terminal state is on the path in force, not the one before
    solution = mpc.solve(high.start.copy())
    assert solution.success
    np.testing.assert_allclose(solution.x_pred[-1], high.pose(solution.s), atol=1e-5)
    assert np.linalg.norm(low.pose(solution.s)[:2] - solution.x_pred[-1][:2]) > 0.05


def test_with_compile_the_cache_folder_is_part_of_the_problem(
        monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    terminal = path_terminal(Unicycle(), paper_sinusoid())
    compiled = MpcConfig()
    assert compiled.solving.compile
    monkeypatch.setenv('MPC_LOCAL_PLANNER_CACHE', str(tmp_path / 'one'))
    one = problem_key(Unicycle(), compiled, terminal, 1, 4)
    interpreted = problem_key(Unicycle(), BY_ITERATIONS, terminal, 1, 4)
    monkeypatch.setenv('MPC_LOCAL_PLANNER_CACHE', str(tmp_path / 'two'))
    assert problem_key(Unicycle(), compiled, terminal, 1, 4) != one
    assert problem_key(Unicycle(), BY_ITERATIONS, terminal, 1, 4) == interpreted


def test_the_deadline_of_a_shared_solver_is_the_calling_threads() -> None:
    deadline = paper_mpc().nlp_for(1, 4).deadline
    deadline.arm(at=5.0, max_iterations=3)
    seen: list[tuple[float, float]] = []
    other = threading.Thread(target=lambda: seen.append((deadline.at, deadline.max_iterations)))
    other.start()
    other.join()
    assert seen == [(math.inf, math.inf)]
    assert (deadline.at, deadline.max_iterations) == (5.0, 3)
    deadline.arm()
    assert (deadline.at, deadline.max_iterations) == (math.inf, math.inf)
