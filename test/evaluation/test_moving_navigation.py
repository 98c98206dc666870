# SPDX-License-Identifier: Apache-2.0
"""The suites' navigation run in a world whose obstacles move (sensing_suites.run_navigation)."""

from __future__ import annotations

import numpy as np
import pytest

from mpc_local_planner.evaluation import sensing_suites as suites
from mpc_local_planner.evaluation.rollout import Outcome
from mpc_local_planner.sim.moving import ContactKind
from mpc_local_planner.worlds.world import World, world_from_dict

CIRCLE = suites.ROBOTS['circle']


def head_on_world() -> World:
    """A walker coming down an empty corridor towards the robot, along its route."""
    return world_from_dict({
        'bounds': [-0.5, 8.5, -1.5, 1.5], 'start': [0.0, 0.0, 0.0], 'goal': [8.0, 0.0, 0.0],
        'obstacles': [{'box': [-0.5, 1.2, 8.5, 1.5]}, {'box': [-0.5, -1.5, 8.5, -1.2]}],
        'moving_obstacles': [{'circle': [0.0, 0.0, 0.25],
                              'waypoints': {'points': [[7.0, 0.0], [1.0, 0.0]],
                                            'speed': 0.5, 'mode': 'back_and_forth'}}]},
        name='head_on')


def test_a_path_follower_meets_a_walker_head_on_where_the_walker_is_then() -> None:
    world = head_on_world()
    result = suites.run_navigation(world, 'pure_pursuit', CIRCLE, prepare=False)
    run = result.run
    assert run.outcome is Outcome.COLLISION and run.contact is ContactKind.ACTIVE
    assert (result.contacts, result.active_contacts, result.passive_contacts) == (1, 1, 0)
    fields = suites.result_fields(result)
    assert (fields['active_contacts'], fields['passive_contacts']) == (1, 0)
    # the contact is with the walker where it is at the last row's time, not where it started
    t, robot = run.rows[-1, 0], run.rows[-1, 1:3]
    walker = world.moving_obstacles[0].position(t)
    assert np.hypot(*(robot - walker)) <= CIRCLE.footprint.radius + 0.25 + 1e-9
    assert walker[0] < 7.0 - 0.5  # it had walked towards the robot
    earlier = world.moving_obstacles[0].position(t - 0.2)
    assert np.hypot(*(run.rows[-2, 1:3] - earlier)) > CIRCLE.footprint.radius + 0.25
    # the laser saw it on the way: the memory holds something near the walker's path
    sensed = [o for _, obstacles in result.navigator.log.sensed for o in obstacles
              if np.any(np.abs(o.vertices[:, 1]) < 0.5)]
    assert sensed


def test_a_moving_world_runs_the_same_twice() -> None:
    first = suites.run_navigation(head_on_world(), 'pure_pursuit', CIRCLE, prepare=False)
    again = suites.run_navigation(head_on_world(), 'pure_pursuit', CIRCLE, prepare=False)
    # every column but the last, the wall time of the solves
    assert np.array_equal(first.run.rows[:, :-1], again.run.rows[:, :-1], equal_nan=True)


def test_the_physics_robot_meets_the_walker_the_engine_moves() -> None:
    pytest.importorskip('mujoco', reason='the [physics] extra is not installed')
    world = head_on_world()
    result = suites.run_navigation(world, 'pure_pursuit', CIRCLE, prepare=False,
                                   plant='mujoco')
    run = result.run
    assert run.outcome is Outcome.COLLISION and run.contact is ContactKind.ACTIVE
    t, robot = run.rows[-1, 0], run.rows[-1, 1:3]
    walker = world.moving_obstacles[0].position(t)
    assert np.hypot(*(robot - walker)) <= CIRCLE.footprint.radius + 0.25 + 1e-9


def test_with_tracking_the_walker_is_a_moving_track_and_the_walls_are_not() -> None:
    """track_moving: the controller's memory follows the walker as a moving track.

    The corridor's walls are long clusters (structure, never tracked), so nothing but the
    walker is told moving; the run meets the walker as before (a path follower ignores
    obstacles), the same run, since the follower's command never depends on them.
    """
    plain = suites.run_navigation(head_on_world(), 'pure_pursuit', CIRCLE, prepare=False)
    tracked = suites.run_navigation(head_on_world(), 'pure_pursuit', CIRCLE, prepare=False,
                                    track_moving=True)
    assert np.array_equal(plain.run.rows[:, :-1], tracked.run.rows[:, :-1], equal_nan=True)
    tracker = tracked.navigator.memory.tracker
    assert tracker is not None and plain.navigator.memory.tracker is None
    moving = [t for t in tracker.tracker.tracks if t.moving]
    t = tracked.run.rows[-1, 0]
    walker = head_on_world().moving_obstacles[0]
    assert len(moving) == 1
    assert np.hypot(*(moving[0].position - walker.position(t))) < 0.4
    # coming towards the robot (at the contact the robot hides part of it: only the sign)
    assert moving[0].velocity[0] < -0.1
