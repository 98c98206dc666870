# SPDX-License-Identifier: Apache-2.0
"""Tests of scans to convex obstacles and of the obstacle memory."""

from __future__ import annotations

import math

from conftest import point_in_any
import numpy as np
import pytest

from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.core.obstacles import ConvexPolygon, min_clearance
from mpc_local_planner.perception.scan_obstacles import (
    cluster_bounds,
    ObstacleMemory,
    scan_to_obstacles,
)
from mpc_local_planner.perception.scans import (
    classify_beams,
    Scan,
    scan_points,
    ScanError,
    validate_scan,
)
from mpc_local_planner.sim.laser import SimulatedLaser

BOX = ConvexPolygon.from_box(2.0, -0.5, 2.6, 0.5)


def covered(obstacles: list[ConvexPolygon], points: np.ndarray, tol: float = 1e-6) -> bool:
    return bool(np.all(point_in_any(obstacles, points, margin=tol)))


def test_box_in_front_gives_obstacles_covering_its_visible_face_and_nothing_far_off() -> None:
    scan = SimulatedLaser([BOX]).scan((0.0, 0.0, 0.0))

    obstacles = scan_to_obstacles(scan, (0.0, 0.0, 0.0))

    face = np.column_stack([np.full(101, 2.0), np.linspace(-0.5, 0.5, 101)])
    assert covered(obstacles, face)
    assert len(obstacles) <= 3
    for obstacle in obstacles:  # bounded, with an interior, near the box
        assert len(obstacle.vertices) >= 3
        assert min_clearance([BOX], obstacle.vertices) <= 0.1
        assert np.ptp(obstacle.vertices, axis=0).min() >= 0.03


def test_a_face_seen_at_a_grazing_angle_gives_pieces_without_needle_corners() -> None:
    # unknown_box's box from where a run stalled: its bottom face at 6 degrees. Pushed back
    # along the rays, that face's hull was a sliver with 5 degree corners, which the MPC's
    # inflation grew into a 10 m spike across the robot's free path.
    box = ConvexPolygon.from_box(2.8, 0.3, 3.3, 1.0)
    pose = (4.341, 0.166, -0.887)
    obstacles = scan_to_obstacles(SimulatedLaser([box]).scan(pose), pose)
    assert obstacles
    for obstacle in obstacles:
        normals = obstacle.A
        turn = np.arccos(np.clip(np.einsum('ij,ij->i', normals, np.roll(normals, 1, axis=0)),
                                 -1.0, 1.0))
        assert np.min(np.pi - turn) >= math.radians(60.0)
        assert min_clearance([box], obstacle.vertices) <= 0.1


def test_laser_mounting_pose_and_robot_pose_put_points_in_the_map_frame() -> None:
    laser = SimulatedLaser([BOX])
    # The laser sits 0.5 m ahead of a robot at (-0.5, 0) facing +x: it is at the origin.
    scan = laser.scan((0.0, 0.0, 0.0))
    points, beams = scan_points(scan, (-0.5, 0.0, 0.0), laser_pose=(0.5, 0.0, 0.0))
    assert np.allclose(points[:, 0], 2.0)
    # The same scan from a robot turned by 90 degrees with the laser turned back by -90.
    turned, _ = scan_points(scan, (0.0, 0.0, math.pi / 2), laser_pose=(0.0, 0.0, -math.pi / 2))
    np.testing.assert_allclose(turned, points, atol=1e-12)
    assert len(beams) == len(points)


def test_two_separate_boxes_give_separate_clusters() -> None:
    other = ConvexPolygon.from_box(2.0, 1.5, 2.6, 2.5)
    scan = SimulatedLaser([BOX, other]).scan((0.0, 0.0, 0.0))
    points, _ = scan_points(scan, (0.0, 0.0, 0.0))

    first, last = cluster_bounds(points, 0.3)
    obstacles = scan_to_obstacles(scan, (0.0, 0.0, 0.0))

    assert len(first) == 2
    assert all(np.ptp(points[a:b + 1, 1]) < 1.2 for a, b in zip(first, last, strict=True))
    touching = [o for o in obstacles
                if min_clearance([BOX], o.vertices) < 0.1 and min_clearance([other], o.vertices)
                < 0.1]
    assert not touching  # no piece bridges the gap between the boxes


