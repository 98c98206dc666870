# SPDX-License-Identifier: Apache-2.0
"""mpc_bench's Opti + IPOPT peer: the same problem as the package's MPC, warm-started."""

import numpy as np
import pytest

from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.paths import paper_sinusoid
from mpc_local_planner.evaluation.bench import HEADER
from mpc_local_planner.evaluation.bench_runs import (
    closed_loop,
    paper_obstacle,
    PEER,
    STEP,
)
from mpc_local_planner.evaluation.opti_peer import OptiMpc


def test_peer_drives_the_paper_scenario_as_the_package_mpc_does() -> None:
    peer = closed_loop(PEER, 10, [paper_obstacle()], max_steps=90)
    package = closed_loop('ipopt', 10, [paper_obstacle()], max_steps=90,
                          compile_functions=False)
    assert peer['solver'] == PEER
    assert peer['reached'] and package['reached']
    assert peer['failures'] == 0 and not peer['collision']
    # The same optimal control problem: the same closed loop, to the centimetre.
    assert peer['path_length'] == pytest.approx(package['path_length'], abs=0.01)


def test_warm_start_cuts_the_iterations_and_reset_starts_cold_again() -> None:
    model, path = Unicycle(), paper_sinusoid()
    peer = OptiMpc(model, MpcConfig(horizon=10, step=STEP), [paper_obstacle()], path)
    x = np.array(path.start, dtype=float)
    for _ in range(5):  # a few steps in, with an obstacle in the horizon's reach
        u, _, _, ok = peer.solve(x)
        assert ok and np.all(np.isfinite(u))
        x = model.step(x, u, STEP)
    u_warm, _, warm, ok = peer.solve(x)
    assert ok
    peer.reset()
    u_cold, _, cold, ok = peer.solve(x)
    assert ok
    assert warm < cold
    assert u_warm == pytest.approx(u_cold, abs=1e-5)  # the same problem, the same answer


def test_table_names_the_peer() -> None:
    assert 'x peer' in HEADER and 'naive' not in HEADER
    assert len(PEER) <= 16  # the backend column's width
    assert OptiMpc.LABEL == 'Opti + IPOPT, expand, warm start'
