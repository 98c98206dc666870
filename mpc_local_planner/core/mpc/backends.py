# SPDX-License-Identifier: Apache-2.0
"""Which solver runs problem (6), with which options, and how its functions are compiled.

The formulation does not depend on the backend: fatrop (structure-exploiting, the default)
and IPOPT (the reference, and the fallback when fatrop fails) get the same NLP. With
settings.compile the NLP's functions are generated as C, compiled by gcc in a daemon thread and
kept on disk (compilation.py), so that a restarted controller loads them at once; until the
library is there, CasADi's interpreted functions run.

Each solver call can be given a time limit and an iteration limit (run_solver's time_limit
and iteration_limit: what is left of the control step's budget, SolverSettings.budget). IPOPT is
stopped by an iteration callback that reads the limits of the call in progress (its own
max_wall_time and max_iter options are fixed when the solver is built): past the time, or
after so many iterations exactly. Fatrop has no time limit (CasADi refuses max_wall_time and
max_cpu_time for it: "Fatrop option not supported") and calls no iteration callback, so a call
with little left runs a copy of the solver with a smaller max_iter (ITERATION_LEVELS):
the largest that fits the iterations left, or the time left at the time per iteration measured
on this NLP. The time-limited copies are built on first use from the compiled library (until
that is loaded, the full solver runs, and only the retries after it are bounded); an iteration
limit is always kept, by an interpreted copy if need be.
"""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass, field, replace
import hashlib
import json
import logging
import math
import os
from pathlib import Path
import threading
import time
from typing import Any, Callable, NamedTuple, Protocol

import casadi as ca
import numpy as np

from mpc_local_planner.core.config import NlpSolver, SolverSettings
from mpc_local_planner.core.mpc import compilation
from mpc_local_planner.core.mpc.formulation import Formulation
from mpc_local_planner.core.mpc.hang_guard import call_guarded, SolverHang

__all__ = ['HANG_SECONDS', 'Nlp', 'SolverRun', 'SolverRunner', 'backend_options', 'build_nlp',
           'compile_flags', 'hang_after', 'iteration_levels', 'run_solver', 'stage_size']

_LOG = logging.getLogger(__name__)

# Iteration limits of the copies a call with little time left runs instead of the full solver
# (fatrop: no time limit of its own), as fractions of settings.max_iterations: halving keeps the
# copies few (one per level and NLP, built when first needed) and wastes at most half of what
# the time left would allow.
ITERATION_LEVELS = (0.5, 0.25, 0.125, 0.0625)
# Fewer iterations than this are not worth a call: from the warm start a solve typically
# takes 5 to 20 (the limited call still runs, so that the time per iteration stays measured).
MIN_ITERATIONS = 8
# How fast the measured time per iteration follows a faster sample (a slower one is taken at
# once): a load spike makes the next calls careful, and they relax over some ten calls.
ITERATION_TIME_DECAY = 0.9
# IPOPT's status when the iteration callback stopped it.
_USER_STOP = 'User_Requested_Stop'


def _ipopt_options(settings: SolverSettings, *, cold: bool = False) -> dict[str, Any]:
    """Return IPOPT's options: from the proof's candidate (warm), or from an infeasible start.

    Warm: the initial guess is the candidate, feasible by construction, so the interior-point
    iterates are kept near it instead of being pushed off the bounds. Cold (the robot at
    rest, no plan): those settings slow IPOPT down; at the seven BARN stalls at 1 m/s
    (polygon NLPs with 2 to 5 obstacles, three starts each) IPOPT's default bound push with
    mu_init 1e-2 converged in 20 of the 21 solves, in 22 to 138 iterations, mostly about
    half of the warm settings' count, where fatrop failed in six of the seven from every
    start.
    """
    options = {
        'ipopt.print_level': 0,
        'ipopt.sb': 'yes',
        'ipopt.max_iter': settings.max_iterations,
        'ipopt.tol': settings.tolerance,
        'ipopt.acceptable_tol': 1e-6,
    }
    if cold:
        options['ipopt.mu_init'] = 1e-2
        options['ipopt.mu_strategy'] = 'adaptive'
    else:
        options.update({'ipopt.bound_push': 1e-8, 'ipopt.bound_frac': 1e-8,
                        'ipopt.mu_init': 1e-4})
    return options


