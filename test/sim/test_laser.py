# SPDX-License-Identifier: Apache-2.0
"""Tests of the simulated laser and the contact check against the exact world."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.sim.contact import contact, footprint_distances
from mpc_local_planner.sim.laser import JACKAL_FOV, SimulatedLaser
from mpc_local_planner.worlds.data_files import BARN_DIR
from mpc_local_planner.worlds.world import Circle, load_barn_world, world_from_dict


def brute_force(shapes: list, origin: np.ndarray, angles: np.ndarray, range_max: float
                ) -> np.ndarray:
    """Cast every beam against every shape densely (no pruning): the reference."""
    ranges = np.full(len(angles), np.inf)
    d = np.column_stack([np.cos(angles), np.sin(angles)])
    for shape in shapes:
        if isinstance(shape, Circle):
            f = origin - (shape.x, shape.y)
            proj = d @ f
            disc = proj**2 - (f @ f - shape.radius**2)
            t = np.where(disc >= 0, -proj - np.sqrt(np.maximum(disc, 0)), np.inf)
            t[t < 0] = np.inf
        else:
            t = np.full(len(angles), np.inf)
            v = shape.vertices
            for s, e in zip(v, np.roll(v, -1, axis=0), strict=True):
                edge, rel = e - s, s - origin
                den = d[:, 0] * edge[1] - d[:, 1] * edge[0]
                with np.errstate(divide='ignore', invalid='ignore'):
                    tt = (rel[0] * edge[1] - rel[1] * edge[0]) / den
                    u = (rel[0] * d[:, 1] - rel[1] * d[:, 0]) / den
                ok = (np.abs(den) > 1e-12) & (tt >= 0) & (u >= 0) & (u <= 1)
                t = np.minimum(t, np.where(ok, tt, np.inf))
        ranges = np.minimum(ranges, t)
    ranges[ranges > range_max] = np.inf
    return ranges


def test_laser_uses_rep117_conventions_and_centres_beams_on_the_forward_axis() -> None:
    laser = SimulatedLaser([ConvexPolygon.from_box(2.0, -1.0, 3.0, 1.0)])
    scan = laser.scan((0.0, 0.0, 0.0))

    assert len(scan.ranges) == 720
    assert scan.angle_min == pytest.approx(-JACKAL_FOV / 2)
    assert scan.angle_min + 719 * scan.angle_increment == pytest.approx(JACKAL_FOV / 2)
    assert scan.ranges[359] == pytest.approx(2.0, abs=1e-3)
    assert scan.ranges[360] == pytest.approx(2.0, abs=1e-3)
    assert np.isinf(scan.ranges[0]) and np.isinf(scan.ranges[-1])  # nothing there: inf


def test_laser_hits_a_circle_exactly_and_follows_the_pose_yaw() -> None:
    laser = SimulatedLaser([Circle(0.0, 3.0, 0.5)], beams=361, fov=math.pi)
    scan = laser.scan((0.0, 0.0, math.pi / 2))

    assert scan.ranges[180] == pytest.approx(2.5, abs=1e-12)
    angles = laser.angles() + math.pi / 2
    np.testing.assert_allclose(scan.ranges,
                               brute_force([Circle(0.0, 3.0, 0.5)], np.zeros(2), angles, 10.0))


def test_barn_scan_matches_a_brute_force_cast_against_every_cylinder() -> None:
    world = load_barn_world(BARN_DIR / 'world_000.json')
    laser = SimulatedLaser(TrueGeometry.from_world(world))
    for pose in ([-2.25, 3.5, 1.57], [-1.0, 6.0, -2.5], [-3.5, 9.0, 0.3]):
        scan = laser.scan(pose)
        angles = pose[2] + laser.angles()
        reference = brute_force(list(world.true_shapes), np.array(pose[:2]), angles, 10.0)
        np.testing.assert_allclose(scan.ranges, reference, atol=1e-9)
        assert np.isfinite(scan.ranges).sum() > 100


def test_laser_drops_hits_beyond_range_max() -> None:
    laser = SimulatedLaser([Circle(5.0, 0.0, 0.5)], range_max=4.0)

    assert np.all(np.isinf(laser.scan((0.0, 0.0, 0.0)).ranges))


def test_laser_sees_unknown_obstacles_of_a_world() -> None:
    world = world_from_dict({
        'bounds': [-1, 5, -2, 2], 'obstacles': [], 'start': [0, 0, 0], 'goal': [4, 0, 0],
        'unknown_obstacles': [{'circle': [2.0, 0.0, 0.25]}],
    }, name='hidden')
    scan = SimulatedLaser(TrueGeometry.from_world(world)).scan(world.start)

    assert np.min(scan.ranges) == pytest.approx(1.75, abs=1e-3)
    assert isinstance(world.true_shapes[0], Circle)  # cast against the disk itself


@pytest.mark.parametrize('options', [{'beams': 1}, {'fov': 0.0}, {'range_max': math.inf},
                                     {'range_min': 2.0, 'range_max': 1.0}])
def test_laser_refuses_bad_options(options: dict) -> None:
    with pytest.raises(ValueError):
        SimulatedLaser([], **options)


def test_contact_uses_exact_distances_to_polygons_and_disks() -> None:
    geometry = TrueGeometry([ConvexPolygon.from_box(0.0, 0.0, 1.0, 1.0), Circle(3.0, 0.0, 0.5)])

    assert contact(geometry, 1.2, 0.5, 0.2)  # touching a face counts
    assert not contact(geometry, 1.21, 0.5, 0.2)
    corner = 1.0 + 0.2 / math.sqrt(2)
    assert contact(geometry, corner, corner, 0.2 + 1e-9)  # the corner is round, not a box
    assert not contact(geometry, corner + 0.01, corner + 0.01, 0.2)
    assert contact(geometry, 0.5, 0.5, 0.0)  # inside
    assert contact(geometry, 3.69, 0.0, 0.2) and not contact(geometry, 3.71, 0.0, 0.2)
    assert not contact(TrueGeometry([]), 0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match='finite'):
        contact(geometry, math.nan, 0.0, 0.2)


# ----------------------------------------------------------------------------- footprints
# The Jackal: 0.508 m x 0.430 m, centred; inscribed radius 0.215 m, circumscribed 0.3328 m.
INSCRIBED = 0.215


def test_the_jackal_misses_what_its_circumscribed_circle_would_touch() -> None:
    # a wall 0.25 m to the left: inside the circumscribed circle, beyond the rectangle's side
    geometry = TrueGeometry([ConvexPolygon.from_box(-0.5, 0.25, 0.5, 0.6)])

    assert contact(geometry, 0.0, 0.0, JACKAL.radius)
    assert not contact(geometry, 0.0, 0.0, JACKAL, 0.0)
    assert footprint_distances(geometry, JACKAL, [[0.0, 0.0, 0.0]])[0] == pytest.approx(0.035)
    # turned a quarter, its half-length (0.254 m) reaches past 0.25 m: heading matters
    assert contact(geometry, 0.0, 0.0, JACKAL, math.pi / 2)
    assert footprint_distances(geometry, JACKAL, [[0.0, 0.0, math.pi / 2]])[0] == \
        pytest.approx(-0.004)
    # a cylinder beside the left side, inside the circumscribed circle
    cylinder = TrueGeometry([Circle(0.0, 0.30, 0.05)])
    assert contact(cylinder, 0.0, 0.0, JACKAL.radius)
    assert not contact(cylinder, 0.0, 0.0, JACKAL)
    assert footprint_distances(cylinder, JACKAL, [[0.0, 0.0, 0.0]])[0] == pytest.approx(0.035)


def test_the_jackal_touches_what_its_inscribed_circle_would_miss() -> None:
    # a wall 0.24 m ahead: beyond the inscribed circle, within the rectangle's front
    wall = TrueGeometry([ConvexPolygon.from_box(0.24, -0.5, 0.6, 0.5)])
    assert not contact(wall, 0.0, 0.0, INSCRIBED)
    assert contact(wall, 0.0, 0.0, JACKAL)
    assert footprint_distances(wall, JACKAL, [[0.0, 0.0, 0.0]])[0] == pytest.approx(-0.014)
    # a cylinder on the diagonal, touching only the front-left corner
    corner = np.array([0.254, 0.215])
    direction = corner / np.linalg.norm(corner)
    centre = corner + 0.07 * direction
    for radius, touching in ((0.0701, True), (0.0699, False)):
        cylinder = TrueGeometry([Circle(*centre, radius)])
        assert not contact(cylinder, 0.0, 0.0, INSCRIBED)
        assert contact(cylinder, 0.0, 0.0, JACKAL) is touching
    # the same corner case at a pose: the footprint moves and turns with the robot
    pose = (1.0, -2.0, 0.7)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    moved = np.array(pose[:2]) + np.array([[c, -s], [s, c]]) @ centre
    assert contact(TrueGeometry([Circle(*moved, 0.0701)]), *pose[:2], JACKAL, pose[2])
    assert not contact(TrueGeometry([Circle(*moved, 0.0699)]), *pose[:2], JACKAL, pose[2])


def test_a_circle_footprint_is_the_radius_path_unchanged() -> None:
    geometry = TrueGeometry([ConvexPolygon.from_box(0.0, 0.0, 1.0, 1.0), Circle(3.0, 0.0, 0.5)])
    rng = np.random.default_rng(3)
    for x, y in rng.uniform(-1.0, 4.0, size=(300, 2)):
        for radius in (0.0, 0.2, 0.6):
            assert contact(geometry, x, y, Footprint.circle(radius), 1.0) is \
                contact(geometry, x, y, radius)
            outside = geometry.distance((x, y)) - radius
            distance = footprint_distances(geometry, Footprint.circle(radius), [[x, y]])[0]
            if outside > 0:  # apart, the signed distance is the distance
                assert distance == pytest.approx(outside, abs=1e-12)
            else:
                assert distance <= 1e-12


def test_footprint_checks_refuse_bad_poses_and_an_empty_world_is_free() -> None:
    geometry = TrueGeometry([Circle(0.0, 0.0, 0.5)])
    with pytest.raises(ValueError, match='finite'):
        contact(geometry, 0.0, 0.0, JACKAL, math.inf)
    with pytest.raises(ValueError, match=r'\(n, 3\)'):
        footprint_distances(geometry, JACKAL, [[0.0, 0.0]])
    with pytest.raises(ValueError, match='finite'):
        footprint_distances(geometry, JACKAL, [[0.0, math.nan, 0.0]])
    assert not contact(TrueGeometry([]), 0.0, 0.0, JACKAL, 0.3)
    assert np.all(np.isinf(footprint_distances(TrueGeometry([]), JACKAL, np.zeros((4, 3)))))


def random_footprint(rng: np.random.Generator) -> Footprint:
    """A random convex polygon around the origin (3 to 8 vertices), or the Jackal."""
    if rng.random() < 0.25:
        return JACKAL
    while True:
        points = rng.uniform(-0.45, 0.45, size=(int(rng.integers(3, 9)), 2))
        try:
            return Footprint.polygon(ConvexPolygon.from_vertices(points).vertices)
        except ValueError:  # a hull too flat to be a footprint: draw again
            continue


def random_shapes(rng: np.random.Generator) -> list:
    """Random boxes, convex polygons and disks in [-1.2, 1.2]^2."""
    shapes: list = []
    for _ in range(int(rng.integers(2, 6))):
        centre = rng.uniform(-1.2, 1.2, size=2)
        kind = rng.integers(3)
        if kind == 0:
            half = rng.uniform(0.05, 0.5, size=2)
            shapes.append(ConvexPolygon.from_box(*(centre - half), *(centre + half)))
        elif kind == 1:
            shapes.append(ConvexPolygon.from_vertices(centre + rng.uniform(
                -0.4, 0.4, size=(int(rng.integers(3, 8)), 2))))
        else:
            shapes.append(Circle(*centre, rng.uniform(0.05, 0.4)))
    return shapes


def dense_samples(footprint: Footprint, pose: np.ndarray, spacing: float, grid: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Return (boundary, interior) points of the footprint at pose, spaced by spacing, grid."""
    vertices = footprint.vertices
    boundary = []
    for start, end in zip(vertices, np.roll(vertices, -1, axis=0), strict=True):
        count = max(2, int(np.ceil(np.linalg.norm(end - start) / spacing)) + 1)
        boundary.append(np.linspace(start, end, count))
    boundary = np.vstack(boundary)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], grid), np.arange(lo[1], hi[1], grid))
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    interior = grid[ConvexPolygon.from_vertices(vertices).contains(grid)]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rotation = np.array([[c, s], [-s, c]])
    return boundary @ rotation + pose[:2], interior @ rotation + pose[:2]


