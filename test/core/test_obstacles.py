# SPDX-License-Identifier: Apache-2.0
"""Unit tests of convex obstacles in H-representation."""

from conftest import point_in_any
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from mpc_local_planner.core.obstacles import (
    ConvexPolygon,
    face_weights,
    first_blocked_segment,
    min_clearance,
    ObstacleSet,
    polygon_separation,
    segment_collides,
    within_faces,
)

BOX = [ConvexPolygon.from_box(0.0, 0.0, 1.0, 1.0)]


def test_box_h_representation_has_unit_outward_normals() -> None:
    box = ConvexPolygon.from_box(1, -1, 1.5, 1)
    np.testing.assert_allclose(np.linalg.norm(box.A, axis=1), 1.0)
    assert box.contains(np.array([[1.2, 0.0]]))[0]
    assert not box.contains(np.array([[0.9, 0.0]]))[0]
    np.testing.assert_allclose(box.signed_distance_lower_bound(np.array([[0.8, 0.0]])), [0.2])


def test_inflation_moves_every_face_out_by_the_distance() -> None:
    box = ConvexPolygon.from_box(0, 0, 1, 1).inflate(0.1)
    assert box.contains(np.array([[-0.09, 0.5]]))[0]
    assert not box.contains(np.array([[-0.11, 0.5]]))[0]
    np.testing.assert_allclose(box.vertices.min(axis=0), [-0.1, -0.1])


def test_circumscribed_polygon_contains_the_whole_circle() -> None:
    polygon = ConvexPolygon.from_circle(1.0, 2.0, 0.5, sides=8)
    angles = np.linspace(0, 2 * np.pi, 361)
    rim = np.column_stack([1.0 + 0.5 * np.cos(angles), 2.0 + 0.5 * np.sin(angles)])
    assert np.all(polygon.contains(rim, margin=1e-12))


def test_boxes_and_circles_built_without_qhull_are_the_hulls_to_the_last_digit() -> None:
    rng = np.random.default_rng(7)
    for _ in range(300):
        x0, y0 = rng.normal(size=2) * 10.0
        w, h = rng.uniform(1e-3, 5.0, size=2)
        box = ConvexPolygon.from_box(x0, y0, x0 + w, y0 + h)
        hull = ConvexPolygon.from_vertices([[x0 + w, y0 + h], [x0, y0], [x0, y0 + h],
                                            [x0 + w, y0]])
        cx, cy = rng.normal(size=2) * 10.0
        radius, sides = rng.uniform(1e-3, 3.0), int(rng.integers(3, 17))
        circle = ConvexPolygon.from_circle(cx, cy, radius, sides=sides)
        outer = radius / np.cos(np.pi / sides)
        angles = np.arange(sides) * 2.0 * np.pi / sides + np.pi / sides
        around = ConvexPolygon.from_vertices(np.column_stack(
            [cx + outer * np.cos(angles), cy + outer * np.sin(angles)])[::-1])
        for fast, qhull in ((box, hull), (circle, around)):
            for field in ('A', 'b', 'vertices'):
                np.testing.assert_array_equal(getattr(fast, field), getattr(qhull, field))
    with pytest.raises(ValueError, match='finite'):
        ConvexPolygon.from_box(0.0, 0.0, np.inf, 1.0)


def test_vertices_in_any_order_give_the_convex_hull() -> None:
    polygon = ConvexPolygon.from_vertices([[1, 1], [0, 0], [1, 0], [0, 1], [0.5, 0.5]])
    assert polygon.num_faces == 4


def test_degenerate_polygons_are_refused() -> None:
    with pytest.raises(ValueError, match='collinear'):
        ConvexPolygon.from_vertices([[0, 0], [1, 1], [2, 2]])
    with pytest.raises(ValueError, match='xmin < xmax'):
        ConvexPolygon.from_box(1, 0, 0, 1)


