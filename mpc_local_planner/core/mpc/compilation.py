# SPDX-License-Identifier: Apache-2.0
"""Compiling an NLP's functions to C, and the cache of compiled libraries on disk.

With SolverSettings.compile the NLP's functions are generated as C (nlp_source), compiled by gcc
(the flags: COMPILE_FLAGS, NO_OBSTACLE_COMPILE_FLAGS) in one daemon thread, one compilation
at a time (submit_compilation; a step that needs one still queued runs it itself, wait_for),
and kept in compile_cache_dir() under the hash of their source (library_path), found again
by a pointer file named by a cheaper key (pointer_path). backends.py decides what to compile
and swaps the library in; nothing here knows an NLP.
"""

from __future__ import annotations

import atexit
from collections import deque
from concurrent.futures import Future
import fcntl
import hashlib
import multiprocessing.util
import os
from pathlib import Path
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from typing import Callable

import casadi as ca

__all__ = ['COMPILE_FLAGS', 'COMPILE_NICENESS', 'NO_OBSTACLE_COMPILE_FLAGS', 'Compiler',
           'compile_cache_dir', 'compile_library', 'compile_wait_seconds', 'library_path',
           'nlp_source', 'pointed_library', 'pointer_path', 'run_compiler',
           'submit_compilation', 'wait_for', 'write_pointer']

# How much lower the compiler's CPU priority is than its process's (nice -n): a background
# compilation must not take a core from a robot's control loop or its other nodes.
COMPILE_NICENESS = 10
# C compiler and flags for config.compile (compile_flags); CC overrides the compiler as usual.
# NLPs with obstacle slots: -O0, not -O2: gcc took 5x less time on the Jackal's polygon NLPs
# (4.6 s instead of 25.6 s for 3 boxes, 17 s instead of 88 s for 10 octagons, on 2 loaded
# cores) and the solves 1.2x more (most of such a solve is the solver's own linear algebra,
# compiled with the solver), with the same results to the bit (x86-64: no -ffast-math, no
# fused multiply-add); see docs/results.md, "Cold start".
COMPILE_FLAGS = ('-O0', '-fPIC', '-shared')
# The NLP without obstacles: -O1. The smallest (gcc 10 s at -O1, 12 s at -O2, compiled
# first, while the others are built), the most used (half of a BARN run's solves), and the
# one where the generated functions are most of a solve: 1.56x at -O0, 1.00x at -O1.
NO_OBSTACLE_COMPILE_FLAGS = ('-O1', '-fPIC', '-shared')

def compile_cache_dir() -> Path:
    """Return where compiled NLPs are kept ($MPC_LOCAL_PLANNER_CACHE or ~/.cache/...)."""
    env = os.environ.get('MPC_LOCAL_PLANNER_CACHE')
    if env:
        return Path(env)
    base = os.environ.get('XDG_CACHE_HOME') or str(Path.home() / '.cache')
    return Path(base) / 'mpc_local_planner'


def pointer_path(key: str) -> Path:
    """Return the pointer file of a problem key: it names the key's library."""
    return compile_cache_dir() / f'mpc_nlp_{key}.key'


def pointed_library(pointer: Path) -> Path | None:
    """Return the library a pointer file names, if both are there."""
    try:
        library = pointer.parent / pointer.read_text(encoding='utf-8').strip()
    except OSError:
        return None
    return library if library.suffix == '.so' and library.exists() else None


def write_pointer(pointer: Path, library: Path) -> None:
    """Write the pointer file atomically (two processes may write the same one)."""
    pointer.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile('w', dir=pointer.parent, suffix='.tmp', delete=False,
                                     encoding='utf-8') as f:
        f.write(library.name)
    os.replace(f.name, pointer)


def nlp_source(problem: dict, solver: ca.Function) -> str:
    """Return C code of the NLP functions the solver plugin evaluates (and the oracle)."""
    generator = ca.CodeGenerator('mpc_nlp.c', {'with_header': False})
    generator.add(ca.Function('nlp', [problem['x'], problem['p']],
                              [problem['f'], problem['g']], ['x', 'p'], ['f', 'g']))
    for name in solver.get_function():
        generator.add(solver.get_function(name))
    return generator.dump()


def library_path(source: str, flags: tuple[str, ...] = COMPILE_FLAGS) -> Path:
    """Return the cache file of this source (its hash, with CasADi, compiler and flags)."""
    compiler = os.environ.get('CC', 'gcc')
    key = hashlib.sha256('\n'.join(
        [ca.__version__, compiler, *flags, source]).encode()).hexdigest()[:24]
    return compile_cache_dir() / f'mpc_nlp_{key}.so'


# What turns a C source into a library: (source, library, flags) -> library (run_compiler).
Compiler = Callable[[str, Path, tuple[str, ...]], Path]


class _CompileJob(Future):
    """A compilation: its result (the library) once run, by the queue or by a waiter."""

    def __init__(self, source: str, library: Path, flags: tuple[str, ...],
                 compiler: Compiler) -> None:
        super().__init__()
        self._work: tuple[str, Path, tuple[str, ...]] | None = (source, library, flags)
        self._compiler = compiler
        self._claim = threading.Lock()

    def run(self) -> None:
        """Compile, unless it is (being) done already: whoever comes first runs it."""
        with self._claim:
            work, self._work = self._work, None
        if work is None:
            return
        try:
            self.set_result(compile_library(*work, compiler=self._compiler))
        except BaseException as err:  # handed to the waiting solver
            self.set_exception(err)