def point_distance(shape, points: np.ndarray) -> np.ndarray:
    """Exact distance from points to one shape (0 inside)."""
    if isinstance(shape, Circle):
        return np.maximum(np.hypot(points[:, 0] - shape.x, points[:, 1] - shape.y)
                          - shape.radius, 0.0)
    return shape.distance(points)


def covers(shape, points: np.ndarray) -> bool:
    """Say whether any point lies in the shape (boundary included)."""
    if isinstance(shape, Circle):
        return bool(np.any(np.hypot(points[:, 0] - shape.x, points[:, 1] - shape.y)
                           <= shape.radius))
    return bool(np.any(shape.contains(points)))


def support_signed_distance(footprint: Footprint, pose: np.ndarray, shapes: list,
                            directions: int = 7200) -> float:
    """Signed distance by brute force over directions u: -min_u (h_F(u) + h_O(-u)).

    For convex sets this is the distance when apart and minus the penetration depth when
    overlapping; sampling u can only make the minimum larger, so the result is <= the truth
    (by at most about size * pi / directions).
    """
    angles = np.arange(directions) * 2 * math.pi / directions
    u = np.column_stack([np.cos(angles), np.sin(angles)])
    c, s = math.cos(pose[2]), math.sin(pose[2])
    robot = footprint.vertices @ np.array([[c, s], [-s, c]])  # relative to the pose
    h_robot = np.max(u @ robot.T, axis=1)
    best = math.inf
    for shape in shapes:
        if isinstance(shape, Circle):
            h_shape = -(u @ (np.array([shape.x, shape.y]) - pose[:2])) + shape.radius
        else:
            h_shape = np.max(-(u @ (shape.vertices - pose[:2]).T), axis=1)
        best = min(best, -float(np.min(h_robot + h_shape)))
    return best