def test_distance_and_clearance_queries() -> None:
    boxes = [ConvexPolygon.from_box(0, 0, 1, 1), ConvexPolygon.from_box(3, 0, 4, 1)]
    np.testing.assert_allclose(boxes[0].distance(np.array([[2.0, 0.5], [0.5, 0.5]])), [1.0, 0])
    assert min_clearance(boxes, np.array([[2.0, 0.5]])) == pytest.approx(1.0)
    np.testing.assert_array_equal(point_in_any(boxes, np.array([[3.5, 0.5], [2, 2]])),
                                  [True, False])


def test_obstacle_set_queries_match_the_polygons_one_by_one() -> None:
    rng = np.random.default_rng(3)
    polygons = [ConvexPolygon.from_box(0, 0, 1, 1), ConvexPolygon.from_circle(3, 1, 0.4),
                ConvexPolygon.from_vertices([[5, 0], [6, 0], [5.5, 1]])]
    points = rng.uniform(-1, 7, size=(50, 2))
    bounds = ObstacleSet(polygons).signed_distance_lower_bound(points)
    for j, polygon in enumerate(polygons):
        np.testing.assert_allclose(bounds[:, j], polygon.signed_distance_lower_bound(points))
    subset = ObstacleSet(polygons).subset(np.array([2, 0]))
    assert subset.obstacles == [polygons[2], polygons[0]]
    np.testing.assert_allclose(subset.signed_distance_lower_bound(points), bounds[:, [2, 0]])


def test_obstacle_set_near_never_misses_an_obstacle_within_the_distance() -> None:
    rng = np.random.default_rng(4)
    polygons = [ConvexPolygon.from_circle(*rng.uniform(-5, 5, 2), rng.uniform(0.1, 0.5))
                for _ in range(60)]
    obstacles = ObstacleSet(polygons)
    for point in rng.uniform(-5, 5, size=(40, 2)):
        chosen, bounds = obstacles.near(point[None], 1.0)
        exact = {j for j, o in enumerate(polygons) if o.distance(point)[0] <= 1.0}
        assert exact <= set(chosen.tolist())
        assert np.all(np.diff(bounds) >= 0)  # nearest first
    assert len(ObstacleSet([]).near(np.zeros((1, 2)), 1.0)[0]) == 0


# ----------------------------------------------------------------------------- the clipper
@pytest.mark.parametrize(('a', 'b', 'grazing_hit', 'strict_hit'), [
    ([-1.0, 0.5], [2.0, 0.5], True, True),  # crosses, both ends outside
    ([0.5, 0.5], [0.5, 0.5], True, True),  # a point inside
    ([0.2, 0.2], [0.8, 0.9], True, True),  # wholly inside
    ([-1.0, 1.0], [2.0, 1.0], True, False),  # runs along the top face
    ([0.0, 2.0], [2.0, 0.0], True, False),  # touches only the corner (1, 1)
    ([1.0, 0.5], [3.0, 0.5], True, False),  # starts on the right face, leaves
    ([0.5, 2.0], [1.5, 1.0], False, False),  # passes the corner above
    ([-1.0, 1.01], [2.0, 1.01], False, False),
    ([1.2, -1.0], [2.0, 2.0], False, False),
])
def test_the_clipper_counts_grazing_only_when_asked(a: list[float], b: list[float],
                                                    grazing_hit: bool, strict_hit: bool) -> None:
    assert segment_collides(BOX, a, b, grazing=True) is grazing_hit
    assert segment_collides(BOX, a, b, grazing=False) is strict_hit
    assert segment_collides(BOX, b, a, grazing=True) is grazing_hit  # either direction
    assert segment_collides(BOX, b, a, grazing=False) is strict_hit


def test_the_clipper_without_obstacles_hits_nothing() -> None:
    assert not segment_collides([], [0.0, 0.0], [1.0, 1.0])
    assert ObstacleSet([]).segment_hits(np.zeros((3, 2)), np.ones((3, 2)), grazing=True).shape \
        == (3, 0)
    assert first_blocked_segment([], np.array([[0.0, 0.0], [1.0, 1.0]])) is None