# Compilations not yet started, in the order they were asked for; one daemon thread runs
# them one at a time (the machine may have two cores and a control loop to run), and a
# step that needs one still queued runs it itself (Nlp.finish_compilation(wait=True)).
_QUEUE: deque[_CompileJob] = deque()
_QUEUE_READY = threading.Condition()
_WORKER: list[threading.Thread] = []
class _WaitTotal:
    """Seconds spent waiting for compilations in this process, added from any thread."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._seconds = 0.0

    def add(self, seconds: float) -> None:
        with self._lock:
            self._seconds += seconds

    @property
    def seconds(self) -> float:
        with self._lock:
            return self._seconds


_WAITED = _WaitTotal()


def compile_wait_seconds() -> float:
    """Return the seconds callers have waited for compilations so far in this process.

    A rollout subtracts what a control step waited for its NLP's compilation from the
    step's time: the wait happens once per NLP on a fresh machine, not in a robot's loop.
    """
    return _WAITED.seconds


def wait_for(job: Future) -> None:
    """Block until job is done, running it here if it is still queued; count the wait."""
    start = time.perf_counter()
    if isinstance(job, _CompileJob):
        job.run()  # still queued: now, here; else this returns at once
    try:
        job.exception()  # blocks until done
    finally:
        _WAITED.add(time.perf_counter() - start)


def _queue_worker() -> None:
    while True:
        with _QUEUE_READY:
            while not _QUEUE:
                _QUEUE_READY.wait()
            job = _QUEUE.popleft()
        job.run()


def submit_compilation(source: str, library: Path,
                       flags: tuple[str, ...] = COMPILE_FLAGS, *,
                       compiler: Compiler | None = None) -> Future:
    """Queue a compilation for the daemon thread: a node stopped with Ctrl-C must not wait.

    A ThreadPoolExecutor's workers are joined at interpreter exit, which kept a stopped
    controller alive for the whole compilation; a daemon thread is simply dropped (the
    library is renamed into place atomically, so an interrupted build leaves no bad file).
    compiler runs the compiler (run_compiler when None), as in compile_library.
    """
    job = _CompileJob(source, library, flags, compiler or run_compiler)
    with _QUEUE_READY:
        if not _WORKER or not _WORKER[0].is_alive():
            _WORKER[:] = [threading.Thread(target=_queue_worker, name='mpc_compile',
                                           daemon=True)]
            _WORKER[0].start()
        _QUEUE.append(job)
        _QUEUE_READY.notify()
    return job


def compile_library(source: str, library: Path, flags: tuple[str, ...] = COMPILE_FLAGS, *,
                    compiler: Compiler | None = None) -> Path:
    """Compile source into library (atomically: a half-written file is never loaded).

    Processes that want the same library (an evaluation's workers, two nodes) take turns on
    a lock file beside it: the first compiles, the others find the library when their turn
    comes instead of running gcc on the same source at the same time. compiler runs the
    compiler (run_compiler when None; a test gives a stand-in).
    """
    library.parent.mkdir(parents=True, exist_ok=True)
    with open(library.with_suffix('.lock'), 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file is closed
        if library.exists():
            return library
        return (compiler or run_compiler)(source, library, flags)


def run_compiler(source: str, library: Path, flags: tuple[str, ...] = COMPILE_FLAGS) -> Path:
    """Run the system compiler ($CC, else gcc) on source with flags; return library.

    At COMPILE_NICENESS (through `nice`, where there is one): the compiler gets what the
    control loop and the other processes leave of the CPU.

    Raises:
        RuntimeError: if the compiler fails (with its message).
        subprocess.TimeoutExpired: if it takes longer than ten minutes (it is killed).

    """
    compiler = os.environ.get('CC', 'gcc')
    with tempfile.TemporaryDirectory(dir=library.parent) as tmp:
        c_file = Path(tmp) / 'mpc_nlp.c'
        c_file.write_text(source)
        out = Path(tmp) / library.name
        command = [compiler, *flags, str(c_file), '-o', str(out), '-lm']
        nice = shutil.which('nice')
        if nice is not None:
            command = [nice, '-n', str(COMPILE_NICENESS), *command]
        with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True,
                              start_new_session=True) as process:  # gcc and its cc1: a group
            _RUNNING.add(process)
            try:
                _, stderr = process.communicate(timeout=600)
            except subprocess.TimeoutExpired:
                _kill(process)
                raise
            finally:
                _RUNNING.discard(process)
        if process.returncode != 0:
            msg = f'{compiler} failed ({process.returncode}): {stderr.strip()[:500]}'
            raise RuntimeError(msg)
        os.replace(out, library)
    return library


# Compilers running in this process's threads: stopped when it exits (an evaluation's
# worker ends with compilations still queued; its gcc would go on, orphaned, for nothing:
# the temporary folder it writes to is removed at exit). Pool workers leave through
# multiprocessing's exit function, which runs no atexit handler: both are registered.
_RUNNING: set[subprocess.Popen] = set()


def _kill(process: subprocess.Popen) -> None:
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except OSError:  # gone already
        pass


def _stop_compilers() -> None:
    for process in list(_RUNNING):
        _kill(process)


atexit.register(_stop_compilers)
multiprocessing.util.Finalize(None, _stop_compilers, exitpriority=10)
