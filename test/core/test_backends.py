# SPDX-License-Identifier: Apache-2.0
"""Every MPC backend drives the paper's scenario like the IPOPT reference (no timing here)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
import os
import threading

import numpy as np
import pytest

from mpc_local_planner.core.config import MpcConfig, SOLVERS, SolverSettings
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import compilation, PathReferenceMPC, PlanSource
from mpc_local_planner.core.mpc.backends import run_solver
from mpc_local_planner.core.mpc.built_nlps import clear_shared_nlps
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import paper_sinusoid

STEPS = 150
H = 0.2


def run_paper_scenario(solver: str, *, compile_functions: bool) -> dict:
    """Run the paper's obstacle scenario in closed loop; return what the tests check."""
    model, path = Unicycle(), paper_sinusoid()
    box = ConvexPolygon.from_box(1.0, -1.0, 1.5, 1.0)
    mpc = PathReferenceMPC(model,
                           MpcConfig(solving=SolverSettings(solver=solver,
                                                            compile=compile_functions)),
                           obstacles=[box], path=path)
    x = path.start.copy()
    length, values, lyapunov, sources, positions = 0.0, [], [], [], [x[:2]]
    for _ in range(STEPS):
        sol = mpc.solve(x)
        values.append(sol.value)
        lyapunov.append(sol.lyapunov_ok)
        sources.append(sol.source)
        x_next = model.step(x, sol.u0, H)
        length += float(np.hypot(*(x_next[:2] - x[:2])))
        x = x_next
        positions.append(x[:2])
    return {'x': x, 'length': length, 'values': np.array(values), 'lyapunov': lyapunov,
            'sources': sources, 'positions': np.array(positions), 'goal': path.goal,
            'box': box, 'backend': mpc.backend}


@pytest.fixture(scope='module')
def reference() -> dict:
    return run_paper_scenario('ipopt', compile_functions=False)


@pytest.mark.parametrize('solver', SOLVERS)
@pytest.mark.parametrize('compile_functions', [False, True])
def test_backend_reaches_the_target_like_ipopt(solver: str, compile_functions: bool,
                                               reference: dict) -> None:
    run = run_paper_scenario(solver, compile_functions=compile_functions)
    assert np.hypot(*(run['x'][:2] - run['goal'][:2])) < 0.02
    assert abs(run['x'][2] - run['goal'][2]) < 0.05
    assert not np.any(run['box'].contains(run['positions']))
    assert all(ok is not False for ok in run['lyapunov'])
    assert np.all(np.diff(run['values']) <= 1e-6 * (1 + np.abs(run['values'][:-1])))
    assert PlanSource.STOP not in run['sources']
    assert run['length'] == pytest.approx(reference['length'], rel=0.01)


def test_compilation_failure_falls_back_to_the_interpreter(
        monkeypatch: pytest.MonkeyPatch, tmp_path, caplog: pytest.LogCaptureFixture) -> None:
    monkeypatch.setenv('MPC_LOCAL_PLANNER_CACHE', str(tmp_path))
    monkeypatch.setenv('CC', 'no-such-compiler-mpc-local-planner')
    model, path = Unicycle(), paper_sinusoid()
    mpc = PathReferenceMPC(model, MpcConfig(horizon=5, solving=SolverSettings(compile=True)),
                           path=path)
    sol = mpc.solve(path.start)
    mpc.wait_compiled()
    sol = mpc.solve(model.step(path.start, sol.u0, H))
    assert sol.source == PlanSource.SOLVER
    assert mpc.backend == 'fatrop'
    assert 'compiling the MPC NLP failed' in caplog.text


def test_processes_wanting_the_same_library_compile_it_once(tmp_path) -> None:
    runs: list[str] = []

    def compiler(source: str, library, flags=None):
        runs.append(source)
        library.write_text('built')  # what gcc would leave
        return library

    library = tmp_path / 'mpc_nlp_test.so'
    # each call opens the lock file itself, as another process would
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(lambda _: compilation.compile_library(
            'int f;', library, compiler=compiler), range(2)))
    assert results == [library, library]
    assert runs == ['int f;']  # the second found the library when its turn came


