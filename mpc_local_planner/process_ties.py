# SPDX-License-Identifier: Apache-2.0
"""Processes the package starts end with the process that started them.

An evaluation sweep starts worker processes, each worker a ``closed_loop`` per world, each
``closed_loop`` five node processes. A parent that ends in order stops its children (the
sweep's pool, closed_loop's finally blocks); one killed outright (SIGKILL, an out-of-memory
kill, a session that ends) cannot, and its children went on running worlds nobody would read,
holding the cores and DDS domains of the next sweep. On Linux a child can ask the kernel for
a signal when its parent dies (prctl PR_SET_PDEATHSIG): `tie_to_parent` asks for SIGTERM,
which closed_loop and the nodes handle as Ctrl-C (nodes publish a zero cmd_vel, closed_loop
stops its own children).

Only processes the package starts are tied, through TIED_ENV in their environment
(`tied_environment`; `tie_if_asked` at their start): a node a user starts with ``ros2 run``
or from a launch file must not end because the shell that started it did. Elsewhere than
Linux, nothing is tied.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
from typing import Mapping

__all__ = ['tie_if_asked', 'tie_to_parent', 'TIED_ENV', 'tied_environment']

# Set to '1' in the environment of a process the package starts: it ends with its parent.
TIED_ENV = 'MPC_LOCAL_PLANNER_TIED_TO_PARENT'
_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def tie_to_parent(signum: int = signal.SIGTERM) -> bool:
    """Ask for signum when the parent ends; send it at once if the parent is gone already.

    The kernel's "parent" is the thread that started this process, so a parent must start
    its tied children from a thread that lives as long as it does (the package starts them
    from main threads). Returns whether the tie is in place (Linux only).
    """
    if not sys.platform.startswith('linux'):
        return False
    parent = os.getppid()
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(_PR_SET_PDEATHSIG, int(signum), 0, 0, 0) != 0:
        return False
    if os.getppid() != parent:  # the parent ended while the tie was being made
        os.kill(os.getpid(), signum)
    return True


def tie_if_asked() -> bool:
    """Tie this process to its parent if its environment says so (TIED_ENV)."""
    return os.environ.get(TIED_ENV) == '1' and tie_to_parent()


def tied_environment(base: Mapping[str, str] | None = None) -> dict[str, str]:
    """Return the environment (os.environ by default) for a child that ends with its parent."""
    return {**(os.environ if base is None else base), TIED_ENV: '1'}