def _fatrop_options(settings: SolverSettings, structure: dict) -> dict[str, Any]:
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
            'max_iter': settings.max_iterations,
            'tol': settings.tolerance,
        },
    }


def backend_options(settings: SolverSettings, structure: dict) -> tuple[str, dict[str, Any]]:
    """Return (nlpsol plugin, options) for settings.solver.

    Args:
        settings: the solver's name, iteration limit, tolerance and extra options.
        structure: the formulation's stage sizes (Formulation.structure), for fatrop.

    Raises:
        ValueError: if settings.solver is not a known backend.

    """
    common = {'print_time': False, 'error_on_fail': False}
    name = settings.solver
    if name is NlpSolver.IPOPT:
        plugin, options = 'ipopt', _ipopt_options(settings)
    elif name is NlpSolver.FATROP:
        plugin, options = 'fatrop', _fatrop_options(settings, structure)
    else:
        msg = f'unknown solver {name!r}'
        raise ValueError(msg)
    options.update(common)
    options.update(settings.solver_options)
    return plugin, options


class _Deadline(ca.Callback):
    """IPOPT's iteration callback: asks the solver to stop once the clock passes `at`.

    Or once `max_iterations` iterations are done (IPOPT calls it at iteration 0 too: the
    call after `max_iterations` stops it, and it reports as many). One per NLP (its inputs
    are the solver's outputs, sized by the NLP), shared by the IPOPT solvers of that NLP;
    run_solver sets the limits for the call in progress and clears them after. The limits are
    the calling thread's (IPOPT calls back in the thread that called it): MPCs share their
    solvers (built_nlps.py), and two of them solving in two threads keep their own limits.
    """

    def __init__(self, problem: dict) -> None:
        ca.Callback.__init__(self)
        nx, ng, npar = (int(problem[k].numel()) for k in ('x', 'g', 'p'))
        self._sizes = {'x': nx, 'f': 1, 'g': ng, 'lam_x': nx, 'lam_g': ng, 'lam_p': npar}
        self._call = threading.local()
        self.construct('mpc_deadline', {})

    def arm(self, at: float = math.inf, max_iterations: float = math.inf) -> None:
        """Set the limits of this thread's next call (the defaults clear them).

        Args:
            at: time.perf_counter() seconds after which the call stops.
            max_iterations: iterations after which it stops.

        """
        self._call.at, self._call.max_iterations, self._call.calls = at, max_iterations, 0

    @property
    def at(self) -> float:
        """This thread's time limit (time.perf_counter() seconds; inf: none)."""
        return getattr(self._call, 'at', math.inf)

    @property
    def max_iterations(self) -> float:
        """This thread's iteration limit (inf: none)."""
        return getattr(self._call, 'max_iterations', math.inf)

    @property
    def calls(self) -> int:
        """Iterations reported in this thread's call in progress (or last call)."""
        return getattr(self._call, 'calls', 0)

    def get_n_in(self) -> int:
        return ca.nlpsol_n_out()

    def get_n_out(self) -> int:
        return 1

    def get_name_in(self, i: int) -> str:
        return ca.nlpsol_out(i)

    def get_name_out(self, i: int) -> str:
        return 'stop'

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(self._sizes[ca.nlpsol_out(i)], 1)

    def eval(self, arg: list) -> list:
        self._call.calls = self.calls + 1
        stop = self.calls > self.max_iterations or time.perf_counter() > self.at
        return [1.0 if stop else 0.0]


def _built_once(factory: Callable[[], ca.Function] | None
                ) -> Callable[[], ca.Function] | None:
    """Return factory, calling it at most once: later calls return what it built."""
    if factory is None:
        return None
    built: list[ca.Function] = []

    def once() -> ca.Function:
        if not built:
            built.append(factory())
        return built[0]

    return once


