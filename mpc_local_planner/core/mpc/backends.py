# Copyright 2026 mpc_local_planner developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Which solver runs problem (6), with which options, and how its functions are compiled.

The formulation does not depend on the backend: fatrop (structure-exploiting, the default)
and IPOPT (the reference, and the fallback when fatrop fails) get the same NLP. With
config.compile the NLP's functions are generated as C, compiled by gcc in a daemon thread and
kept on disk (compile_cache_dir()), so that a restarted controller loads them at once; until
the library is there, CasADi's interpreted functions run.
"""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass
import hashlib
import logging
import math
import os
from pathlib import Path
import subprocess
import tempfile
import threading
import time
from typing import Any, Callable, NamedTuple

import casadi as ca
import numpy as np

from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.mpc.formulation import Formulation

__all__ = ['Nlp', 'SolverRun', 'backend_options', 'build_nlp', 'compile_cache_dir',
           'run_solver']

_LOG = logging.getLogger(__name__)

# C compiler and flags for config.compile; CC overrides the compiler as usual.
COMPILE_FLAGS = ('-O2', '-fPIC', '-shared')
# One compilation at a time (the machine may have two cores and a control loop to run).
_COMPILE_LOCK = threading.Lock()


def _ipopt_options(config: MpcConfig) -> dict[str, Any]:
    return {
        'ipopt.print_level': 0,
        'ipopt.sb': 'yes',
        'ipopt.max_iter': config.max_iterations,
        'ipopt.tol': config.tolerance,
        'ipopt.acceptable_tol': 1e-6,
        # the initial guess is the proof's candidate, feasible by construction: keep the
        # interior-point iterates near it instead of pushing them off the bounds
        'ipopt.bound_push': 1e-8,
        'ipopt.bound_frac': 1e-8,
        'ipopt.mu_init': 1e-4,
    }


def _fatrop_options(config: MpcConfig, structure: dict) -> dict[str, Any]:
    return {
        'structure_detection': 'manual',
        'N': structure['N'],
        'nx': structure['nx'],
        'nu': structure['nu'],
        'ng': structure['ng'],
        # fatrop's bound_push/bound_frac defaults (1e-2) are kept: IPOPT's warm-start settings
        # above make fatrop stall when an obstacle enters the horizon; mu_init 1e-2 (not 0.1)
        # keeps the first step (everything at rest, every quartic derivative zero) short
        'fatrop': {
            'print_level': 0,
            'mu_init': 1e-2,
            'max_iter': config.max_iterations,
            'tol': config.tolerance,
        },
    }


def backend_options(config: MpcConfig, structure: dict) -> tuple[str, dict[str, Any]]:
    """Return (nlpsol plugin, options) for config.solver.

    Args:
        config: the solver's name, iteration limit, tolerance and extra options.
        structure: the formulation's stage sizes (Formulation.structure), for fatrop.

    Raises:
        ValueError: if config.solver is not a known backend.

    """
    common = {'print_time': False, 'error_on_fail': False}
    name = config.solver
    if name == 'ipopt':
        plugin, options = 'ipopt', _ipopt_options(config)
    elif name == 'fatrop':
        plugin, options = 'fatrop', _fatrop_options(config, structure)
    else:
        msg = f'unknown solver {name!r}'
        raise ValueError(msg)
    options.update(common)
    options.update(config.solver_options)
    return plugin, options


@dataclass
class Nlp:
    """One formulation with its solver, its IPOPT fallback and its compilation state."""

    formulation: Formulation
    solver: ca.Function
    backend: str
    plugin: str
    options: dict[str, Any]
    build_time_s: float = 0.0
    compiled: bool = False
    pending: Future | None = None  # a compilation running in the background
    fallback: ca.Function | None = None  # IPOPT on the same NLP, when the backend fails
    fallback_factory: Callable[[], ca.Function] | None = None

    def fallback_solver(self) -> ca.Function | None:
        """Return the IPOPT fallback, building it the first time it is needed."""
        if self.fallback is None and self.fallback_factory is not None:
            self.fallback = self.fallback_factory()
        return self.fallback

    def finish_compilation(self, *, wait: bool = False) -> None:
        """Swap in the compiled solver once its background compilation is done.

        Args:
            wait: block until the compilation is done (or failed).

        """
        future = self.pending
        if future is None or not (wait or future.done()):
            return
        self.pending = None
        try:
            library = future.result()
            self.solver = ca.nlpsol('mpc', self.plugin, str(library), self.options)
            self.compiled = True
        except Exception as err:  # any failure falls back to the interpreter
            _LOG.warning('compiling the MPC NLP failed, using the interpreted functions: %s',
                         err)


def build_nlp(formulation: Formulation, config: MpcConfig) -> Nlp:
    """Create the solver of config.solver for the formulation (and start compiling it)."""
    start = time.perf_counter()
    problem, structure = formulation.problem, formulation.structure
    plugin, options = backend_options(config, structure)
    nlp = Nlp(formulation=formulation, solver=ca.nlpsol('mpc', plugin, problem, options),
              backend=config.solver, plugin=plugin, options=options)
    if config.solver != 'ipopt':
        # a structure-exploiting backend is fast but less robust far from its warm start
        # (seen: fatrop failing near the box's corner under timing jitter); IPOPT, the
        # reference, gets the same problem before the controller gives up. Built on first
        # use: building it with every NLP doubled the start-up time.
        fb_plugin, fb_options = backend_options(config.with_changes(solver='ipopt'), structure)
        nlp.fallback_factory = lambda: ca.nlpsol('mpc_fallback', fb_plugin, problem, fb_options)
    if config.compile:
        _start_compilation(nlp)
    nlp.build_time_s = time.perf_counter() - start
    return nlp


class SolverRun(NamedTuple):
    """What one call of an NLP solver returned (not yet verified)."""

    w: np.ndarray  # the primal solution
    value: float  # the cost at w (inf when the solver did not report success)
    success: bool  # the solver reported success and w is finite
    status: str  # the solver's return status
    iterations: int
    seconds: float  # wall time of the call


def run_solver(nlp: Nlp, w0: np.ndarray, params: np.ndarray,
               solver: ca.Function | None = None) -> SolverRun:
    """Solve the NLP from w0 with its solver (or the given one, e.g. the fallback)."""
    solver = nlp.solver if solver is None else solver
    form = nlp.formulation
    start = time.perf_counter()
    result = solver(x0=w0, p=params, lbx=form.lbw, ubx=form.ubw, lbg=form.lbg, ubg=form.ubg)
    seconds = time.perf_counter() - start
    stats = solver.stats()
    w_opt = np.asarray(result['x']).reshape(-1)
    success = bool(stats.get('success', False)) and bool(np.all(np.isfinite(w_opt)))
    return SolverRun(w=w_opt, value=float(result['f']) if success else math.inf,
                     success=success, status=str(stats.get('return_status', 'unknown')),
                     iterations=int(stats.get('iter_count', 0)), seconds=seconds)


# ----------------------------------------------------------------------------- compilation
def compile_cache_dir() -> Path:
    """Return where compiled NLPs are kept ($MPC_LOCAL_PLANNER_CACHE or ~/.cache/...)."""
    env = os.environ.get('MPC_LOCAL_PLANNER_CACHE')
    if env:
        return Path(env)
    base = os.environ.get('XDG_CACHE_HOME') or str(Path.home() / '.cache')
    return Path(base) / 'mpc_local_planner'


def _start_compilation(nlp: Nlp) -> None:
    """Use a cached compiled library now, or compile one in the background."""
    try:
        source = _nlp_source(nlp.formulation.problem, nlp.solver)
        library = _library_path(source)
        if library.exists():
            nlp.solver = ca.nlpsol('mpc', nlp.plugin, str(library), nlp.options)
            nlp.compiled = True
            return
        nlp.pending = _submit_compilation(source, library)
    except Exception as err:  # any failure falls back to the interpreter
        _LOG.warning('compiling the MPC NLP failed, using the interpreted functions: %s', err)


def _nlp_source(problem: dict, solver: ca.Function) -> str:
    """Return C code of the NLP functions the solver plugin evaluates (and the oracle)."""
    generator = ca.CodeGenerator('mpc_nlp.c', {'with_header': False})
    generator.add(ca.Function('nlp', [problem['x'], problem['p']],
                              [problem['f'], problem['g']], ['x', 'p'], ['f', 'g']))
    for name in solver.get_function():
        generator.add(solver.get_function(name))
    return generator.dump()


def _library_path(source: str) -> Path:
    """Return the cache file of this source (its hash, with CasADi, compiler and flags)."""
    compiler = os.environ.get('CC', 'gcc')
    key = hashlib.sha256('\n'.join(
        [ca.__version__, compiler, *COMPILE_FLAGS, source]).encode()).hexdigest()[:24]
    return compile_cache_dir() / f'mpc_nlp_{key}.so'


def _submit_compilation(source: str, library: Path) -> Future:
    """Compile in a daemon thread: a node stopped with Ctrl-C must not wait for gcc.

    A ThreadPoolExecutor's workers are joined at interpreter exit, which kept a stopped
    controller alive for the whole compilation; a daemon thread is simply dropped (the
    library is renamed into place atomically, so an interrupted build leaves no bad file).
    """
    future: Future = Future()

    def work() -> None:
        with _COMPILE_LOCK:
            try:
                future.set_result(_compile(source, library))
            except BaseException as err:  # handed to the waiting solver
                future.set_exception(err)

    threading.Thread(target=work, name='mpc_compile', daemon=True).start()
    return future


def _compile(source: str, library: Path) -> Path:
    """Compile source into library (atomically: a half-written file is never loaded)."""
    library.parent.mkdir(parents=True, exist_ok=True)
    compiler = os.environ.get('CC', 'gcc')
    with tempfile.TemporaryDirectory(dir=library.parent) as tmp:
        c_file = Path(tmp) / 'mpc_nlp.c'
        c_file.write_text(source)
        out = Path(tmp) / library.name
        result = subprocess.run([compiler, *COMPILE_FLAGS, str(c_file), '-o', str(out), '-lm'],
                                capture_output=True, text=True, timeout=600, check=False)
        if result.returncode != 0:
            msg = f'{compiler} failed ({result.returncode}): {result.stderr.strip()[:500]}'
            raise RuntimeError(msg)
        os.replace(out, library)
    return library