def test_the_clipper_is_vectorised_over_segments_and_obstacles() -> None:
    rng = np.random.default_rng(5)
    polygons = [ConvexPolygon.from_box(0, 0, 1, 1), ConvexPolygon.from_circle(3, 1, 0.4),
                ConvexPolygon.from_vertices([[5, 0], [6, 0], [5.5, 1]])]
    starts, ends = rng.uniform(-1, 7, size=(40, 2)), rng.uniform(-1, 7, size=(40, 2))
    hits = ObstacleSet(polygons).segment_hits(starts, ends, grazing=True)
    assert hits.shape == (40, 3)
    for i in range(40):
        for k, polygon in enumerate(polygons):
            assert hits[i, k] == segment_collides([polygon], starts[i], ends[i])


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-3.0, 3.0), min_size=4, max_size=4), st.booleans())
def test_the_clipper_agrees_with_dense_sampling(coords: list[float], grazing: bool) -> None:
    polygon = ConvexPolygon.from_vertices([[0.0, 0.0], [1.0, -0.5], [1.5, 0.7], [0.3, 1.2]])
    a, b = np.array(coords[:2]), np.array(coords[2:])
    depth = polygon.signed_distance_lower_bound(np.linspace(a, b, 2001))

    exact = segment_collides([polygon], a, b, grazing=grazing)

    if depth.min() < -1e-3:
        assert exact  # a sample is clearly inside
    elif depth.min() > 1e-3:
        assert not exact  # every sample is clearly outside (sampling step < 4.3 mm)


def test_first_blocked_segment_names_the_first_obstacle_and_its_first_segment() -> None:
    boxes = [ConvexPolygon.from_box(0, 0, 1, 1), ConvexPolygon.from_box(3, 0, 4, 1)]
    clear = np.array([[-1.0, 2.0], [5.0, 2.0]])
    assert first_blocked_segment(boxes, clear) is None
    # segment 1 crosses box 1, segment 2 crosses box 0: box 0 (the first obstacle) wins
    polyline = np.array([[2.0, 2.0], [2.0, 0.5], [3.5, 0.5], [3.5, 2.0], [0.5, 2.0],
                         [0.5, -1.0]])
    assert first_blocked_segment(boxes, polyline) == (0, 4)
    assert first_blocked_segment(boxes[1:], polyline) == (0, 1)
    # a plan along a face at exactly the clearance passes; with grazing it does not
    along = np.array([[-1.0, 1.0], [2.0, 1.0]])
    assert first_blocked_segment(boxes, along) is None
    assert first_blocked_segment(boxes, along, grazing=True) == (0, 0)
    # extra columns (yaw) are ignored
    assert first_blocked_segment(boxes, np.column_stack([along, np.zeros(2)])) is None


# ----------------------------------------------------------------------------- polygon pairs
def random_polygon(rng: np.random.Generator, centre_spread: float = 1.0,
                   sides: int | None = None) -> ConvexPolygon:
    """A random convex polygon: points on a stretched circle at sorted random angles."""
    sides = int(rng.integers(3, 9)) if sides is None else sides
    angles = np.sort(rng.uniform(0.0, 2 * np.pi, sides))
    radius = rng.uniform(0.1, 1.0)
    stretch = rng.uniform(0.3, 1.5)
    centre = rng.uniform(-centre_spread, centre_spread, 2)
    return ConvexPolygon.from_vertices(
        centre + radius * np.column_stack([stretch * np.cos(angles), np.sin(angles)]))


