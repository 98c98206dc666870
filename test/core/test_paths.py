# SPDX-License-Identifier: Apache-2.0
"""Unit tests of reference paths: continuity, Lipschitz bound, symbolic form, projection."""

import casadi as ca
import numpy as np
import pytest

from mpc_local_planner.core.paths import (
    paper_sinusoid,
    Polyline,
    remaining_polyline,
    simplify_polyline,
    WaypointPath,
)


def _symbolic_values(path, s_values):
    s = ca.SX.sym('s')
    f = ca.Function('p', [s], [path.symbolic(s, ca.DM(path.parameters()))])
    return np.array([np.asarray(f(v)).ravel() for v in s_values])


def test_paper_path_starts_at_origin_and_ends_at_target() -> None:
    path = paper_sinusoid()
    np.testing.assert_allclose(path.start, [0.0, 0.0, np.arctan(1.1 * np.pi / 2.5)])
    np.testing.assert_allclose(path.goal, [2.5, 0.0, np.arctan(-1.1 * np.pi / 2.5)], atol=1e-12)


def test_paper_path_heading_is_the_tangent_direction() -> None:
    path = paper_sinusoid()
    s, poses = path.sample(2001)
    tangent = np.arctan2(np.gradient(poses[:, 1], s), np.gradient(poses[:, 0], s))
    np.testing.assert_allclose(poses[1:-1, 2], tangent[1:-1], atol=1e-5)


def test_corner_becomes_a_turn_in_place_with_continuous_unwrapped_heading() -> None:
    path = WaypointPath(np.array([[0, 0], [1, 0], [1, 1], [0, 1]]), start_heading=0.0)
    s, poses = path.sample(4001)
    steps = np.linalg.norm(np.diff(poses, axis=0), axis=1)
    assert np.max(steps) < 1e-2  # no jump anywhere, heading included
    assert poses[-1, 2] == pytest.approx(np.pi)  # unwrapped: two left turns, not -pi


def test_waypoint_path_is_lipschitz_with_the_bound_its_knots_imply() -> None:
    path = WaypointPath(np.array([[0, 0], [2, 0], [2, 2]]), start_heading=0.0,
                        goal_heading=np.pi / 2, turn_length=0.25)
    knots = path.knots
    total = 4.0 + 0.25 * (np.pi / 2)
    bound = total * max(1.0, 1 / 0.25)  # |dp/ds| <= L_total per metre or per turn_length
    assert path.lipschitz_estimate() <= bound * (1 + 1e-9)
    assert paper_sinusoid().lipschitz_estimate() < 6.0  # |p'(s)| <= 2.5 + 1.1 pi + heading
    assert len(knots) == 4


def test_waypoint_path_symbolic_form_equals_numeric_form() -> None:
    path = WaypointPath(np.array([[0, 0], [1, 0.5], [2, -0.5], [3, 0]]), start_heading=1.0,
                        goal_heading=-1.0, capacity=16)
    s_values = np.linspace(0, 1, 57)
    np.testing.assert_allclose(_symbolic_values(path, s_values), path.pose(s_values),
                               atol=1e-12)


def test_projection_finds_the_nearest_point_on_the_path() -> None:
    path = paper_sinusoid()
    s_true = 0.37
    pose = path.pose(s_true)
    assert path.project(pose) == pytest.approx(s_true, abs=1e-3)
    assert path.project(pose, s_min=0.5) == pytest.approx(0.5, abs=1e-3)


@pytest.mark.parametrize('waypoints, message', [
    (np.array([[0.0, 0.0]]), 'at least two distinct'),
    (np.array([[0.0, 0.0], [0.0, 0.0]]), 'at least two distinct'),
    (np.array([[0.0, 0.0], [np.nan, 1.0]]), 'NaN or inf'),
    (np.zeros((3, 3)), 'shape'),
])
def test_bad_waypoints_are_refused_with_a_reason(waypoints, message) -> None:
    with pytest.raises(ValueError, match=message):
        WaypointPath(waypoints)


def test_too_many_segments_are_refused_and_simplification_fixes_it() -> None:
    x = np.linspace(0, 10, 100_000)
    points = np.column_stack([x, 0.001 * np.sin(x)])
    with pytest.raises(ValueError, match='capacity'):
        WaypointPath(points, capacity=64)
    simple = simplify_polyline(points, 0.01)
    assert len(simple) < 10
    WaypointPath(simple, capacity=64)


