# SPDX-License-Identifier: Apache-2.0
"""The dynamic suite's worlds: DynaBARN-like, reproducible, harder with the index, solvable."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.evaluation import evaluate
from mpc_local_planner.evaluation.dynamic_worlds import (
    dynamic_world,
    dynamic_world_data,
    DYNAMIC_WORLDS,
    MOVING_X,
    PROFILES,
)
from mpc_local_planner.worlds.motion import ConstantVelocity, Sinusoid, Waypoints
from mpc_local_planner.worlds.world import Circle, world_from_dict


def test_a_world_is_the_same_for_the_same_seed_and_another_for_another() -> None:
    assert dynamic_world_data(7, 0) == dynamic_world_data(7, 0)
    assert dynamic_world_data(7, 0) != dynamic_world_data(7, 1)
    assert dynamic_world_data(7, 0) != dynamic_world_data(8, 0)


def test_worlds_grow_harder_by_count_and_speed_and_use_every_profile() -> None:
    counts, tops, kinds = [], [], set()
    for index in range(DYNAMIC_WORLDS):
        world = world_from_dict(dynamic_world_data(index, 0), name='w')
        speeds = [float(np.max(np.hypot(*np.array(
            [m.velocity(t) for t in np.linspace(0.0, 30.0, 61)]).T)))
            for m in world.moving_obstacles]
        counts.append(len(world.moving_obstacles))
        tops.append(max(speeds))
        kinds |= {type(m.trajectory) for m in world.moving_obstacles}
        for m in world.moving_obstacles:
            assert isinstance(m.shape, Circle) and 0.15 <= m.shape.radius <= 0.5
        assert all(0.2 - 1e-9 <= s <= 1.5 + 1e-9 for s in speeds)
    assert counts[0] == 2 and counts[-1] == 8 and counts == sorted(counts)
    assert np.mean(tops[:20]) < np.mean(tops[-20:])
    assert kinds == {ConstantVelocity, Waypoints, Sinusoid} and len(PROFILES) == 3


@pytest.mark.parametrize('index', [0, 31, 59])
def test_moving_cylinders_keep_off_the_start_and_the_goal(index: int) -> None:
    world = dynamic_world(index, 0, footprint=JACKAL)
    assert world.footprint is JACKAL
    for t in np.arange(0.0, 60.0, 0.25):
        for m in world.moving_obstacles:
            shape = m.shape_at(float(t))
            assert MOVING_X[0] - 1e-9 <= shape.x - shape.radius
            assert shape.x + shape.radius <= MOVING_X[1] + 1e-9
            assert world.bounds[2] - 1e-9 <= shape.y - shape.radius
            assert shape.y + shape.radius <= world.bounds[3] + 1e-9
    assert not world.obstacles  # nothing is in the map: the laser finds it all
    assert len(world.unknown_obstacles) > 0


def test_a_negative_index_is_refused() -> None:
    with pytest.raises(ValueError, match='>= 0'):
        dynamic_world(-1, 0)


def test_evaluate_runs_the_dynamic_suite_and_splits_its_contacts(tmp_path: Path) -> None:
    assert evaluate.main(['--suite', 'dynamic', '--robot', 'jackal', '--count', '1',
                          '--controllers', 'regulated_pure_pursuit', '--out',
                          str(tmp_path)]) == 0
    with open(tmp_path / 'runs.csv', encoding='utf-8') as f:
        rows = list(csv.DictReader(f))
    assert [(r['world'], r['name'], r['sensing']) for r in rows] == [
        ('0', 'dynamic_000', 'True')]
    assert rows[0]['active_contacts'] in ('0', '1') and rows[0]['passive_contacts'] in ('0', '1')
    summary = (tmp_path / 'summary.md').read_text(encoding='utf-8')
    assert '# dynamic with sensing' in summary or '# dynamic' in summary
    assert 'Contacts (runs; active' in summary