def iteration_levels(max_iterations: int) -> list[int]:
    """Return the iteration limits a time-limited call may use, largest (the full one) first."""
    levels = [max_iterations]
    for fraction in ITERATION_LEVELS:
        level = int(max_iterations * fraction)
        if level < MIN_ITERATIONS:
            break
        levels.append(level)
    return levels


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
    cold: ca.Function | None = None  # IPOPT with cold-start options (_cold_ipopt_options)
    cold_factory: Callable[[], ca.Function] | None = None
    deadline: _Deadline | None = None  # stops this NLP's IPOPT solvers (see run_solver)
    library: Path | None = None  # the compiled functions, once the solver uses them
    max_iterations: int = 0  # the solver's iteration limit
    # the primary solver with fewer iterations (fatrop: see run_solver), by limit
    limited: dict[int, ca.Function] = field(default_factory=dict)
    # seconds per iteration measured on this NLP's primary solver (0: not yet measured)
    iteration_time: float = 0.0

    def shareable(self) -> Nlp:
        """Make this just-built record the template of the records MPCs share (built_nlps.py).

        Its IPOPT factories then build once for every record, and its formulation's bounds
        become read-only (every record reads them).
        """
        self.fallback_factory = _built_once(self.fallback_factory)
        self.cold_factory = _built_once(self.cold_factory)
        form = self.formulation
        for bounds in (form.lbw, form.ubw, form.lbg, form.ubg):
            bounds.setflags(write=False)
        return self

    def share(self) -> Nlp:
        """Return a new record of this template as build_nlp would: its solvers, shared.

        Its IPOPTs are not set yet (the first fallback_solver() or cold_solver() gets the
        shared one), its time per iteration is not measured, and its compiled solver is the
        template's: loaded if the compilation is done, else swapped in when it is.
        """
        self.finish_compilation()
        return replace(self, fallback=None, cold=None, iteration_time=0.0)

    def fallback_solver(self) -> ca.Function | None:
        """Return the IPOPT fallback, building it the first time it is needed."""
        if self.fallback is None and self.fallback_factory is not None:
            self.fallback = self.fallback_factory()
        return self.fallback

    def cold_solver(self) -> ca.Function | None:
        """Return IPOPT with cold-start options, building it the first time it is needed."""
        if self.cold is None and self.cold_factory is not None:
            self.cold = self.cold_factory()
        return self.cold

    @property
    def cold_build_time(self) -> float:
        """Return the seconds getting the cold-start IPOPT will take: 0 once built."""
        return 0.0 if self.cold is not None else self.build_time_s

    @property
    def has_fallback(self) -> bool:
        """There is an IPOPT fallback (built or not yet)."""
        return self.fallback is not None or self.fallback_factory is not None

    @property
    def fallback_build_time(self) -> float:
        """Return the seconds getting the fallback will take: 0 once built.

        Until then, the time this NLP's own solver took to build: IPOPT on the same problem
        takes about as long (0.6 to 1.3 times, measured on the paper's and BARN's NLPs).
        """
        return 0.0 if self.fallback is not None else self.build_time_s

    def solver_within(self, seconds: float,
                      iterations: float = math.inf) -> tuple[ca.Function, int]:
        """Return the primary solver, or a copy with fewer iterations that fits the limits.

        The full solver unless it is fatrop (IPOPT stops itself: its iteration callback), or
        when max_iterations of it fit: in the iterations given, and in seconds at the time
        per iteration measured (not measured yet: no time bound). Else the copy of the
        largest level of iteration_levels() that fits (the smallest if none does). Copies are
        built from the compiled library (a few ms, once per level); before there is one, a
        time-bounded call runs the full solver (an interpreted copy costs tens of ms to build,
        more than it would save), an iteration-bounded one an interpreted copy (the
        iteration budget is kept whatever its build costs: wall time does not count there).

        Returns:
            The solver and its iteration limit.

        """
        full = self.max_iterations
        if self.plugin != 'fatrop' or full <= 0:
            return self.solver, full
        fit = iterations
        if self.iteration_time > 0.0:
            fit = min(fit, seconds / self.iteration_time)
        if fit >= full:
            return self.solver, full
        levels = iteration_levels(full)
        limit = next((level for level in levels if level <= fit), levels[-1])
        if limit == full:
            return self.solver, full
        solver = self.limited.get(limit)
        if solver is None:
            if self.library is not None:
                source: Any = str(self.library)
            elif iterations < full:
                source = self.formulation.problem
            else:
                return self.solver, full
            solver = self.limited[limit] = ca.nlpsol(
                f'mpc_{limit}', self.plugin, source, _with_iteration_limit(self.options, limit))
        return solver, limit

    def abandon(self, solver: ca.Function) -> None:
        """Stop using a solver whose call never returned (a thread is still inside it).

        Its memory and its stats are the stuck call's: the primary solver is built again
        (from the compiled library, a few ms, else from the problem), a limited copy is
        dropped (rebuilt when next needed); an IPOPT (the fallback, the cold start) is
        kept (IPOPT's own perturbation limit and deadline bound its calls; not met).
        """
        if solver is self.solver:
            source: Any = str(self.library) if self.library is not None \
                else self.formulation.problem
            self.solver = ca.nlpsol('mpc', self.plugin, source, self.options)
        self.limited = {k: v for k, v in self.limited.items() if v is not solver}

    def record_iterations(self, seconds: float, iterations: int) -> None:
        """Update the time per iteration from a call of the primary solver (or its copies)."""
        if iterations <= 0 or not math.isfinite(seconds):
            return
        sample = seconds / iterations
        decayed = ITERATION_TIME_DECAY * self.iteration_time + (1 - ITERATION_TIME_DECAY) * sample
        self.iteration_time = sample if self.iteration_time <= 0.0 else max(sample, decayed)

    def finish_compilation(self, *, wait: bool = False) -> None:
        """Swap in the compiled solver once its background compilation is done.

        Args:
            wait: block until the compilation is done (or failed). A compilation still
                queued behind others is run at once, in this thread (gcc is a subprocess:
                the background one goes on meanwhile); the seconds waited are counted in
                compile_wait_seconds().

        """
        future = self.pending
        if future is None or not (wait or future.done()):
            return
        self.pending = None
        try:
            if not future.done():
                compilation.wait_for(future)
            library = future.result()
            self.solver = ca.nlpsol('mpc', self.plugin, str(library), self.options)
            self.compiled = True
            self.library = library
        except Exception as err:  # any failure falls back to the interpreter
            _LOG.warning('compiling the MPC NLP failed, using the interpreted functions: %s',
                         err)


