# SPDX-License-Identifier: Apache-2.0
"""mpc_bench's barn rows: recorded BARN states replayed through each controller, part by part."""

from __future__ import annotations

import math

import numpy as np

from mpc_local_planner.evaluation.bench_barn import (
    barn_figures,
    barn_lines,
    record_barn_run,
    replay_steps,
)

STEPS = 12


def test_the_replay_is_the_run_and_every_controller_is_timed_on_its_states() -> None:
    """The same states give the MPC's recorded commands again, part by part timed.

    That is what makes the rows the node's step on states a robot met, not a new run; a
    path follower replayed on them has no solver part.
    """
    robot, world, steps, outcome = record_barn_run(200)
    assert outcome.startswith('reached')
    assert steps[0].plan is not None  # the first plan comes at the first step
    assert sum(s.scan is not None for s in steps) == len(steps)  # ideal: a scan a step
    replays = {name: replay_steps(name, robot, world, steps[:STEPS])
               for name in ('proposed', 'regulated_pure_pursuit')}
    mpc = replays['proposed']
    assert mpc['differ'] == 0
    times = mpc['times']
    assert len(times['step']) == STEPS and len(times['solver']) == STEPS
    assert np.allclose(times['step'], np.add(times['perception'], times['controller']))
    assert all(0.0 < s <= c for s, c in zip(times['solver'], times['controller'], strict=True))
    assert len(mpc['iterations']) == STEPS and min(mpc['iterations']) >= 1

    result = barn_figures([{'world': 200, 'outcome': outcome, 'steps': STEPS,
                            'scans': STEPS}], [replays])
    assert result['same_commands'] is True
    rows = result['rows']
    assert all(math.isfinite(rows[name]['step']['median']) for name in rows)
    assert math.isnan(rows['regulated_pure_pursuit']['solver']['median'])
    assert result['solved_steps'] == {'proposed': STEPS, 'regulated_pure_pursuit': 0}
    text = '\n'.join(barn_lines(result))
    assert "the paper's MPC's step against issue 34's targets" in text
    assert "replayed MPC commands equal to the recorded run's: yes" in text