def _distance_to_polyline(points, polyline):
    a, b = polyline[:-1], polyline[1:]
    ab = b - a
    t = np.clip(np.einsum('nkd,kd->nk', points[:, None] - a[None], ab)
                / np.maximum(np.sum(ab ** 2, axis=1), 1e-300), 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.min(np.linalg.norm(points[:, None] - closest, axis=2), axis=1)


def test_rounded_corners_keep_the_positions_on_the_polyline_and_the_ends_exact() -> None:
    waypoints = np.array([[0, 0], [1, 0], [1.2, 0.9], [0.1, 1.4], [0.1, 2.0]])
    path = WaypointPath(waypoints, start_heading=-1.0, goal_heading=3.0, smoothing=0.1)
    sharp = WaypointPath(waypoints, start_heading=-1.0, goal_heading=3.0, smoothing=1e-9)
    s, poses = path.sample(4001)
    assert np.max(_distance_to_polyline(poses[:, :2], waypoints)) < 1e-12
    np.testing.assert_allclose(path.start, [0.0, 0.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(path.goal[:2], [0.1, 2.0], atol=1e-12)
    assert path.goal[2] == pytest.approx(sharp.goal[2])
    # the same poses as the sharp polyline away from the knots; near them, within
    # smoothing / 4 of path parameter (position along the path, or turn_length * heading)
    away = np.min(np.abs(s[:, None] - sharp.s_knots[None, 1:-1]), axis=1) > 0.2
    np.testing.assert_allclose(poses[away], sharp.pose(s[away]), atol=1e-12)
    scale = np.array([1.0, 1.0, 0.25])
    assert np.max(np.abs(poses - sharp.pose(s)) * scale) <= 0.1 / 4 + 1e-12


def test_rounded_path_is_differentiable_at_its_knots() -> None:
    waypoints = np.array([[0, 0], [1, 0], [1, 1]])
    path = WaypointPath(waypoints, start_heading=0.0)
    sharp = WaypointPath(waypoints, start_heading=0.0, smoothing=1e-9)
    s = ca.SX.sym('s')
    slope = ca.Function('dp', [s], [ca.jacobian(path.symbolic(s, ca.DM(path.parameters())), s)])
    for knot in sharp.s_knots[1:-1]:  # straight -> turn in place, turn -> straight
        left, right = (np.asarray(slope(knot + d)).ravel() for d in (-1e-9, 1e-9))
        np.testing.assert_allclose(left, right, atol=1e-6)
        # the polyline itself has a kink there: its one-sided slopes differ
        jump = (sharp.pose(knot + 1e-4) - sharp.pose(knot)) - (sharp.pose(knot)
                                                              - sharp.pose(knot - 1e-4))
        assert np.max(np.abs(jump)) / 1e-4 > 1.0


@pytest.mark.parametrize('smoothing', [0.0, -0.1, float('nan')])
def test_bad_smoothing_is_refused(smoothing) -> None:
    with pytest.raises(ValueError, match='smoothing'):
        WaypointPath(np.array([[0, 0], [1, 0]]), smoothing=smoothing)


def test_a_polyline_drops_repeats_and_gives_points_by_arc_length_clipped_to_its_ends() -> None:
    line = Polyline(np.array([[0.0, 0.0], [0.0, 0.0], [3.0, 0.0], [3.0, 4.0]]))
    assert len(line.points) == 3 and line.length == pytest.approx(7.0)
    np.testing.assert_allclose(line.arc, [0.0, 3.0, 7.0])
    np.testing.assert_allclose(line.point_at(1.5), [1.5, 0.0])
    np.testing.assert_allclose(line.point_at(5.0), [3.0, 2.0])
    np.testing.assert_allclose(line.point_at(-1.0), [0.0, 0.0])
    np.testing.assert_allclose(line.point_at(9.0), [3.0, 4.0])
    with pytest.raises(ValueError, match='two distinct waypoints'):
        Polyline(np.array([[1.0, 1.0], [1.0, 1.0]]))


def test_the_remaining_plan_starts_at_the_projection_on_or_after_forward_from() -> None:
    # a plan out and back beside itself: at (1, 0.1) the nearest point is on the way back
    plan = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 0.2], [0.0, 0.2]])
    point = np.array([1.0, 0.11])
    nearest = remaining_polyline(plan, point)
    assert nearest.segment == 2
    np.testing.assert_allclose(nearest.points, [[1.0, 0.2], [0.0, 0.2]])
    # a controller still on the way out (its last projection on segment 0) keeps going
    # forward: forward_from limits the search to segments from there on, not before
    behind = remaining_polyline(plan, np.array([1.0, 0.09]), forward_from=0)
    assert behind.segment == 0
    np.testing.assert_allclose(behind.points, [[1.0, 0.0], *plan[1:]])
    ahead = remaining_polyline(plan, np.array([1.0, 0.09]), forward_from=2)
    assert ahead.segment == 2
    np.testing.assert_allclose(ahead.points, [[1.0, 0.2], [0.0, 0.2]])
    clipped = remaining_polyline(plan, np.array([-1.0, 0.0]), forward_from=99)
    assert clipped.segment == 2
    np.testing.assert_allclose(clipped.points, [[0.0, 0.2]] * 2)
    single = remaining_polyline(plan[:1], point)
    assert single.segment == 0
    np.testing.assert_array_equal(single.points, plan[:1])