def _with_iteration_limit(options: dict[str, Any], limit: int) -> dict[str, Any]:
    """Return a copy of a fatrop solver's options with another iteration limit."""
    limited = dict(options)
    limited['fatrop'] = {**options.get('fatrop', {}), 'max_iter': limit}
    return limited


def _iteration_limit(plugin: str, options: dict[str, Any], default: int) -> int:
    """Return the iteration limit the options give the plugin (settings.solver_options may)."""
    inner = options.get(plugin, {})
    if isinstance(inner, dict) and 'max_iter' in inner:
        return int(inner['max_iter'])
    return int(options.get(f'{plugin}.max_iter', default))


def stage_size(structure: dict) -> int:
    """Return the most variables a stage of the formulation has (states plus inputs)."""
    return max(nx + nu for nx, nu in zip(structure['nx'], structure['nu'], strict=True))


def build_nlp(formulation: Formulation, settings: SolverSettings) -> Nlp:
    """Create the solver of settings.solver for the formulation (and start compiling it).

    fatrop with stages larger than settings.fatrop_stage_limit is IPOPT instead (see there):
    with 10 boxes held, fatrop's iterations were 3x IPOPT's and a warm solve overran the
    step's budget, where even fatrop's smallest iteration limit did not fit.
    """
    start = time.perf_counter()
    problem, structure = formulation.problem, formulation.structure
    if settings.solver is NlpSolver.FATROP and \
            stage_size(structure) > settings.fatrop_stage_limit:
        settings = settings.with_changes(solver=NlpSolver.IPOPT)
    plugin, options = backend_options(settings, structure)
    deadline = _Deadline(problem)
    if plugin == 'ipopt':
        options.setdefault('iteration_callback', deadline)
    nlp = Nlp(formulation=formulation, solver=ca.nlpsol('mpc', plugin, problem, options),
              backend=settings.solver, plugin=plugin, options=options, deadline=deadline,
              max_iterations=_iteration_limit(plugin, options, settings.max_iterations))
    if settings.solver is not NlpSolver.IPOPT:
        # a structure-exploiting backend is fast but less robust far from its warm start
        # (seen: fatrop failing near the box's corner under timing jitter); IPOPT, the
        # reference, gets the same problem before the controller gives up. Built on first
        # use: building it with every NLP doubled the start-up time.
        fallback = settings.with_changes(solver=NlpSolver.IPOPT)
        fb_plugin, fb_options = backend_options(fallback, structure)
        fb_options.setdefault('iteration_callback', deadline)
        nlp.fallback_factory = lambda: ca.nlpsol('mpc_fallback', fb_plugin, problem, fb_options)
    cold_options = {**_ipopt_options(settings, cold=True), 'print_time': False,
                    'error_on_fail': False, 'iteration_callback': deadline}
    nlp.cold_factory = lambda: ca.nlpsol('mpc_cold', 'ipopt', problem, cold_options)
    if settings.compile:
        _start_compilation(nlp)
    nlp.build_time_s = time.perf_counter() - start
    return nlp