def test_a_waiter_compiles_its_queued_job_itself_and_the_wait_is_counted(tmp_path) -> None:
    started: list[str] = []
    gate = threading.Event()

    def compiler(source: str, library, flags=compilation.COMPILE_FLAGS):
        started.append(source)
        if source == 'first':
            gate.wait(10.0)  # the queue's thread is busy with the first job
        library.write_text('built')
        return library

    first = compilation.submit_compilation('first', tmp_path / 'mpc_nlp_first.so',
                                           compiler=compiler)
    second = compilation.submit_compilation('second', tmp_path / 'mpc_nlp_second.so',
                                            compiler=compiler)
    waited = compilation.compile_wait_seconds()
    compilation.wait_for(second)  # not behind the first: run here
    assert second.result() == tmp_path / 'mpc_nlp_second.so'
    assert not first.done()
    assert compilation.compile_wait_seconds() >= waited
    gate.set()
    assert first.result(timeout=10.0) == tmp_path / 'mpc_nlp_first.so'
    assert sorted(started) == ['first', 'second']  # each compiled once


def test_a_cached_library_is_found_without_generating_its_source(
        tmp_path, monkeypatch) -> None:
    monkeypatch.setenv('MPC_LOCAL_PLANNER_CACHE', str(tmp_path))
    model, path = Unicycle(), paper_sinusoid()
    config = MpcConfig(horizon=5, solving=SolverSettings(compile=True))
    first = PathReferenceMPC(model, config, path=path)
    nlp = first.nlp_for(0, 0)
    first.wait_compiled()
    assert nlp.compiled and nlp.library is not None
    assert [p.read_text() for p in tmp_path.glob('*.key')] == [nlp.library.name]

    def no_source(*args: object) -> str:
        raise AssertionError('the source was generated again')

    monkeypatch.setattr(compilation, 'nlp_source', no_source)
    clear_shared_nlps()  # a restarted controller: a new process, nothing built in memory
    again = PathReferenceMPC(model, config, path=path).nlp_for(0, 0)
    assert again.compiled and again.pending is None
    assert again.library == nlp.library


def test_the_compiled_functions_give_the_interpreted_solution_to_the_bit(
        tmp_path, monkeypatch) -> None:
    """Interpreted and compiled, one NLP's solve is the same: a test may skip gcc's wait."""
    monkeypatch.setenv('MPC_LOCAL_PLANNER_CACHE', str(tmp_path))
    model, path = Unicycle(), paper_sinusoid()
    box = ConvexPolygon.from_box(1.0, -1.0, 1.5, 1.0)
    config = MpcConfig(horizon=5, solving=SolverSettings(compile=True))
    mpc = PathReferenceMPC(model, config, obstacles=[box], path=path)
    x = path.start.copy()
    problem = mpc.solver_problem(x, mpc.inflated_obstacles)
    interpreted = problem.nlp.solver
    mpc.wait_compiled()
    assert problem.nlp.compiled and problem.nlp.solver is not interpreted
    by_interpreter = run_solver(problem.nlp, problem.w0, problem.params, interpreted)
    compiled = run_solver(problem.nlp, problem.w0, problem.params)
    assert by_interpreter.success and compiled.success
    assert by_interpreter.iterations == compiled.iterations
    np.testing.assert_array_equal(compiled.w, by_interpreter.w)


def test_the_compiler_runs_at_a_lower_cpu_priority(tmp_path, monkeypatch) -> None:
    """A background compilation leaves the CPU to the control loop (COMPILE_NICENESS)."""
    seen = tmp_path / 'niceness'
    compiler = tmp_path / 'cc'
    compiler.write_text(f'#!/bin/sh\nnice > {seen}\nexec gcc "$@"\n')
    compiler.chmod(0o755)
    monkeypatch.setenv('CC', str(compiler))
    library = compilation.run_compiler('int f(void) { return 1; }', tmp_path / 'f.so')
    assert library.is_file()
    # nice caps at 19
    assert int(seen.read_text()) == min(19, os.nice(0) + compilation.COMPILE_NICENESS)