def minkowski_signed_distance(polygon: ConvexPolygon, obstacle: ConvexPolygon) -> float:
    """Brute force: the polygons meet iff the origin is in their difference P - O.

    P - O is the hull of all vertex differences; outside it the signed distance is the
    origin's Euclidean distance to it, inside minus the distance to its nearest face.
    """
    difference = ConvexPolygon.from_vertices(
        (polygon.vertices[:, None, :] - obstacle.vertices[None, :, :]).reshape(-1, 2))
    origin = np.zeros((1, 2))
    if difference.contains(origin)[0]:
        return float(difference.signed_distance_lower_bound(origin)[0])
    return float(difference.distance(origin)[0])


def sampled_distance(polygon: ConvexPolygon, obstacle: ConvexPolygon) -> float:
    """Brute force for disjoint polygons: points along each outline to the other polygon.

    ConvexPolygon.distance is an exact point query; the closest pair of two disjoint convex
    polygons has a vertex of one of them, and the vertices are among the samples, so the
    least of these distances is the exact one (samples between vertices can only be
    further).
    """
    def outline(vertices: np.ndarray) -> np.ndarray:
        t = np.linspace(0.0, 1.0, 25)[None, :, None]
        return (vertices[:, None] + t * (np.roll(vertices, -1, axis=0) - vertices)[:, None]
                ).reshape(-1, 2)
    return float(min(np.min(obstacle.distance(outline(polygon.vertices))),
                     np.min(polygon.distance(outline(obstacle.vertices)))))


def test_polygon_separation_is_the_exact_signed_distance_of_random_pairs() -> None:
    rng = np.random.default_rng(11)
    overlapping = disjoint = 0
    for _ in range(150):
        polygons = [random_polygon(rng, sides=5) for _ in range(3)]
        obstacles = [random_polygon(rng) for _ in range(4)]  # 3 to 8 faces: padded
        signed, direction = polygon_separation(np.array([p.vertices for p in polygons]),
                                               ObstacleSet(obstacles))
        assert signed.shape == (3, 4) and direction.shape == (3, 4, 2)
        for m, polygon in enumerate(polygons):
            for k, obstacle in enumerate(obstacles):
                expected = minkowski_signed_distance(polygon, obstacle)
                assert signed[m, k] == pytest.approx(expected, abs=1e-12)
                # the direction is unit and separates by exactly that much
                w = direction[m, k]
                assert np.linalg.norm(w) == pytest.approx(1.0, abs=1e-12)
                along = np.min(polygon.vertices @ w) - np.max(obstacle.vertices @ w)
                assert along == pytest.approx(signed[m, k], abs=1e-12)
                overlapping += expected < 0
                disjoint += expected > 0
    assert overlapping > 100 and disjoint > 100  # both cases were exercised


def test_polygon_separation_of_disjoint_pairs_agrees_with_sampled_outlines() -> None:
    rng = np.random.default_rng(12)
    checked = 0
    while checked < 20:
        polygon, obstacle = random_polygon(rng, 2.0), random_polygon(rng, 2.0)
        signed, _ = polygon_separation(polygon.vertices, ObstacleSet([obstacle]))
        if signed[0, 0] <= 0:
            continue
        assert signed[0, 0] == pytest.approx(sampled_distance(polygon, obstacle), abs=1e-12)
        checked += 1