# A solver call that has not returned after this long is abandoned (hang_guard.py): fatrop's
# inertia correction has no bound. Under a wall budget, HANG_FACTOR times the call's time
# limit (at least HANG_FLOOR); under an iteration budget (no time limit), HANG_SECONDS: about
# eight times the slowest solve seen in the suites (0.64 s, BARN at --jobs 2).
HANG_SECONDS = 5.0
HANG_FLOOR = 1.0
HANG_FACTOR = 10.0


def hang_after(time_limit: float) -> float:
    """Return the seconds after which a call with this time limit is given up."""
    if not math.isfinite(time_limit):
        return HANG_SECONDS
    return min(HANG_SECONDS, max(HANG_FLOOR, HANG_FACTOR * time_limit))


class SolverRun(NamedTuple):
    """What one call of an NLP solver returned (not yet verified)."""

    w: np.ndarray  # the primal solution
    value: float  # the cost at w (inf when the solver did not report success)
    success: bool  # the solver reported success and w is finite
    status: str  # the solver's return status
    iterations: int
    seconds: float  # wall time of the call (and of building a limited copy for it)
    cut: bool = False  # the time limit stopped it (or left no time to start) before success


class SolverRunner(Protocol):
    """What runs an NLP's solver for a step (run_solver; a test's or benchmark's stand-in)."""

    def __call__(self, nlp: Nlp, w0: np.ndarray, params: np.ndarray,
                 solver: ca.Function | None = None, *, time_limit: float = math.inf,
                 iteration_limit: float = math.inf) -> SolverRun:
        """Solve nlp from w0 within the limits (see run_solver)."""


def _limited_call(solver: ca.Function, deadline: _Deadline | None, at: float,
                  iteration_limit: float, arguments: dict[str, Any]) -> dict[str, Any]:
    """Call solver with the deadline armed on this thread (IPOPT calls back on it)."""
    if deadline is not None:
        deadline.arm(at, iteration_limit)
    try:
        return solver(**arguments)
    finally:
        if deadline is not None:
            deadline.arm()