def test_a_wall_becomes_few_thin_polygons_along_it() -> None:
    wall = ConvexPolygon.from_box(-3.0, 1.0, 3.0, 1.2)
    scan = SimulatedLaser([wall], fov=math.pi, beams=361).scan((0.0, 0.0, math.pi / 2))

    obstacles = scan_to_obstacles(scan, (0.0, 0.0, math.pi / 2))

    assert 1 <= len(obstacles) <= 3
    face = np.column_stack([np.linspace(-2.5, 2.5, 201), np.full(201, 1.0)])
    assert covered(obstacles, face)
    for obstacle in obstacles:
        ys = obstacle.vertices[:, 1]
        assert ys.min() >= 0.9 and ys.max() <= 1.1  # thin, and along the wall
        assert np.ptp(obstacle.vertices[:, 0]) > 1.0


def test_split_and_merge_splits_an_l_shaped_corner() -> None:
    corner = ConvexPolygon.from_box(1.0, 1.0, 3.0, 3.0)
    scan = SimulatedLaser([corner], fov=math.pi, beams=361).scan((0.0, 0.0, math.pi / 4))

    obstacles = scan_to_obstacles(scan, (0.0, 0.0, math.pi / 4))

    assert len(obstacles) >= 2
    faces = np.vstack([np.column_stack([np.linspace(1, 3, 50), np.full(50, 1.0)]),
                       np.column_stack([np.full(50, 1.0), np.linspace(1, 3, 50)])])
    assert covered(obstacles, faces)


def test_a_single_return_still_gives_a_polygon_with_an_interior() -> None:
    ranges = np.full(9, np.inf)
    ranges[4] = 2.0
    scan = Scan(-0.4, 0.1, 0.05, 10.0, ranges)

    (obstacle,) = scan_to_obstacles(scan, (0.0, 0.0, 0.0))

    assert obstacle.contains(np.array([2.0, 0.0]), margin=1e-9)[0]
    assert np.ptp(obstacle.vertices, axis=0).min() > 0.0


def test_memory_keeps_an_obstacle_after_the_robot_turns_away() -> None:
    laser = SimulatedLaser([BOX])
    memory = ObstacleMemory(ttl=5.0)
    memory.update(laser.scan((0.0, 0.0, 0.0), stamp=0.0), (0.0, 0.0, 0.0))
    seen = memory.obstacles()

    memory.update(laser.scan((0.0, 0.0, math.pi), stamp=1.0), (0.0, 0.0, math.pi))

    assert memory.obstacles() == seen
    assert covered(memory.obstacles(), np.array([[2.0, 0.0]]))
    assert memory.obstacles((0.0, 0.0), 1.0) == []  # only within the radius asked
    assert memory.obstacles((0.0, 0.0), 2.5) == seen


def test_memory_replaces_rather_than_duplicates_what_it_sees_again() -> None:
    laser = SimulatedLaser([BOX])
    memory = ObstacleMemory(ttl=5.0)
    for k in range(5):
        current = memory.update(laser.scan((0.0, 0.0, 0.0), stamp=0.1 * k), (0.0, 0.0, 0.0))

    assert memory.obstacles() == current


