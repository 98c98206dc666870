# SPDX-License-Identifier: Apache-2.0
"""BARN world 283's recorded pocket: the robot backs out along its trail, then reaches the goal.

The state comes from a run through the nodes on the MuJoCo Jackal (data/barn_283_pocket.json:
the pose the robot stood at, facing the pocket's closed end, and the poses of the way there).
It is resumed in process (`run_navigation`'s lead_in: the laser's view from those poses and
the trail) on the kinematic plant at the `real` preset, with the controller set up as
config/jackal.yaml sets it for a real base. From there the paper's MPC alone stands still
(every solve infeasible or refused) until the stall rule ends the run, 20 s later (measured
when this test was written: docs/results.md, "Recoveries"). The test runs it with the
recoveries, as the node runs them, and checks what they are for: the robot stands for
``stuck_timeout``, backs out along the trail until a turn in place is possible, and is then
driven to the goal, with no contact.

The rest of the run after the first recovery is not pinned: it differs with the last digits
of the solver's arithmetic (compiled or not, another CPU), while what the test asserts held
on every variant tried (the state as recorded and moved by 1e-6, compiled and interpreted).
"""

from __future__ import annotations

from dataclasses import replace
import json
from pathlib import Path

import numpy as np
import pytest

from mpc_local_planner.core.recoveries import RecoveryKind, RecoverySettings
from mpc_local_planner.evaluation import sensing_suites as suites
from mpc_local_planner.evaluation.rollout import Outcome
from mpc_local_planner.worlds.data_files import BARN_DIR

POCKET = Path(__file__).parent / 'data' / 'barn_283_pocket.json'
JACKAL = suites.ROBOTS['jackal']


# About 1,100 control steps of the interpreted MPC (no gcc wait on a fresh machine): about a
# minute on an idle 2-core machine, three on a loaded one; the suite's 180 s is for hangs.
@pytest.mark.timeout(600)
def test_world_283s_recorded_pocket_backs_out_along_the_trail_and_reaches_the_goal() -> None:
    record = json.loads(POCKET.read_text())
    lead_in, x = np.array(record['lead_in']), np.array(record['x'])
    world = replace(suites.barn_sensing_world(BARN_DIR / 'world_283.json', JACKAL), start=x)
    result = suites.run_navigation(world, 'proposed', JACKAL, reality='real', recoveries=True,
                                   lead_in=lead_in, prepare=False,
                                   setup=suites.MpcSetup(compile=False))
    run, recoveries = result.run, result.navigator.recoveries
    assert recoveries is not None and recoveries.log
    stuck_timeout = RecoverySettings().stuck_timeout
    first = recoveries.log[0]
    # the MPC alone stood in the pocket: no recovery before stuck_timeout, none needed later
    t = run.rows[:, 0]
    standing = run.rows[t < first.start - 1e-9, 1:3]
    assert np.max(np.hypot(*(standing - x[:2]).T)) < recoveries.settings.progress_radius
    assert abs(first.start - stuck_timeout) < 0.2
    # the first recovery backs out along the trail, and ends where a turn is possible
    assert first.kind is RecoveryKind.BACK_OUT
    assert first.distance >= 0.1
    assert first.ended == 'a turn in place is possible'
    backing = run.rows[(t >= first.start) & (t <= first.end)]
    assert np.all(backing[:, 4] <= 1e-9)  # (v, omega) columns: never forward while backing
    # then the MPC drives it out of the pocket to the goal, with no contact
    assert run.outcome is Outcome.REACHED
    assert result.contacts == 0 and result.min_clearance > 0.0
    with pytest.raises(ValueError, match='before the first step'):
        result.navigator.lead_in(lead_in)


@pytest.mark.parametrize(('rows', 'match'), [
    (np.zeros((3, 3)), r'\[t, x, y, theta\]'),
    (np.array([[-1.0, 0.0, 0.0, 0.0], [np.nan, 0.0, 0.0, 0.0]]), 'finite'),
    (np.array([[-1.0, 0.0, 0.0, 0.0], [-1.0, 0.1, 0.0, 0.0]]), 'increase'),
    (np.array([[-0.2, 0.0, 0.0, 0.0], [0.0, 0.1, 0.0, 0.0]]), 'before the start'),
])
def test_a_malformed_lead_in_is_refused_before_the_run(rows: np.ndarray, match: str) -> None:
    world = suites.barn_sensing_world(BARN_DIR / 'world_283.json', JACKAL)
    with pytest.raises(ValueError, match=match):
        suites.run_navigation(world, 'pure_pursuit', JACKAL, prepare=False, lead_in=rows)