def test_polygon_footprint_contact_and_distance_match_brute_force_on_random_cases() -> None:
    rng = np.random.default_rng(2026)
    spacing, grid = 0.004, 0.01
    counts = {'apart': 0, 'deep': 0, 'near': 0}
    for _ in range(25):
        footprint = random_footprint(rng)
        shapes = random_shapes(rng)
        geometry = TrueGeometry(shapes)
        poses = np.column_stack([rng.uniform(-1.2, 1.2, size=(24, 2)),
                                 rng.uniform(-math.pi, math.pi, 24)])
        distances = footprint_distances(geometry, footprint, poses)
        for pose, distance in zip(poses, distances, strict=True):
            touching = contact(geometry, pose[0], pose[1], footprint, pose[2])
            assert touching is bool(distance <= 0.0)
            reference = support_signed_distance(footprint, pose, shapes)
            assert reference - 1e-12 <= distance <= reference + 2e-3
            boundary, interior = dense_samples(footprint, pose, spacing, grid)
            sampled = min(float(np.min(point_distance(shape, boundary))) for shape in shapes)
            inside = any(covers(shape, np.vstack([boundary, interior])) for shape in shapes)
            if distance > 0.0:  # apart: no sample touches, and the nearest is as far
                assert not inside
                assert distance - 1e-12 <= sampled <= distance + spacing
                counts['apart'] += 1
            elif distance < -0.02:  # clearly overlapping: samples fall inside a shape
                assert inside
                counts['deep'] += 1
            else:
                assert sampled <= spacing
                counts['near'] += 1
    # the random cases exercise every branch (apart, overlapping, grazing)
    assert counts['apart'] >= 100 and counts['deep'] >= 100 and counts['near'] >= 5, counts


def test_footprint_distances_for_many_poses_equal_one_pose_at_a_time() -> None:
    world = load_barn_world(BARN_DIR / 'world_000.json')
    geometry = TrueGeometry.from_world(world)
    rng = np.random.default_rng(11)
    lo = np.array(world.bounds[::2]) + 1.0
    hi = np.array(world.bounds[1::2]) - 1.0
    poses = np.column_stack([rng.uniform(lo, hi, size=(1100, 2)),
                             rng.uniform(-math.pi, math.pi, 1100)])
    together = footprint_distances(geometry, JACKAL, poses)
    alone = np.array([footprint_distances(geometry, JACKAL, pose[None])[0] for pose in poses])

    np.testing.assert_array_equal(together, alone)
    for pose, distance in zip(poses[:200], together[:200], strict=True):
        reference = support_signed_distance(JACKAL, pose, list(world.true_shapes), 3600)
        assert reference - 1e-12 <= distance <= reference + 2e-3
    assert np.any(together < 0.0) and np.any(together > 0.0)
