# SPDX-License-Identifier: Apache-2.0
"""Moving obstacles in world files: each trajectory at chosen times, malformed ones refused."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mpc_local_planner.core.errors import WorldError
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.worlds.world import Circle, load_world, World, world_from_dict

WORLDS = Path(__file__).resolve().parents[2] / 'config' / 'worlds'
BASE = {'bounds': [0.0, 10.0, 0.0, 4.0], 'start': [0.5, 2.0, 0.0], 'goal': [9.5, 2.0, 0.0]}


def moving_world(*entries: dict[str, Any]) -> World:
    return world_from_dict({**BASE, 'moving_obstacles': list(entries)}, name='moving')


def test_constant_velocity_bounces_off_the_bounds_with_the_whole_shape_inside() -> None:
    world = moving_world({'circle': [0.0, 0.0, 0.5],
                          'constant_velocity': {'start': [5.0, 2.0], 'velocity': [1.0, 0.5]}})
    walker = world.moving_obstacles[0]
    # x runs in [0.5, 9.5] (the disk's radius from the bounds), y in [0.5, 3.5]
    assert walker.position(1.0).tolist() == [6.0, 2.5]
    assert walker.position(3.5).tolist() == [8.5, 3.25]  # y turned at 3.5 at t = 3
    assert walker.velocity(3.5).tolist() == [1.0, -0.5]
    assert walker.position(4.5).tolist() == [9.5, 2.75]  # x touches the right bound now
    assert walker.velocity(5.0).tolist() == [-1.0, -0.5]
    assert walker.position(22.5).tolist() == pytest.approx([9.5, 1.25])  # one lap later
    assert walker.shape_at(4.5) == Circle(9.5, 2.75, 0.5)


def test_constant_velocity_bounces_in_its_own_box_when_given() -> None:
    world = moving_world({'polygon': [[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]],
                          'constant_velocity': {'start': [3.0, 2.0], 'velocity': [-1.0, 0.0],
                                                'bounds': [1.5, 4.5, 0.0, 4.0]}})
    walker = world.moving_obstacles[0]
    assert walker.position(1.0).tolist() == [2.0, 2.0]  # its left side on x = 1.5
    assert walker.position(2.0).tolist() == [3.0, 2.0]
    assert walker.position(4.0).tolist() == [3.0, 2.0]  # 4.0 = x's highest, then back
    polygon = walker.shape_at(1.0)
    assert isinstance(polygon, ConvexPolygon)
    assert polygon.vertices.min(axis=0).tolist() == [1.5, 1.5]
    assert bool(polygon.contains(np.array([1.6, 2.0]))[0])


def test_waypoints_back_and_forth_turn_around_at_the_last_point() -> None:
    world = moving_world({'circle': [0.0, 0.0, 0.2],
                          'waypoints': {'points': [[2.0, 1.0], [4.0, 1.0], [4.0, 3.0]],
                                        'speed': [1.0, 2.0], 'mode': 'back_and_forth'}})
    walker = world.moving_obstacles[0]
    assert walker.position(1.0).tolist() == [3.0, 1.0]
    assert walker.position(2.5).tolist() == [4.0, 2.0]  # the second segment at 2 m/s
    assert walker.position(3.0).tolist() == [4.0, 3.0]  # the turn-around
    assert walker.velocity(3.5).tolist() == [0.0, -2.0]  # coming back at the same speed
    assert walker.position(4.5).tolist() == [3.5, 1.0]
    assert walker.position(6.0).tolist() == [2.0, 1.0]  # home after one lap of 6 s
    assert walker.position(7.0).tolist() == walker.position(1.0).tolist()


def test_waypoints_loop_back_to_the_first_point() -> None:
    world = moving_world({'circle': [0.0, 0.0, 0.2],
                          'waypoints': {'points': [[2.0, 1.0], [4.0, 1.0], [4.0, 3.0]],
                                        'speed': 1.0}})
    walker = world.moving_obstacles[0]
    lap = 2.0 + 2.0 + np.hypot(2.0, 2.0)
    assert walker.position(4.0 + np.hypot(1.0, 1.0)).tolist() == pytest.approx([3.0, 2.0])
    assert walker.position(lap + 1.0).tolist() == pytest.approx([3.0, 1.0])


def test_a_sinusoid_swings_about_its_centre() -> None:
    world = moving_world({'circle': [0.0, 0.0, 0.3],
                          'sinusoid': {'centre': [6.0, 2.0], 'amplitude': [0.0, 1.5],
                                       'period': 4.0, 'phase': 0.0}})
    walker = world.moving_obstacles[0]
    assert walker.position(0.0).tolist() == [6.0, 2.0]
    assert walker.position(1.0).tolist() == pytest.approx([6.0, 3.5])
    assert walker.position(3.0).tolist() == pytest.approx([6.0, 0.5])
    assert walker.velocity(0.0).tolist() == pytest.approx([0.0, 1.5 * 2.0 * np.pi / 4.0])


def test_positions_are_a_function_of_the_time_alone() -> None:
    world = moving_world({'circle': [0.0, 0.0, 0.5],
                          'constant_velocity': {'start': [5.0, 2.0], 'velocity': [0.7, 0.3]}})
    walker = world.moving_obstacles[0]
    t = 0.0
    for _ in range(1000):  # whatever path led to t, the answer is the same
        t += 0.01
    again = [walker.position(t) for _ in range(3)]
    assert all(a.tolist() == again[0].tolist() for a in again)


def test_shapes_at_adds_the_moving_ones_to_the_static_shapes() -> None:
    world = world_from_dict({**BASE, 'obstacles': [{'box': [7.0, 0.0, 8.0, 1.0]}],
                             'moving_obstacles': [
                                 {'circle': [0.0, 0.0, 0.3],
                                  'sinusoid': {'centre': [5.0, 2.0], 'amplitude': [1.0, 0.0],
                                               'period': 4.0}}]}, name='w')
    assert len(world.physical_shapes()) == 1  # the static ones only
    assert world.shapes_at(1.0)[1] == Circle(6.0, 2.0, 0.3)


@pytest.mark.parametrize(('entry', 'problem'), [
    ({'circle': [0, 0, 0.3]}, r'moving_obstacles\[0\] needs exactly one trajectory'),
    ({'velocity': [1, 0]}, r'moving_obstacles\[0\]: unknown key'),
    ({'circle': [0, 0, 0.3], 'polygon': [[0, 0], [1, 0], [0, 1]],
      'sinusoid': {'centre': [5, 2], 'amplitude': [1, 0], 'period': 2}},
     'exactly one shape'),
    ({'circle': [0, 0, -0.3], 'sinusoid': {'centre': [5, 2], 'amplitude': [1, 0],
                                           'period': 2}},
     r'moving_obstacles\[0\]\.circle: circle needs radius > 0'),
    ({'circle': [0, 0, 0.3], 'sinusoid': {'centre': [5, 2], 'amplitude': [1, 0],
                                          'period': 0}},
     'sinusoid.period must be > 0'),
    ({'circle': [0, 0, 0.3], 'sinusoid': {'centre': [5, 2], 'amplitude': [1, 0]}},
     "sinusoid: missing required key 'period'"),
    ({'circle': [0, 0, 0.3], 'sinusoid': {'centre': [5, 2], 'amplitude': [1, 0],
                                          'period': 2, 'frequency': 1}},
     r"sinusoid: unknown key\(s\) \['frequency'\]"),
    ({'circle': [0, 0, 0.3], 'waypoints': {'points': [[1, 1], [1, 1]], 'speed': 1}},
     r'waypoints.points\[0\] and \[1\] are the same point'),
    ({'circle': [0, 0, 0.3], 'waypoints': {'points': [[1, 1], [2, 1], [1, 1]], 'speed': 1}},
     'a loop closes itself'),
    ({'circle': [0, 0, 0.3], 'waypoints': {'points': [[1, 1], [2, 1]], 'speed': 0}},
     'waypoints.speed must be > 0'),
    ({'circle': [0, 0, 0.3], 'waypoints': {'points': [[1, 1], [2, 1]], 'speed': [1, 1, 1],
                                           'mode': 'back_and_forth'}},
     'one speed per segment'),
    ({'circle': [0, 0, 0.3], 'waypoints': {'points': [[1, 1], [2, 1]], 'speed': 1,
                                           'mode': 'ping_pong'}},
     'waypoints.mode must be one of loop, back_and_forth'),
    ({'circle': [0, 0, 0.5], 'constant_velocity': {'start': [0.2, 2], 'velocity': [1, 0]}},
     'must lie inside the box it bounces in'),
    ({'circle': [0, 0, 0.5], 'constant_velocity': {'start': [5, 2], 'velocity': [1, 'x']}},
     r'constant_velocity.velocity\[1\] must be a finite number'),
    ({'circle': [0, 0, 0.3], 'sinusoid': {'centre': [0.5, 2], 'amplitude': [1, 0],
                                          'period': 2}},
     r'start \(0.5, 2\) is inside moving obstacle 0 at t = 0'),
])
def test_a_malformed_moving_obstacle_is_refused_naming_the_entry(entry: dict[str, Any],
                                                                 problem: str) -> None:
    with pytest.raises(WorldError, match=problem):
        moving_world(entry)


def test_moving_obstacles_must_be_a_list() -> None:
    with pytest.raises(WorldError, match='moving_obstacles must be a list'):
        world_from_dict({**BASE, 'moving_obstacles': {'circle': [0, 0, 1]}}, name='w')


def test_the_shipped_crossing_world_has_a_walker_across_the_route() -> None:
    world = load_world(WORLDS / 'moving_crossing.yaml')
    assert len(world.moving_obstacles) == 2 and len(world.obstacles) == 2
    route_y = world.start[1]
    ys = [world.moving_obstacles[0].position(t)[1] for t in np.linspace(0.0, 20.0, 201)]
    assert min(ys) < route_y < max(ys)
