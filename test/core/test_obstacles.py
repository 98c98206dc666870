"""Unit tests of convex obstacles in H-representation."""

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from mpc_local_planner.core.obstacles import (
    ConvexPolygon,
    first_blocked_segment,
    min_clearance,
    ObstacleSet,
    point_in_any,
    segment_collides,
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
