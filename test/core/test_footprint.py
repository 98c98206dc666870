# SPDX-License-Identifier: Apache-2.0
import math

import numpy as np
import pytest

from mpc_local_planner.core.footprint import (
    Footprint,
    FROM_WORLD,
    JACKAL,
    parse_footprint,
    resolve,
)


def test_nav2_string_form_gives_a_counter_clockwise_polygon_and_its_circumscribed_radius() -> None:
    footprint = parse_footprint('[[0.254, 0.215], [0.254, -0.215], [-0.254, -0.215], '
                                '[-0.254, 0.215]]')
    assert not footprint.is_circle
    area2 = np.sum(footprint.vertices[:, 0] * np.roll(footprint.vertices[:, 1], -1)
                   - np.roll(footprint.vertices[:, 0], -1) * footprint.vertices[:, 1])
    assert area2 > 0  # counter-clockwise although given clockwise
    assert footprint.radius == pytest.approx(math.hypot(0.254, 0.215))
    assert JACKAL.radius == pytest.approx(0.3328, abs=1e-4)


@pytest.mark.parametrize('text', ['', '[]', None])
def test_no_polygon_means_a_round_robot_of_robot_radius(text: str | None) -> None:
    footprint = parse_footprint(text, robot_radius=0.2)
    assert footprint.is_circle and footprint.radius == 0.2


@pytest.mark.parametrize(('vertices', 'match'), [
    ([[0, 0], [1, 0]], 'at least 3'),
    ([[0, 0], [1, 0], [2, 0]], 'collinear'),
    ([[0, 0], [1, 0], [1, 0], [0, 1]], 'repeated'),
    ([[0, 0], [2, 0], [1, 0.2], [2, 1], [0, 1]], 'not convex'),
    ([[0, 0], [1, 0], [0, float('nan')]], 'finite'),
    ([[math.cos(a), math.sin(a)] for a in np.arange(5) * 4 * math.pi / 5], 'crosses itself'),
])
def test_non_convex_or_degenerate_polygons_are_refused(vertices: list, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Footprint.polygon(vertices)


@pytest.mark.parametrize('text', ['[[0, 0], [1, 0]', 'footprint', '[[0, "a"], [1, 0], [0, 1]]'])
def test_malformed_strings_are_refused_with_the_expected_form(text: str) -> None:
    with pytest.raises(ValueError):
        parse_footprint(text)


def test_a_negative_radius_is_refused() -> None:
    with pytest.raises(ValueError, match='>= 0'):
        Footprint.circle(-0.1)


def test_the_polygon_at_a_pose_is_rotated_then_translated() -> None:
    corners = JACKAL.at([1.0, 2.0, math.pi / 2])
    # the front-left corner (0.254, 0.215) turns to (-0.215, 0.254)
    assert np.any(np.all(np.isclose(corners, [1.0 - 0.215, 2.0 + 0.254]), axis=1))
    circle = Footprint.circle(0.2).at([0.0, 0.0, 0.0])
    assert np.all(np.linalg.norm(circle, axis=1) >= 0.2)


def test_the_body_is_the_polygon_as_unit_half_planes_in_the_robot_frame() -> None:
    body = JACKAL.body
    np.testing.assert_allclose(np.linalg.norm(body.A, axis=1), 1.0)
    # the origin is 0.254 from the front and back faces and 0.215 from the sides
    np.testing.assert_allclose(np.sort(body.b), [0.215, 0.215, 0.254, 0.254])
    assert np.all(body.contains(JACKAL.vertices, margin=1e-12))
    assert not body.contains(np.array([[0.26, 0.0]]))[0]
    with pytest.raises(ValueError, match='no faces'):
        _ = Footprint.circle(0.2).body


def test_the_polygon_at_many_poses_matches_one_pose_at_a_time() -> None:
    poses = np.array([[1.0, 2.0, 0.3], [-1.0, 0.5, -2.0], [0.0, 0.0, math.pi]])
    corners = JACKAL.at_poses(poses)
    assert corners.shape == (3, 4, 2)
    for pose, expected in zip(poses, corners, strict=True):
        np.testing.assert_allclose(JACKAL.at(pose), expected, atol=1e-12)
    # extra state columns (a bicycle's steering angle) are ignored
    np.testing.assert_allclose(JACKAL.at_poses(np.column_stack([poses, np.ones(3)])), corners)


def test_contains_says_which_robot_frame_points_are_within_the_footprint_grown_by_margin(
        ) -> None:
    circle = Footprint.circle(0.2)
    points = np.array([[0.0, 0.0], [0.2, 0.0], [0.0, -0.2005], [0.15, 0.15], [0.21, 0.0]])
    assert circle.contains(points).tolist() == [True, True, False, False, False]
    assert circle.contains(points, margin=1e-3).tolist() == [True, True, True, False, False]
    # the Jackal: 0.254 to the front and back faces, 0.215 to the sides
    points = np.array([[0.254, 0.0], [0.2545, 0.0], [-0.2, 0.214], [0.0, -0.2155],
                       [0.3, 0.3]])
    assert JACKAL.contains(points).tolist() == [True, False, True, False, False]
    assert JACKAL.contains(points, margin=1e-3).tolist() == [True, True, True, True, False]
    assert JACKAL.contains(np.array([0.0, 0.0])).tolist() == [True]  # one point, (2,)


def test_the_footprint_in_force_follows_nav2s_precedence():
    square = '[[0.2, 0.2], [-0.2, 0.2], [-0.2, -0.2], [0.2, -0.2]]'
    world = Footprint.polygon([[0.3, 0.1], [-0.3, 0.1], [-0.3, -0.1], [0.3, -0.1]])
    # 1. the parameter's polygon wins over the world's polygon and any radius
    assert np.allclose(resolve(square, 1.0, world, 2.0).vertices,
                       parse_footprint(square).vertices)
    # 2. else the world's polygon, whatever the radii
    assert resolve('', 1.0, world, 2.0) is world
    # 3. else a circle of robot_radius, smaller than the world's too; -1: the world's
    assert resolve('', 0.3, Footprint.circle(0.1), 0.2).radius == pytest.approx(0.3)
    assert resolve('', 0.1, None, 0.25).radius == pytest.approx(0.1)
    assert resolve('', 0.0, None, 0.25).radius == 0.0
    assert resolve('', FROM_WORLD, None, 0.25).radius == pytest.approx(0.25)
    assert resolve('', world_radius=0.25).radius == pytest.approx(0.25)  # the default
    with pytest.raises(ValueError, match='footprint'):
        resolve('[[0, 0], [1, 0]]')
