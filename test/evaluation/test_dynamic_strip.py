# SPDX-License-Identifier: Apache-2.0
"""The dynamic suite's strip of frames: instants, the rows drawn at them, bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.evaluation.dynamic_strip import frame_times, plot_dynamic_strip, row_at
from mpc_local_planner.evaluation.dynamic_worlds import dynamic_world
from mpc_local_planner.evaluation.rollout import Outcome, Rollout
from mpc_local_planner.evaluation.trajectory import TRAJECTORY_COLUMNS


def straight_run(seconds: float, outcome: Outcome, h: float = 0.2) -> Rollout:
    """A robot driving along y = 0 at 1 m/s for seconds."""
    t = np.arange(0.0, seconds + 1e-9, h)
    rows = np.zeros((len(t), len(TRAJECTORY_COLUMNS)))
    rows[:, 0], rows[:, 1] = t, t
    return Rollout(outcome=outcome, rows=rows, steps=(), step_times=np.zeros(0), h=h)


def test_frames_span_the_longest_run_and_a_run_that_ended_stays_where_it_ended(
        tmp_path: Path) -> None:
    short, long = straight_run(4.0, Outcome.COLLISION), straight_run(10.0, Outcome.REACHED)
    times = frame_times([short, long], 6)
    assert times[0] == 0.0 and times[-1] == pytest.approx(10.0) and len(times) == 6
    assert row_at(long, 3.1)[0] == pytest.approx(3.0)  # the last row at or before t
    assert np.array_equal(row_at(short, 7.0), short.rows[-1])  # ended: its last pose
    world = dynamic_world(3, 0, footprint=JACKAL)
    target = plot_dynamic_strip(tmp_path / 'strip.png', world,
                                [('short', short), ('long', long)], footprint=JACKAL)
    assert target.is_file() and target.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_a_strip_without_runs_or_rows_is_refused() -> None:
    with pytest.raises(ValueError, match='runs with rows'):
        frame_times([])
    empty = Rollout(outcome=Outcome.STOPPED, rows=np.zeros((0, len(TRAJECTORY_COLUMNS))),
                    steps=(), step_times=np.zeros(0), h=0.2)
    with pytest.raises(ValueError, match='runs with rows'):
        frame_times([empty])
    with pytest.raises(ValueError, match='at least one frame'):
        frame_times([straight_run(1.0, Outcome.REACHED)], 0)
