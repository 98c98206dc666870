# SPDX-License-Identifier: Apache-2.0
"""Tests of the run metrics' clearance: the round robot as before, the polygon exactly."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.core.mpc import LyapunovCase
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import analytic_path
from mpc_local_planner.evaluation.metrics import (
    arrivals,
    compute_metrics,
    footprint_clearance,
    travelled,
)
from mpc_local_planner.evaluation.rollout import circle_clearance, polygon_clearance
from mpc_local_planner.evaluation.trajectory import trajectory_row
from mpc_local_planner.worlds.world import Circle, load_world, paper_world

ROOT = Path(__file__).resolve().parents[2]
NARROW_GAP = ROOT / 'config' / 'worlds' / 'narrow_gap.yaml'
GAP_HALF_WIDTH = 0.30


def rows_along(poses: np.ndarray) -> np.ndarray:
    """Trajectory rows through the poses, one every 0.1 s."""
    return np.array([trajectory_row(0.1 * k, pose) for k, pose in enumerate(poses)])


def old_circle_clearance(rows: np.ndarray, obstacles: list[ConvexPolygon],
                         robot_radius: float) -> tuple[float, bool]:
    """The clearance compute_metrics computed before footprints, copied as it was."""
    xy = rows[:, [1, 2]]
    distances = np.min(np.stack([o.distance(xy) for o in obstacles]), axis=0)
    inside = np.zeros(len(xy), dtype=bool)
    for o in obstacles:
        inside |= o.contains(xy)
    clearance = np.where(inside, -1.0, distances) - robot_radius
    min_clearance = float(np.min(clearance))
    return min_clearance, bool(np.any(inside) or min_clearance < 0)


def test_circle_clearance_and_collision_are_unchanged_to_the_last_bit() -> None:
    rng = np.random.default_rng(5)
    cases = {'inside': 0, 'grazing': 0, 'free': 0}
    for _ in range(60):
        obstacles = [ConvexPolygon.from_vertices(rng.uniform(-1.0, 1.0, size=2)
                                                 + rng.uniform(-0.3, 0.3, size=(5, 2)))
                     for _ in range(3)]
        poses = np.column_stack([rng.uniform(-2.0, 2.0, size=(6, 2)),
                                 rng.uniform(-3.0, 3.0, 6)])
        rows = rows_along(poses)
        radius = float(rng.choice([0.0, 0.1, 0.3]))

        metrics = compute_metrics(rows, goal=np.zeros(3), obstacles=obstacles,
                                  robot_radius=radius)
        expected, collision = old_circle_clearance(rows, obstacles, radius)
        assert metrics['min_clearance'] == expected  # exactly, not approximately
        assert metrics['collision'] is collision
        same = compute_metrics(rows, goal=np.zeros(3), obstacles=obstacles,
                               footprint=Footprint.circle(radius))
        assert same['min_clearance'] == expected and same['collision'] is collision
        cases['inside' if expected <= -1.0 else 'grazing' if expected < 0 else 'free'] += 1
    assert min(cases.values()) >= 5, cases  # every convention is exercised


def test_footprint_clearance_of_a_circle_is_the_rollouts_clearance() -> None:
    rng = np.random.default_rng(8)
    points = rng.uniform(-2.0, 2.0, size=(500, 2))
    poses = np.column_stack([points, rng.uniform(-3.0, 3.0, 500)])
    boxes = [ConvexPolygon.from_box(-0.5, -0.5, 0.2, 0.4), ConvexPolygon.from_box(1, 1, 2, 1.5)]
    centres = rng.uniform(-2.0, 2.0, size=(7, 2))
    cylinders = [Circle(x, y, 0.15) for x, y in centres]

    for radius in (0.0, 0.2):
        robot = Footprint.circle(radius)
        np.testing.assert_array_equal(footprint_clearance(boxes, robot)(poses),
                                      polygon_clearance(boxes, radius)(points))
        np.testing.assert_array_equal(footprint_clearance(cylinders, robot)(points),
                                      circle_clearance(centres, 0.15, radius)(points))
        both = footprint_clearance(boxes + cylinders, robot)(poses)
        np.testing.assert_array_equal(both, np.minimum(
            polygon_clearance(boxes, radius)(points),
            circle_clearance(centres, 0.15, radius)(points)))
    assert np.all(np.isinf(footprint_clearance([], JACKAL)(poses)))


def test_the_jackal_through_the_narrow_gap_keeps_its_clearance_and_its_circle_does_not() -> None:
    world = load_world(NARROW_GAP)
    straight = rows_along(np.linspace(world.start, world.goal, 81))
    shapes = world.physical_shapes()

    polygon = compute_metrics(straight, goal=world.goal, obstacles=shapes,
                              footprint=world.footprint)
    assert polygon['collision'] is False
    assert polygon['min_clearance'] == pytest.approx(GAP_HALF_WIDTH - 0.215)
    assert polygon['reached'] is True
    circle = compute_metrics(straight, goal=world.goal, obstacles=shapes,
                             robot_radius=world.robot_radius)
    assert circle['collision'] is True
    assert circle['min_clearance'] == pytest.approx(GAP_HALF_WIDTH - JACKAL.radius)
    # the same positions turned 45 degrees: the heading is in the rows, and the diagonal hits
    turned = straight.copy()
    turned[:, 3] = math.pi / 4
    diagonal = compute_metrics(turned, goal=world.goal, obstacles=shapes,
                               footprint=world.footprint)
    assert diagonal['collision'] is True and diagonal['min_clearance'] < 0.0
    # robot_radius equal to the footprint's covering radius (as World keeps it) is no conflict
    assert compute_metrics(straight, goal=world.goal, obstacles=shapes,
                           robot_radius=world.robot_radius,
                           footprint=world.footprint) == polygon


def test_polygon_clearance_from_cylinders_and_boxes_is_the_exact_signed_distance() -> None:
    shapes = [Circle(0.5, 0.0, 0.1), ConvexPolygon.from_box(-1.0, 0.3, 1.0, 0.6)]
    clearance = footprint_clearance(shapes, JACKAL)

    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, math.pi / 2], [0.2, 0.0, 0.0]])
    np.testing.assert_allclose(clearance(poses), [
        0.3 - 0.215,  # the box beside, nearer than the cylinder ahead (0.5 - 0.1 - 0.254)
        0.3 - 0.254,  # turned, its half-length faces the box (the cylinder: 0.5 - 0.1 - 0.215)
        0.5 - 0.2 - 0.1 - 0.254,  # 0.2 m ahead, its front is 0.054 m into the cylinder
    ], atol=1e-12)
    with pytest.raises(ValueError, match=r'\(n, 3\)'):
        clearance(poses[:, :2])  # a polygon needs the heading


def test_compute_metrics_refuses_a_robot_radius_that_contradicts_the_footprint() -> None:
    rows = rows_along(np.zeros((3, 3)))
    box = [ConvexPolygon.from_box(1.0, 1.0, 2.0, 2.0)]

    with pytest.raises(ValueError, match='robot_radius 0.2 contradicts the footprint'):
        compute_metrics(rows, goal=np.zeros(3), obstacles=box, robot_radius=0.2,
                        footprint=JACKAL)


def test_v_n_checks_are_counted_apart_where_the_proof_covers_them() -> None:
    rows = rows_along(np.array([[0.1 * k, 0.0, 0.0] for k in range(6)]))
    covered, off = LyapunovCase.COVERED, LyapunovCase.STATE_OFF_PREDICTION
    metrics = compute_metrics(
        rows, goal=np.array([0.5, 0.0, 0.0]), obstacles=[],
        lyapunov_ok=[None, True, False, True, False, None],
        lyapunov_cases=[None, covered, off, covered, covered, None])
    assert metrics['lyapunov_checks'] == 4 and metrics['lyapunov_violations'] == 2
    assert metrics['lyapunov_by_case'] == {'covered': {'checks': 3, 'violations': 1},
                                           'state_off_prediction': {'checks': 1,
                                                                    'violations': 1}}
    assert metrics['lyapunov_covered_violations'] == 1
    # without cases (the suites' rollouts): the totals only
    plain = compute_metrics(rows, goal=np.array([0.5, 0.0, 0.0]), obstacles=[],
                            lyapunov_ok=[None, True, False, True, False, None])
    assert plain['lyapunov_violations'] == 2
    assert plain['lyapunov_by_case'] is None and plain['lyapunov_covered_violations'] is None


def test_arrivals_over_rows_are_the_controllers_verdicts_step_by_step() -> None:
    # the paper's goal; the position met at 0.08 m (off the heading: the robot turns in
    # place), then 0.12 m out by noise but on the heading: arrived all the same, as Nav2's
    # stateful SimpleGoalChecker says; once arrived, it stays so
    world = paper_world()
    goal = np.asarray(world.goal, dtype=float)
    back = np.array([-math.cos(goal[2]), -math.sin(goal[2])])
    poses = np.array([[*(goal[:2] + 1.0 * back), goal[2]],
                      [*(goal[:2] + 0.08 * back), goal[2] + 0.5],
                      [*(goal[:2] + 0.12 * back), goal[2] + 0.05],
                      [*(goal[:2] + 1.0 * back), goal[2]]])
    controller = MpcController(config=MpcConfig(solving=SolverSettings(budget='iterations')),
                               obstacles=world.obstacles)
    controller.set_path(analytic_path(world.path))
    verdicts = [controller.compute(pose, None, 0.2 * k).reason is Reason.GOAL_REACHED
                for k, pose in enumerate(poses)]
    assert verdicts == [False, False, True, True]
    settings = ControllerSettings()
    assert arrivals(rows_along(poses), goal, settings).tolist() == verdicts
    metrics = compute_metrics(rows_along(poses), goal=goal, obstacles=[],
                              arrived=arrivals(rows_along(poses), goal, settings))
    assert metrics['reached'] and metrics['time_to_target'] == pytest.approx(0.2)
    assert metrics['position_tolerance'] is None  # the verdicts were given, not tolerances
    # each row judged afresh, the last pose would not count: 1 m out
    assert not compute_metrics(rows_along(poses), goal=goal, obstacles=[])['reached']
    with pytest.raises(ValueError, match='arrived has 3 entries for 4 rows'):
        compute_metrics(rows_along(poses), goal=goal, obstacles=[], arrived=[True] * 3)


def test_with_the_odometrys_speed_the_path_length_counts_motion_not_pose_noise() -> None:
    # 2 m at 0.5 m/s along x, measured at 20 Hz with 1 cm of noise on every pose (a
    # localizer's corrections): the polyline through the poses is a sixth longer
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 4.0 + 1e-9, 0.05)
    poses = np.column_stack([0.5 * t, np.zeros_like(t), np.zeros_like(t)])
    rows = np.array([trajectory_row(ti, pose + rng.normal(0.0, 0.01, 3) * [1, 1, 0])
                     for ti, pose in zip(t, poses, strict=True)])
    goal = np.array([5.0, 0.0, 0.0])  # not reached: the whole run counts
    noisy = compute_metrics(rows, goal=goal, obstacles=[])
    assert noisy['path_length'] > 2.3 and noisy['path_length_source'] == 'positions'
    odometry = np.column_stack([t, np.full_like(t, 0.5)])  # the wheels' speed, 50 Hz would do
    metrics = compute_metrics(rows, goal=goal, obstacles=[], odometry_speed=odometry)
    assert metrics['path_length'] == pytest.approx(2.0)
    assert metrics['path_length_source'] == 'odometry speed'
    # up to the arrival only: arrived from 2 s on, 1 m
    arrived = t >= 2.0 - 1e-9
    assert compute_metrics(rows, goal=goal, obstacles=[], odometry_speed=odometry,
                           arrived=arrived)['path_length'] == pytest.approx(1.0)


def test_travelled_holds_each_speed_until_the_next_and_clips_to_the_span() -> None:
    speed = np.array([[0.0, 1.0], [1.0, -2.0], [2.0, 0.0], [3.0, 5.0]])
    assert travelled(speed, 0.0, 3.0) == pytest.approx(3.0)  # reversing counts
    assert travelled(speed, 0.5, 1.5) == pytest.approx(0.5 + 1.0)
    assert travelled(speed, -1.0, 10.0) == pytest.approx(3.0)  # nothing past the last
    assert travelled(speed[:1], 0.0, 1.0) == 0.0