def test_a_later_beam_through_where_an_obstacle_was_clears_it() -> None:
    memory = ObstacleMemory(ttl=5.0)
    memory.update(SimulatedLaser([BOX]).scan((0.0, 0.0, 0.0), stamp=0.0), (0.0, 0.0, 0.0))
    # The box is gone; a wall behind it returns the beams that pass where it was. Seen from
    # a pose from which the old pieces are only partly in view (so only crossing clears).
    wall = ConvexPolygon.from_box(4.0, -3.0, 4.2, 3.0)
    pose = (0.0, 1.5, -0.3)
    memory.update(SimulatedLaser([wall]).scan(pose, stamp=1.0), pose)

    assert not covered(memory.obstacles(), np.array([[2.0, 0.0]]), tol=0.0)


def test_the_ttl_expires_remembered_obstacles() -> None:
    laser = SimulatedLaser([BOX])
    memory = ObstacleMemory(ttl=2.0)
    memory.update(laser.scan((0.0, 0.0, 0.0), stamp=0.0), (0.0, 0.0, 0.0))
    memory.update(laser.scan((0.0, 0.0, math.pi), stamp=1.5), (0.0, 0.0, math.pi))
    assert memory.obstacles()

    memory.update(laser.scan((0.0, 0.0, math.pi), stamp=2.5), (0.0, 0.0, math.pi))

    assert memory.obstacles() == []
    with pytest.raises(ScanError, match='older than the last'):
        memory.update(laser.scan((0.0, 0.0, 0.0), stamp=1.0), (0.0, 0.0, 0.0))


def test_each_reading_is_judged_on_its_own_as_rep_117_says() -> None:
    # +inf: no return, free to range_max; -inf: too close, a return at range_min that frees
    # nothing; NaN, below range_min, above range_max: ignored (no return, nothing free)
    ranges = np.array([np.inf, -np.inf, np.nan, 0.01, 3.0, 20.0, -1.0, 0.05, 10.0])
    scan = Scan(-0.4, 0.1, 0.05, 10.0, ranges)

    validate_scan(scan)
    beams = classify_beams(scan)

    assert beams.hit.tolist() == [False, True, False, False, True, False, False, True, True]
    np.testing.assert_array_equal(
        beams.seen, [10.0, 0.05, np.nan, np.nan, 3.0, np.nan, np.nan, 0.05, 10.0])
    np.testing.assert_array_equal(beams.free, [10.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.05, 10.0])
    assert beams.usable.tolist() == [True, True, False, False, True, False, False, True, True]
    points, index = scan_points(scan, (0.0, 0.0, 0.0))
    assert index.tolist() == [1, 4, 7, 8]
    with pytest.raises(ScanError, match='robot pose must be three finite'):
        scan_to_obstacles(scan, (0.0, math.nan, 0.0))
    assert issubclass(ScanError, ValueError)


def assert_same_polygons(got: list[ConvexPolygon], expected: list[ConvexPolygon]) -> None:
    assert len(got) == len(expected)
    for a, b in zip(got, expected, strict=True):
        np.testing.assert_array_equal(a.vertices, b.vertices)
        np.testing.assert_array_equal(a.A, b.A)
        np.testing.assert_array_equal(a.b, b.b)


