# SPDX-License-Identifier: Apache-2.0
"""The paper's MPC (problem (6)) and its guard.

formulation.py is problem (6), backends.py runs it (solvers), compilation.py compiles it,
nlp_shapes.py keeps one NLP per obstacle shape, built_nlps.py shares the built ones between
the MPCs of a process, step.py is one control step (verification, constraint generation, the
decision) for the terminal condition path_mpc.py gives, with
candidate.py (the proof's shifted candidate, the guided start), clearance.py (the footprint
against obstacles), budget.py (a step's solving budget) and continuation.py (a cut solve
going on at the next step); solution.py is what a step returns, tries.py the solver strategy
of its NLP solves (which start with which solver, in which order), decision.py its guard
(what is applied).
"""

from mpc_local_planner.core.mpc.compilation import compile_cache_dir
from mpc_local_planner.core.mpc.decision import decide, Decision, LyapunovCase, PlanSource
from mpc_local_planner.core.mpc.path_mpc import PathReferenceMPC
from mpc_local_planner.core.mpc.solution import MpcSolution
from mpc_local_planner.core.mpc.step import MpcBase
from mpc_local_planner.core.mpc.tries import Situation, Solver, solver_tries, Start, Try

__all__ = [
    'Decision',
    'LyapunovCase',
    'MpcBase',
    'MpcSolution',
    'PathReferenceMPC',
    'PlanSource',
    'Situation',
    'Solver',
    'Start',
    'Try',
    'compile_cache_dir',
    'decide',
    'solver_tries',
]