def test_polygon_separation_of_a_rectangle_beside_a_box() -> None:
    box = ObstacleSet([ConvexPolygon.from_box(0.0, 0.0, 1.0, 1.0)])
    rectangle = np.array([[1.2, 0.2], [1.6, 0.2], [1.6, 0.4], [1.2, 0.4]])
    signed, direction = polygon_separation(rectangle, box)
    assert signed[0, 0] == pytest.approx(0.2)
    np.testing.assert_allclose(direction[0, 0], [1.0, 0.0], atol=1e-12)
    # corner to corner: the distance is between the vertices, not along a face normal
    diagonal = rectangle + np.array([0.0, 1.0])
    signed, direction = polygon_separation(diagonal, box)
    assert signed[0, 0] == pytest.approx(np.hypot(0.2, 0.2))
    np.testing.assert_allclose(direction[0, 0], [np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)
    # 0.05 into the box's right face: minus the penetration depth
    signed, _ = polygon_separation(rectangle - np.array([0.25, 0.0]), box)
    assert signed[0, 0] == pytest.approx(-0.05)
    # no obstacles, no polygons
    assert polygon_separation(rectangle, ObstacleSet([]))[0].shape == (1, 0)
    assert polygon_separation(np.zeros((0, 4, 2)), box)[0].shape == (0, 1)


def test_face_weights_write_any_direction_with_two_adjacent_faces() -> None:
    rng = np.random.default_rng(13)
    for _ in range(20):
        polygon = random_polygon(rng)
        angles = rng.uniform(0.0, 2 * np.pi, 50)
        directions = np.column_stack([np.cos(angles), np.sin(angles)])
        weights = face_weights(polygon.A, directions)
        assert np.all(weights >= 0.0)
        np.testing.assert_allclose(weights @ polygon.A, directions, atol=1e-12)
        n = polygon.num_faces
        for row in weights:
            used = np.flatnonzero(row > 0)
            assert len(used) <= 2
            if len(used) == 2:  # neighbours, possibly across the wrap-around
                assert (used[1] - used[0]) % n in (1, n - 1)
            # the faces used are those through the support point in that direction
            vertex = polygon.vertices[np.argmax(polygon.vertices @ (row @ polygon.A))]
            np.testing.assert_allclose(polygon.A[used] @ vertex, polygon.b[used], atol=1e-12)
    # a face normal itself is that face alone
    box = ConvexPolygon.from_box(0.0, 0.0, 1.0, 1.0)
    np.testing.assert_allclose(face_weights(box.A, box.A), np.eye(4), atol=1e-12)


def test_polygons_with_too_many_faces_become_a_rectangle_around_them() -> None:
    decagon = ConvexPolygon.from_circle(1.0, 2.0, 0.5, sides=10)
    box = ConvexPolygon.from_box(0.0, 0.0, 1.0, 1.0)
    fitted = within_faces([decagon, box], 8)
    assert fitted[1] is box
    assert fitted[0].num_faces == 4
    assert np.all(fitted[0].contains(decagon.vertices, margin=1e-9))
    area = np.ptp(fitted[0].vertices[:, 0]) * np.ptp(fitted[0].vertices[:, 1])
    assert area < 1.2 * (2 * 0.5 / np.cos(np.pi / 10)) ** 2


def test_a_sliver_with_needle_corners_becomes_its_rectangle_before_it_is_grown() -> None:
    # a box face seen at a grazing angle, as the laser's hull made it in a stalled run: its
    # 5 degree corners grew by 0.23 m into a 10 m needle across the robot's free path
    sliver = ConvexPolygon.from_vertices(
        [[2.9747, 0.304], [2.7745, 0.3035], [2.8144, 0.3], [3.0145, 0.3]])
    robot = np.array([[4.34, 0.166]])
    assert sliver.inflate(0.23).signed_distance_lower_bound(robot)[0] < 0.0
    (fitted,) = within_faces([sliver], 8)
    assert fitted.num_faces == 4
    assert np.all(fitted.contains(sliver.vertices, margin=1e-9))
    grown = fitted.inflate(0.23)
    assert np.ptp(grown.vertices[:, 0]) < np.ptp(sliver.vertices[:, 0]) + 2 * 0.23 + 1e-6
    assert grown.signed_distance_lower_bound(robot)[0] > 1.0


def test_well_shaped_polygons_pass_unchanged() -> None:
    # (every triangle has a corner of at most 60 degrees: triangles become rectangles)
    thin_box = ConvexPolygon.from_box(0.0, 0.0, 1.0, 0.1)
    hexagon = ConvexPolygon.from_circle(0.0, 0.0, 0.5, sides=6)
    fitted = within_faces([thin_box, hexagon], 8)
    assert fitted[0] is thin_box
    assert fitted[1] is hexagon