def test_a_nan_beam_among_good_ones_is_ignored_and_the_scan_kept() -> None:
    scan = SimulatedLaser([BOX]).scan((0.0, 0.0, 0.0))
    face = np.flatnonzero(np.isfinite(scan.ranges))
    middle = face[len(face) // 2]
    nan_beam = scan._replace(ranges=np.where(np.arange(len(scan.ranges)) == middle, np.nan,
                                             scan.ranges))
    no_return = scan._replace(ranges=np.where(np.arange(len(scan.ranges)) == middle, np.inf,
                                              scan.ranges))

    validate_scan(nan_beam)
    obstacles = scan_to_obstacles(nan_beam, (0.0, 0.0, 0.0))

    assert middle not in scan_points(nan_beam, (0.0, 0.0, 0.0))[1]
    # the pieces are those of the scan without that beam's return
    assert_same_polygons(obstacles, scan_to_obstacles(no_return, (0.0, 0.0, 0.0)))
    assert covered(obstacles, np.column_stack([np.full(51, 2.0), np.linspace(-0.5, 0.5, 51)]))


def test_minus_inf_is_an_obstacle_at_range_min_along_its_beam() -> None:
    ranges = np.full(9, np.inf)
    ranges[6] = -np.inf
    scan = Scan(-0.4, 0.1, 0.2, 10.0, ranges)

    (obstacle,) = scan_to_obstacles(scan, (1.0, 0.0, 0.5))

    points, beams = scan_points(scan, (1.0, 0.0, 0.5))
    assert beams.tolist() == [6]
    np.testing.assert_allclose(points[0], [1.0 + 0.2 * math.cos(0.7), 0.2 * math.sin(0.7)])
    assert obstacle.contains(points, margin=1e-9)[0]


def test_memory_is_not_cleared_by_nan_minus_inf_or_out_of_range_beams() -> None:
    laser = SimulatedLaser([BOX])
    box_face = np.array([[2.0, 0.0]])
    # the box is gone, and the beams that pass where it was say nothing usable (a +inf scan,
    # which does say it is gone, is the control)
    for reading, cleared in ((np.nan, False), (-np.inf, False), (20.0, False), (0.01, False),
                             (np.inf, True)):
        memory = ObstacleMemory(ttl=5.0)
        memory.update(laser.scan((0.0, 0.0, 0.0), stamp=0.0), (0.0, 0.0, 0.0))
        blind = laser.scan((0.0, 0.0, 0.0), stamp=1.0)
        blind = blind._replace(ranges=np.full_like(blind.ranges, reading))

        memory.update(blind, (0.0, 0.0, 0.0))

        assert covered(memory.obstacles(), box_face) is not cleared, reading


def test_a_scan_of_nothing_but_nan_is_valid_and_carries_no_information() -> None:
    scan = Scan(-1.0, 0.01, 0.05, 10.0, np.full(201, np.nan), angle_max=1.0)

    validate_scan(scan)

    assert not classify_beams(scan).usable.any()
    assert scan_to_obstacles(scan, (0.0, 0.0, 0.0)) == []


def test_the_memory_says_whether_the_last_scan_had_a_usable_beam() -> None:
    # the node's scan freshness reads it instead of classifying every scan's beams again
    memory = ObstacleMemory(5.0)
    assert not memory.last_scan_usable
    seen = Scan(-1.0, 0.01, 0.05, 10.0, np.full(201, 2.0), stamp=1.0, angle_max=1.0)
    memory.update(seen, (0.0, 0.0, 0.0))
    assert memory.last_scan_usable
    memory.update(seen._replace(ranges=np.full(201, np.nan), stamp=2.0), (0.0, 0.0, 0.0))
    assert not memory.last_scan_usable


# ------------------------------------------------------------------ the robot's own body
# (the distance from the robot's origin to its front face, for each footprint)
BODIES = [pytest.param(Footprint.circle(0.2), 0.2, id='circle'),
          pytest.param(JACKAL, 0.254, id='jackal')]


def body_scan(front: float) -> Scan:
    """Return nine beams from the right to the left of a laser at the robot's origin.

    range_min 5 cm; -inf to the right and the left, a mount 0.1 m away at -45 degrees, a real
    obstacle 1 cm beyond the front face straight ahead, nothing elsewhere.
    """
    ranges = np.full(9, np.inf)
    ranges[[0, 8]] = -np.inf
    ranges[2] = 0.1
    ranges[4] = front + 0.01
    return Scan(-math.pi / 2, math.pi / 8, 0.05, 10.0, ranges)


@pytest.mark.parametrize(('body', 'front'), BODIES)
def test_returns_inside_the_robots_body_are_the_robot_and_ignored_like_nan(
        body: Footprint, front: float) -> None:
    scan = body_scan(front)
    pose = (1.0, 2.0, 0.7)  # the body is placed at the robot's pose: not the map's origin

    beams = classify_beams(scan, body=body)

    # the -inf beams (5 cm away) and the mount are inside: no return, nothing seen or free
    assert np.flatnonzero(beams.hit).tolist() == [4]
    assert np.isnan(beams.seen[[0, 2, 8]]).all() and not beams.free[[0, 2, 8]].any()
    assert beams.usable.tolist() == [False, True, False, True, True, True, True, True, False]
    points, index = scan_points(scan, pose, body=body)
    assert index.tolist() == [4]
    np.testing.assert_allclose(points[0], [1.0 + (front + 0.01) * math.cos(0.7),
                                           2.0 + (front + 0.01) * math.sin(0.7)])
    # the obstacle just outside the footprint is kept; nothing is left inside the robot
    obstacles = scan_to_obstacles(scan, pose, body=body)
    assert covered(obstacles, points)
    # None (the default): nothing is taken for the robot, every return is an obstacle
    everything, index = scan_points(scan, pose)
    assert index.tolist() == [0, 2, 4, 8]
    assert scan_points(scan, pose, body=None)[1].tolist() == [0, 2, 4, 8]
    own = everything[[0, 1, 3]]  # the -inf points at range_min and the mount
    assert covered(scan_to_obstacles(scan, pose), own)
    assert not point_in_any(obstacles, own).any()


@pytest.mark.parametrize(('body', 'front'), BODIES)
def test_minus_inf_from_a_laser_at_the_front_edge_is_an_obstacle_where_it_reaches_outside(
        body: Footprint, front: float) -> None:
    # two beams, ahead and behind: range_min (5 cm) from a laser on the front face reaches
    # out of the body ahead, and stays inside it behind
    scan = Scan(0.0, math.pi, 0.05, 10.0, np.array([-np.inf, -np.inf]))

    for laser_pose, outside in (((front, 0.0, 0.0), 0), ((front, 0.0, math.pi), 1)):
        points, index = scan_points(scan, (0.0, 0.0, 0.0), laser_pose=laser_pose, body=body)

        assert index.tolist() == [outside], laser_pose  # the laser's yaw turns the beams
        np.testing.assert_allclose(points, [[front + 0.05, 0.0]], atol=1e-12)
        (obstacle,) = scan_to_obstacles(scan, (0.0, 0.0, 0.0), laser_pose=laser_pose,
                                        body=body)
        assert obstacle.contains(points, margin=1e-9)[0]


def test_a_return_within_a_millimetre_of_the_footprint_is_the_robot_farther_out_an_obstacle(
        ) -> None:
    body = Footprint.circle(0.2)
    # flush with the outline, half a millimetre and two millimetres out
    ranges = np.array([0.2, 0.2005, 0.202])
    scan = Scan(-0.1, 0.1, 0.05, 10.0, ranges)  # a round robot: only the range matters

    assert classify_beams(scan, body=body).hit.tolist() == [False, False, True]


def test_the_memory_takes_neither_obstacles_nor_clearing_from_the_robots_body() -> None:
    body = Footprint.circle(0.2)
    memory = ObstacleMemory(ttl=5.0)

    assert len(memory.update(body_scan(0.2), (0.0, 0.0, 0.0), body=body)) == 1
    assert len(memory) == 1
    # a later scan of nothing but -inf and a return inside the body (the laser is covered)
    # says nothing about what is outside: the obstacle is kept, not cleared nor replaced
    blind = body_scan(0.2)._replace(ranges=np.array([-np.inf] * 8 + [0.1]), stamp=1.0)
    assert memory.update(blind, (0.0, 0.0, 0.0), body=body) == []
    assert covered(memory.obstacles(), np.array([[0.21, 0.0]]))
    # without the body the same scan gives obstacles at range_min, inside the robot
    assert len(ObstacleMemory(ttl=5.0).update(blind, (0.0, 0.0, 0.0))) > 0