def run_solver(nlp: Nlp, w0: np.ndarray, params: np.ndarray,
               solver: ca.Function | None = None, *,
               time_limit: float = math.inf, iteration_limit: float = math.inf) -> SolverRun:
    """Solve the NLP from w0 with its solver (or the given one, e.g. the fallback).

    Args:
        nlp: the NLP.
        w0: the initial guess.
        params: the parameter vector.
        solver: the solver to call instead of the NLP's own (the IPOPT fallback).
        time_limit: seconds the call may take. None left (<= 0): no call, a cut run that
            returns w0. IPOPT is stopped by its iteration callback once the limit passes (one
            iteration late at most); the NLP's own fatrop runs a copy with fewer iterations
            when its measured time per iteration says the full limit would not fit
            (Nlp.solver_within): not exact, but bounded.
        iteration_limit: iterations the call may make. None left (< 1): no call, as above.
            IPOPT stops after exactly that many; the NLP's own fatrop runs the copy of the
            largest iteration level within it (the smallest if none is): bounded, and the
            same on any machine.

    """
    if not (time_limit > 0.0 and iteration_limit >= 1):
        return SolverRun(w=np.asarray(w0, dtype=float).reshape(-1), value=math.inf,
                         success=False, status='not started: no budget left', iterations=0,
                         seconds=0.0, cut=True)
    form = nlp.formulation
    start = time.perf_counter()
    limit = None
    if solver is None:
        # may build a limited copy: timed too
        solver, limit = nlp.solver_within(time_limit, iteration_limit)
    called = time.perf_counter()
    try:
        result = call_guarded(_limited_call, hang_after(time_limit), solver=solver,
                              deadline=nlp.deadline, at=start + time_limit,
                              iteration_limit=iteration_limit,
                              arguments={'x0': w0, 'p': params, 'lbx': form.lbw,
                                         'ubx': form.ubw, 'lbg': form.lbg, 'ubg': form.ubg})
    except SolverHang as err:
        nlp.abandon(solver)
        _LOG.error('%s (%s); it is rebuilt and the step goes on without it', err, nlp.plugin)
        return SolverRun(w=np.asarray(w0, dtype=float).reshape(-1), value=math.inf,
                         success=False, status=f'abandoned: {err}', iterations=0,
                         seconds=time.perf_counter() - start, cut=True)
    end = time.perf_counter()
    stats = solver.stats()
    w_opt = np.asarray(result['x']).reshape(-1)
    success = bool(stats.get('success', False)) and bool(np.all(np.isfinite(w_opt)))
    status = str(stats.get('return_status', 'unknown'))
    iterations = int(stats.get('iter_count', 0))
    if limit is not None:
        nlp.record_iterations(end - called, iterations)
    limited = limit is not None and limit < nlp.max_iterations
    cut = not success and (status == _USER_STOP or (limited and iterations >= limit))
    return SolverRun(w=w_opt, value=float(result['f']) if success else math.inf,
                     success=success, status=status, iterations=iterations,
                     seconds=end - start, cut=cut)


# ----------------------------------------------------------------------------- compilation
def _start_compilation(nlp: Nlp) -> None:
    """Use a cached compiled library now, or compile one in the background.

    The library is named by the hash of its C source (compilation.library_path); generating
    the source took a third of a warm start (0.2-0.4 s a shape, 14 s of 47 for the 21 shapes
    of a BARN run), so a pointer file named by a cheaper key (_problem_key: the NLP's serialized
    expressions, 35x faster) finds it without generating the source again.
    """
    try:
        pointer = compilation.pointer_path(_problem_key(nlp))
        library = compilation.pointed_library(pointer)
        if library is None:
            source = compilation.nlp_source(nlp.formulation.problem, nlp.solver)
            flags = compile_flags(nlp)
            library = compilation.library_path(source, flags)
            compilation.write_pointer(pointer, library)
            if not library.exists():
                nlp.pending = compilation.submit_compilation(source, library, flags)
                return
        nlp.solver = ca.nlpsol('mpc', nlp.plugin, str(library), nlp.options)
        nlp.compiled = True
        nlp.library = library
    except Exception as err:  # any failure falls back to the interpreter
        _LOG.warning('compiling the MPC NLP failed, using the interpreted functions: %s', err)


def compile_flags(nlp: Nlp) -> tuple[str, ...]:
    """Return gcc's flags for this NLP (part of its library's cache key)."""
    if nlp.formulation.slots == 0:
        return compilation.NO_OBSTACLE_COMPILE_FLAGS
    return compilation.COMPILE_FLAGS


def _problem_key(nlp: Nlp) -> str:
    """Return a hash of what decides the generated C: the NLP, the plugin and its options.

    The NLP's expressions serialized (exactly its graph), the plugin, the functions it
    evaluates, its options (those that shape the derivatives: a fatrop's stage structure,
    and the rest, which split the cache at worst) and, as for the library, CasADi's
    version, the compiler and its flags.
    """
    problem = nlp.formulation.problem
    function = ca.Function('nlp', [problem['x'], problem['p']], [problem['f'], problem['g']],
                           ['x', 'p'], ['f', 'g'])
    options = {k: v for k, v in nlp.options.items() if k != 'iteration_callback'}
    parts = [ca.__version__, os.environ.get('CC', 'gcc'), *compile_flags(nlp), nlp.plugin,
             ','.join(nlp.solver.get_function()), json.dumps(options, sort_keys=True,
                                                             default=repr),
             function.serialize()]
    return hashlib.sha256('\n'.join(parts).encode()).hexdigest()[:24]
