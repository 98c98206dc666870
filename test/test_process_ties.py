# SPDX-License-Identifier: Apache-2.0
"""Processes the package starts end with their parent, even one killed outright."""

from __future__ import annotations

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest

from mpc_local_planner.process_ties import TIED_ENV, tied_environment

pytestmark = pytest.mark.skipif(not sys.platform.startswith('linux'),
                                reason='PR_SET_PDEATHSIG is Linux only')

# a child that ties itself if asked and then waits to be ended (it never ends by itself)
CHILD = ('from mpc_local_planner.process_ties import tie_if_asked; import time; '
         'tie_if_asked(); print("tied", flush=True); time.sleep(600)')
# a parent that starts the child (tied or not), says the child's pid once tied, and waits
PARENT = ('import subprocess, sys, time; from mpc_local_planner.process_ties import '
          'tied_environment; import os; '
          'env = tied_environment() if sys.argv[1] == "tied" else dict(os.environ); '
          'child = subprocess.Popen([sys.executable, "-c", sys.argv[2]], env=env, '
          'stdout=subprocess.PIPE, text=True); child.stdout.readline(); '
          'print(child.pid, flush=True); time.sleep(600)')
GONE_WITHIN_S = 10.0
# an untied child is looked at this long after its parent ended (a tied one ends within
# about 0.3 s here: the kernel signals it as the parent dies)
UNTIED_LOOK_S = 1.0


def running(pid: int) -> bool:
    """Say whether pid is a live process (a zombie, ended but not reaped, is not)."""
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ('Z', 'X')


def child_after_parent_killed(mode: str, within: float) -> tuple[int, bool]:
    """Return the child's pid, and whether it ended within seconds of its parent's SIGKILL."""
    env = {k: v for k, v in os.environ.items() if k != TIED_ENV}
    parent = subprocess.Popen([sys.executable, '-c', PARENT, mode, CHILD], env=env,
                              stdout=subprocess.PIPE, text=True)
    child = int(parent.stdout.readline())
    parent.kill()  # outright: no handler, no finally
    parent.wait(timeout=GONE_WITHIN_S)
    deadline = time.monotonic() + within
    while running(child) and time.monotonic() < deadline:
        time.sleep(0.05)  # waits for the kernel's signal to take effect, bounded
    return child, not running(child)


def test_a_tied_child_ends_when_its_parent_is_killed_outright() -> None:
    _, ended = child_after_parent_killed('tied', GONE_WITHIN_S)
    assert ended


def test_a_child_not_tied_outlives_its_parent_as_a_user_started_node_must() -> None:
    child, ended = child_after_parent_killed('untied', UNTIED_LOOK_S)
    try:
        assert not ended
    finally:
        if not ended:
            os.kill(child, signal.SIGKILL)


def test_the_tied_environment_keeps_the_given_one_and_adds_the_tie() -> None:
    env = tied_environment({'ROS_DOMAIN_ID': '7'})
    assert env == {'ROS_DOMAIN_ID': '7', TIED_ENV: '1'}
