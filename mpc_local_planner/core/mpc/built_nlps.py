# SPDX-License-Identifier: Apache-2.0
"""The NLPs built in this process, shared by every MPC of the same model and problem.

Building a shape's solvers (the formulation, CasADi's derivatives, the set-up of fatrop and
of its two IPOPTs) takes tens of ms, and preparing an MPC builds every shape it may meet
(docs/design/mpc.md, section "Shared NLPs"). A lifecycle node configured again, an
evaluation's next world and a test's next controller would pay that again for the same
problem. Here the first build of a problem is kept (the last MAX_SHARED_PROBLEMS of them) and
every MPC after it gets the same solvers at once.

What each MPC gets is its own `Nlp` record (`Nlp.share`), exactly as a build would give it:
its time per iteration is measured anew, its IPOPTs are set at first use, its compiled
solver is swapped in by its own steps. What the records share depends on the problem only:
the formulation (read-only), the solvers, the IPOPTs once some record built them, the
iteration-limited copies and the compiled library.

The key is everything a build reads: the model (hashable, as RobotModel asks: its bounds
are in the NLP), the settings' structure_key(), the terminal condition's structure, the
shape, and with compile the compile cache folder and compiler (they decide which library is
loaded).
"""

from __future__ import annotations

from collections import OrderedDict
import os
import threading
from typing import Hashable

from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.models import RobotModel
from mpc_local_planner.core.mpc import compilation
from mpc_local_planner.core.mpc.backends import build_nlp, Nlp
from mpc_local_planner.core.mpc.formulation import formulate, TerminalCondition

__all__ = ['MAX_SHARED_PROBLEMS', 'clear_shared_nlps', 'problem_key', 'shared_nlp']

# Problems kept (the least recently used goes first): a BARN run's MPC uses about 20 shapes,
# and each kept problem holds its solvers' memory (a few MB).
MAX_SHARED_PROBLEMS = 64

_BUILT: OrderedDict[Hashable, Nlp] = OrderedDict()
_LOCK = threading.Lock()


def problem_key(model: RobotModel, config: MpcConfig, terminal: TerminalCondition,
                slots: int, faces: int) -> Hashable:
    """Return the key of the NLP that formulate() and build_nlp() make of these arguments."""
    compiled = ((str(compilation.compile_cache_dir()), os.environ.get('CC', 'gcc'))
                if config.solving.compile else None)
    terminal_key = (terminal.family, terminal.dim, terminal.num_params,
                    tuple(terminal.lower.tolist()), tuple(terminal.upper.tolist()),
                    terminal.carried)
    return (type(model), model, config.structure_key(), terminal_key, slots, faces,
            compiled)


def shared_nlp(model: RobotModel, config: MpcConfig, terminal: TerminalCondition,
               slots: int, faces: int) -> Nlp:
    """Return an own record of the NLP of this problem: built now the first time, shared after.

    Args:
        model: the robot model.
        config: the MPC's settings (its problem and how it is solved).
        terminal: the terminal condition and offset cost.
        slots: obstacles the NLP holds.
        faces: half-planes per obstacle.

    """
    key = problem_key(model, config, terminal, slots, faces)
    with _LOCK:
        template = _BUILT.get(key)
        if template is not None:
            _BUILT.move_to_end(key)
    if template is None:
        template = build_nlp(formulate(model, config, terminal, slots, faces),
                             config.solving).shareable()
        with _LOCK:
            template = _BUILT.setdefault(key, template)
            while len(_BUILT) > MAX_SHARED_PROBLEMS:
                _BUILT.popitem(last=False)
    return template.share()


def clear_shared_nlps() -> None:
    """Forget every shared NLP (the next MPC of each problem builds it again)."""
    with _LOCK:
        _BUILT.clear()
