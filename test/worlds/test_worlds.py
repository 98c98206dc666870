# SPDX-License-Identifier: Apache-2.0
"""Tests of world loading: the shipped worlds, BARN JSON, and every malformed input."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from mpc_local_planner.core.errors import WorldError
from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.core.obstacles import ConvexPolygon, min_clearance
from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.sim.contact import contact
from mpc_local_planner.worlds.data_files import BARN_DIR
from mpc_local_planner.worlds.world import (
    BARN_ROBOT_RADIUS,
    Circle,
    load_barn_world,
    load_world,
    paper_world,
    World,
    world_from_dict,
)

ROOT = Path(__file__).resolve().parents[2]
WORLDS = ROOT / 'config' / 'worlds'
BARN = BARN_DIR
PAPER_HEADING = math.atan(1.1 * math.pi / 2.5)


def valid_world() -> dict[str, Any]:
    return {
        'bounds': [0.0, 4.0, 0.0, 3.0],
        'obstacles': [
            {'box': [1.0, 1.0, 2.0, 2.0]},
            {'polygon': [[2.5, 0.5], [3.0, 0.5], [2.75, 1.0]]},
            {'circle': [3.0, 2.5, 0.2]},
        ],
        'start': [0.5, 0.5, 0.0],
        'goal': [3.5, 1.5, 1.0],
    }


def write_yaml(tmp_path: Path, data: Any, name: str = 'world.yaml') -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


@pytest.mark.parametrize('name', ['paper_obstacle', 'corridor_turn', 'rrt_cluttered',
                                  'unknown_box', 'narrow_gap', 'moving_crossing'])
def test_every_shipped_world_loads_with_start_and_goal_in_free_space(name: str) -> None:
    world = load_world(WORLDS / f'{name}.yaml')

    assert world.name == name
    assert world.start.shape == (3,) and world.goal.shape == (3,)
    assert world.in_bounds(world.start) and world.in_bounds(world.goal)
    inflated = world.inflated_obstacles()
    assert min_clearance(inflated, world.start[:2]) > 0.0
    assert min_clearance(inflated, world.goal[:2]) > 0.0


def test_paper_world_matches_its_yaml_file_and_the_papers_numbers() -> None:
    from_code = paper_world()
    from_file = load_world(WORLDS / 'paper_obstacle.yaml')

    for world in (from_code, from_file):
        assert world.bounds == (-0.5, 3.0, -1.5, 1.8)
        assert world.path == 'paper_sinusoid'
        assert world.robot_radius == 0.0
        np.testing.assert_allclose(world.start, [0.0, 0.0, PAPER_HEADING], atol=1e-12)
        np.testing.assert_allclose(world.goal, [2.5, 0.0, -PAPER_HEADING], atol=1e-12)
        assert len(world.obstacles) == 1
        box = world.obstacles[0]
        np.testing.assert_allclose(box.vertices.min(axis=0), [1.0, -1.0])
        np.testing.assert_allclose(box.vertices.max(axis=0), [1.5, 1.0])
    np.testing.assert_allclose(from_code.obstacles[0].A, from_file.obstacles[0].A)
    np.testing.assert_allclose(from_code.obstacles[0].b, from_file.obstacles[0].b)


def test_corridor_turn_world_is_empty_and_ends_heading_north() -> None:
    world = load_world(WORLDS / 'corridor_turn.yaml')

    assert world.obstacles == ()
    np.testing.assert_allclose(world.start, [0.0, 0.0, 0.0])
    np.testing.assert_allclose(world.goal, [2.0, 2.0, math.pi / 2])
    assert world.bounds == (-1.0, 3.0, -1.0, 3.0)


def test_rrt_cluttered_world_blocks_the_straight_line_but_leaves_half_metre_gaps() -> None:
    world = load_world(WORLDS / 'rrt_cluttered.yaml')

    assert 5 <= len(world.obstacles) <= 7
    assert world.robot_radius == pytest.approx(0.1)
    line = np.linspace(world.start[:2], world.goal[:2], 200)
    assert min_clearance(world.obstacles, line) == 0.0
    for i, first in enumerate(world.obstacles):
        for second in world.obstacles[i + 1 :]:
            gap = min(
                min_clearance([first], second.vertices), min_clearance([second], first.vertices)
            )
            assert gap >= 0.5


def test_narrow_gap_lets_the_jackal_through_straight_but_not_its_circumscribed_circle() -> None:
    world = load_world(WORLDS / 'narrow_gap.yaml')
    lower, upper = sorted(world.obstacles, key=lambda o: o.vertices[:, 1].min())
    (x0, y0), (x1, y1) = lower.vertices.min(axis=0), lower.vertices.max(axis=0)
    (u0, v0), (u1, v1) = upper.vertices.min(axis=0), upper.vertices.max(axis=0)
    # one wall (same x range) from the bottom bound to the top bound, open between y1 and v0
    assert (x0, x1) == (u0, u1)
    assert y0 == world.bounds[2] and v1 == world.bounds[3]
    assert v0 - y1 == pytest.approx(0.60)
    assert world.start[0] < x0 and world.goal[0] > x1  # start on one side, goal on the other
    assert 2.0 <= world.goal[0] - world.start[0] <= 6.0
    np.testing.assert_allclose(world.footprint.vertices, JACKAL.vertices)
    assert world.robot_radius == pytest.approx(0.3328, abs=1e-4) == JACKAL.radius

    geometry = TrueGeometry.from_world(world)
    centre = ((x0 + x1) / 2, (y1 + v0) / 2)
    assert not contact(geometry, *centre, world.footprint, 0.0)  # heading through the gap
    assert contact(geometry, *centre, world.robot_radius)  # the circumscribed circle touches
    assert contact(geometry, *centre, world.footprint, math.pi / 4)  # its diagonal does not
    # driving straight from start to goal touches nothing, and the footprint is free at both
    line = np.linspace(world.start, world.goal, 400)
    assert not any(contact(geometry, x, y, world.footprint, theta) for x, y, theta in line)


def test_yaml_world_footprint_is_a_polygon_in_either_form_and_empty_means_the_circle(
        tmp_path: Path) -> None:
    jackal = JACKAL.vertices.tolist()
    as_list = load_world(write_yaml(tmp_path, valid_world() | {'footprint': jackal}))
    as_string = world_from_dict(valid_world() | {'footprint': str(jackal)}, name='nav2')
    clockwise = world_from_dict(valid_world() | {'footprint': jackal[::-1]}, name='cw')

    for world in (as_list, as_string, clockwise):
        np.testing.assert_allclose(world.footprint.vertices, JACKAL.vertices)
        assert world.robot_radius == JACKAL.radius  # the covering disk, derived
    for empty in ([], '', '[]'):
        world = world_from_dict(valid_world() | {'footprint': empty, 'robot_radius': 0.15},
                                name='round')
        assert world.footprint == Footprint.circle(0.15) and world.robot_radius == 0.15
    # no footprint at all: the circle of robot_radius (0 by default)
    assert world_from_dict(valid_world(), name='plain').footprint == Footprint.circle(0.0)


@pytest.mark.parametrize(('footprint', 'match'), [
    ([[0.2, 0.1], [-0.2, 0.1]], r'footprint: .*at least 3'),
    ([[0.2, 0.1], [0.0, 0.0], [-0.2, 0.1], [0.0, -0.3]], 'footprint: .*not convex'),
    ([[0.2, 0.1], [True, 0.1], [0.0, -0.2]], r'footprint\[1\]\[0\] must be a number'),
    ([[0.2, 0.1], [-0.2], [0.0, -0.2]], r'footprint\[1\] must be a list of 2'),
    ('[[0.2, 0.1], [-0.2, 0.1]', 'footprint: .*not of the form'),
    ('0.3', 'footprint: .*not of the form'),
    (0.3, 'footprint must be a list of'),
])
def test_malformed_footprint_raises_world_error_naming_it(tmp_path: Path, footprint: Any,
                                                         match: str) -> None:
    path = write_yaml(tmp_path, valid_world() | {'footprint': footprint}, 'bad_robot.yaml')

    with pytest.raises(WorldError, match=match) as info:
        load_world(path)

    assert 'bad_robot.yaml' in str(info.value)


def test_yaml_world_refuses_both_robot_radius_and_a_footprint() -> None:
    data = valid_world() | {'footprint': JACKAL.vertices.tolist(), 'robot_radius': 0.2}

    with pytest.raises(WorldError, match='either robot_radius .* or footprint'):
        world_from_dict(data, name='both')


def test_world_built_in_code_keeps_footprint_and_robot_radius_consistent() -> None:
    fields = {'name': 'code', 'bounds': (0.0, 1.0, 0.0, 1.0), 'obstacles': (),
              'start': np.zeros(3), 'goal': np.ones(3)}

    assert World(**fields, robot_radius=0.3).footprint == Footprint.circle(0.3)
    jackal = World(**fields, footprint=JACKAL)
    assert jackal.footprint is JACKAL and jackal.robot_radius == JACKAL.radius
    assert World(**fields, robot_radius=JACKAL.radius, footprint=JACKAL).footprint is JACKAL
    with pytest.raises(ValueError, match='robot_radius 0.2 contradicts the footprint'):
        World(**fields, robot_radius=0.2, footprint=JACKAL)
    with pytest.raises(ValueError, match='contradicts'):
        World(**fields, robot_radius=0.2, footprint=Footprint.circle(0.3))


def test_barn_world_takes_a_footprint_instead_of_the_default_radius() -> None:
    path = BARN / 'world_000.json'

    default = load_barn_world(path)
    assert default.footprint == Footprint.circle(BARN_ROBOT_RADIUS) == Footprint.circle(0.2)
    jackal = load_barn_world(path, footprint=JACKAL)
    assert jackal.footprint is JACKAL and jackal.robot_radius == JACKAL.radius
    assert len(jackal.true_shapes) == len(default.true_shapes)
    with pytest.raises(WorldError, match='either robot_radius or footprint'):
        load_barn_world(path, robot_radius=0.2, footprint=JACKAL)


def test_yaml_world_parses_boxes_polygons_circles_and_optional_fields(tmp_path: Path) -> None:
    data = valid_world() | {
        'robot_radius': 0.15,
        'path': 'paper_sinusoid',
        'goal_tolerance': 0.05,
        'time_limit': 30,
    }
    world = load_world(write_yaml(tmp_path, data, 'mixed.yml'))

    assert isinstance(world, World)
    assert world.name == 'mixed'
    assert len(world.obstacles) == 3
    assert world.obstacles[2].num_faces == 8  # circles become octagons
    assert world.obstacles[2].contains(np.array([3.0, 2.69]))[0]  # circumscribed: disk inside
    assert world.robot_radius == 0.15
    assert world.goal_tolerance == 0.05 and world.time_limit == 30.0
    assert world.path == 'paper_sinusoid'
    assert not world.start.flags.writeable


def test_world_from_dict_accepts_a_world_without_obstacles() -> None:
    data = valid_world()
    del data['obstacles']

    world = world_from_dict(data, name='open')

    assert world.obstacles == ()
    assert world.path is None and world.goal_tolerance is None and world.time_limit is None


def test_barn_world_becomes_octagons_with_heading_bounds_and_limits() -> None:
    path = BARN / 'world_000.json'
    raw = json.loads(path.read_text())
    world = load_world(path)

    assert world.name == 'world_000'
    assert len(world.obstacles) == len(raw['cylinders'])
    assert all(obstacle.num_faces == 8 for obstacle in world.obstacles)
    np.testing.assert_allclose(world.start, raw['start'])
    dx, dy = np.subtract(raw['goal'], raw['start'][:2])
    np.testing.assert_allclose(world.goal, [*raw['goal'], math.atan2(dy, dx)])
    assert world.goal_tolerance == raw['goal_tolerance']
    assert world.time_limit == raw['time_limit_s']
    assert world.robot_radius == 0.2
    centres = np.array(raw['cylinders'])
    r = raw['cylinder_radius']
    points = np.vstack([centres - r, centres + r, [raw['start'][:2]], [raw['goal']]])
    lo, hi = points.min(axis=0) - 1.0, points.max(axis=0) + 1.0
    np.testing.assert_allclose(world.bounds, [lo[0], hi[0], lo[1], hi[1]])
    # The octagon circumscribes each cylinder: points on the cylinder are inside it.
    angles = np.linspace(0, 2 * np.pi, 50)
    rim = centres[0] + r * np.column_stack([np.cos(angles), np.sin(angles)])
    assert world.obstacles[0].contains(rim, margin=1e-12).all()


def test_barn_world_keeps_the_exact_cylinders_as_true_shapes() -> None:
    world = load_barn_world(BARN / 'world_000.json')
    raw = json.loads((BARN / 'world_000.json').read_text())

    assert len(world.true_shapes) == len(raw['cylinders'])
    assert world.physical_shapes() == world.true_shapes
    assert world.true_shapes[0] == Circle(*raw['cylinders'][0], raw['cylinder_radius'])
    assert world.unknown_obstacles == ()


def test_unknown_obstacles_are_parsed_like_obstacles_but_kept_apart() -> None:
    data = valid_world() | {'unknown_obstacles': [{'box': [2.5, 2.0, 3.0, 2.5]},
                                                  {'circle': [0.5, 2.5, 0.2]}]}
    world = world_from_dict(data, name='hidden')

    assert len(world.obstacles) == 3 and len(world.unknown_obstacles) == 2
    assert world.unknown_obstacles[1].num_faces == 8
    shapes = world.physical_shapes()
    assert len(shapes) == 5
    assert shapes[2] == Circle(3.0, 2.5, 0.2) and shapes[4] == Circle(0.5, 2.5, 0.2)
    assert isinstance(shapes[3], ConvexPolygon)
    # Worlds without unknown obstacles (and worlds built in code) keep their behaviour.
    plain = world_from_dict(valid_world(), name='plain')
    assert plain.unknown_obstacles == ()
    assert len(plain.physical_shapes()) == 3


@pytest.mark.parametrize(('changes', 'match'), [
    ({'unknown_obstacles': {'box': [1, 1, 2, 2]}}, 'unknown_obstacles must be a list'),
    ({'unknown_obstacles': [{'cone': [1, 1]}]}, r'unknown_obstacles\[0\]: unknown obstacle kind'),
    ({'unknown_obstacles': [{'box': [0, 0, 1, 1]}]}, r'start \(0.5, 0.5\) is inside unknown'),
])
def test_malformed_unknown_obstacles_raise_world_error(changes: dict[str, Any],
                                                       match: str) -> None:
    with pytest.raises(WorldError, match=match):
        world_from_dict(valid_world() | changes, name='hidden')


def test_unknown_box_lies_on_the_route_planned_around_the_known_wall() -> None:
    world = load_world(WORLDS / 'unknown_box.yaml')
    (wall,) = world.obstacles
    (box,) = world.unknown_obstacles
    # The shortest route around the wall inflated by robot radius + 0.1 m clearance.
    grown = wall.inflate(world.robot_radius + 0.1)
    xmin, ymin = grown.vertices.min(axis=0)
    xmax, ymax = grown.vertices.max(axis=0)
    route = np.array([world.start[:2], [xmin, ymax], [xmax, ymax], world.goal[:2]])
    samples = np.vstack([np.linspace(a, b, 100) for a, b in zip(route[:-1], route[1:],
                                                                 strict=True)])

    assert min_clearance([grown], samples) >= -1e-9 and ymin < world.start[1]
    assert min_clearance([box], samples) <= 0.3
    assert min_clearance([wall], box.vertices) >= 0.5  # a way past both remains
    assert box.vertices[:, 1].max() + 2 * world.robot_radius + 0.2 < world.bounds[3]


def test_barn_loader_honours_robot_radius_and_sides() -> None:
    world = load_barn_world(BARN / 'world_001.json', robot_radius=0.3, sides=12)

    assert world.robot_radius == 0.3
    assert all(obstacle.num_faces == 12 for obstacle in world.obstacles)


def test_missing_world_file_raises_file_not_found(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match='nowhere.yaml'):
        load_world(tmp_path / 'nowhere.yaml')
    with pytest.raises(FileNotFoundError, match='nowhere.json'):
        load_barn_world(tmp_path / 'nowhere.json')


def test_unknown_suffix_raises_world_error(tmp_path: Path) -> None:
    path = tmp_path / 'world.txt'
    path.write_text('bounds: []')

    with pytest.raises(WorldError, match=r'world\.txt.*unknown world format'):
        load_world(path)


def test_invalid_yaml_raises_world_error_naming_the_file(tmp_path: Path) -> None:
    path = tmp_path / 'broken.yaml'
    path.write_text('bounds: [0, 1\nstart: {')

    with pytest.raises(WorldError, match=r'broken\.yaml.*not valid YAML'):
        load_world(path)


def mutate(**changes: Any) -> dict[str, Any]:
    data = valid_world()
    for key, value in changes.items():
        if value is KeyError:
            del data[key]
        else:
            data[key] = value
    return data


@pytest.mark.parametrize(
    ('data', 'match'),
    [
        (['not', 'a', 'mapping'], 'must be a mapping'),
        (mutate(bounds=KeyError), "missing required key 'bounds'"),
        (mutate(start=KeyError), "missing required key 'start'"),
        (mutate(goal=KeyError), "missing required key 'goal'"),
        (mutate(obstacle=[]), r"unknown key\(s\) \['obstacle'\]"),
        (mutate(bounds=[0.0, 4.0, 0.0]), 'bounds must be a list of 4 numbers'),
        (mutate(bounds=[4.0, 0.0, 0.0, 3.0]), 'min < max'),
        (mutate(bounds=[0.0, 4.0, 0.0, float('nan')]), r'bounds\[3\] must be finite'),
        (mutate(start=[0.5, 0.5]), 'start must be a list of 3 numbers'),
        (mutate(start=[0.5, 'x', 0.0]), r'start\[1\] must be a number'),
        (mutate(start=[0.5, True, 0.0]), r'start\[1\] must be a number'),
        (mutate(goal=[0.5, 0.5, float('inf')]), r'goal\[2\] must be finite'),
        (mutate(start=[-1.0, 0.5, 0.0]), r'start \(-1, 0.5\) is outside the bounds'),
        (mutate(goal=[3.5, 9.0, 0.0]), r'goal \(3.5, 9\) is outside the bounds'),
        (mutate(goal=[1.5, 1.5, 0.0]), r'goal \(1.5, 1.5\) is inside obstacle 0'),
        (mutate(obstacles={'box': [1, 1, 2, 2]}), 'obstacles must be a list'),
        (mutate(obstacles=[{'cone': [1, 1, 1]}]), "unknown obstacle kind 'cone'"),
        (mutate(obstacles=[{'box': [1, 1, 2, 2], 'circle': [1, 1, 1]}]), 'exactly one key'),
        (mutate(obstacles=[{'box': [1, 1, 2]}]), r'obstacles\[0\] must be a list of 4'),
        (mutate(obstacles=[{'box': [2, 2, 1, 1]}]), r'obstacles\[0\]: box needs xmin < xmax'),
        (mutate(obstacles=[{'circle': [1, 1, -1]}]), r'obstacles\[0\]: circle needs radius'),
        (mutate(obstacles=[{'polygon': [[1, 1], [2, 2]]}]), 'needs a list of >= 3'),
        (mutate(obstacles=[{'polygon': [[1, 1], [2, 2], [3, 3]]}]), 'collinear'),
        (mutate(obstacles=[{'polygon': [[1, 1], [2], [3, 1]]}]), r'obstacles\[0\]\[1\]'),
        (mutate(robot_radius=-0.1), 'robot_radius must be >= 0'),
        (mutate(robot_radius='wide'), 'robot_radius must be a number'),
        (mutate(path=3), 'path must be the name of an analytic path'),
        (mutate(goal_tolerance=0.0), 'goal_tolerance must be > 0'),
        (mutate(time_limit=-5), 'time_limit must be > 0'),
    ],
)
def test_malformed_yaml_world_raises_world_error_naming_file_and_problem(
    tmp_path: Path, data: Any, match: str
) -> None:
    path = write_yaml(tmp_path, data, 'bad_world.yaml')

    with pytest.raises(WorldError, match=match) as info:
        load_world(path)

    assert 'bad_world.yaml' in str(info.value)


def test_world_error_is_a_value_error() -> None:
    with pytest.raises(ValueError, match='inline'):
        world_from_dict(mutate(start=KeyError), name='inline')


def write_barn(tmp_path: Path, **changes: Any) -> Path:
    data = json.loads((BARN / 'world_000.json').read_text())
    for key, value in changes.items():
        if value is KeyError:
            del data[key]
        else:
            data[key] = value
    path = tmp_path / 'barn_bad.json'
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    ('changes', 'match'),
    [
        ({'cylinders': KeyError}, "missing required key 'cylinders'"),
        ({'goal': KeyError}, "missing required key 'goal'"),
        ({'cylinder_radius': 0}, 'cylinder_radius must be > 0'),
        ({'cylinders': [[0.0, 1.0], [1.0]]}, r'cylinders\[1\] must be a list of 2'),
        ({'start': [0.0, 0.0]}, 'start must be a list of 3'),
        ({'goal': [0.0, 'far']}, r'goal\[1\] must be a number'),
        ({'start': [-0.075, 0.075, 0.0]}, 'start .* is inside obstacle 0'),
    ],
)
def test_malformed_barn_world_raises_world_error(
    tmp_path: Path, changes: dict[str, Any], match: str
) -> None:
    with pytest.raises(WorldError, match=match):
        load_world(write_barn(tmp_path, **changes))


def test_barn_file_that_is_not_json_raises_world_error(tmp_path: Path) -> None:
    path = tmp_path / 'garbage.json'
    path.write_text('{"cylinders": [')

    with pytest.raises(WorldError, match=r'garbage\.json.*not valid JSON'):
        load_world(path)
