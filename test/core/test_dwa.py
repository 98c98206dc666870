# SPDX-License-Identifier: Apache-2.0
"""The DWA baseline: its window, its stops, its detours, and no contact in closed loop."""

import math

import numpy as np
import pytest

from mpc_local_planner.core.baselines.dwa import Dwa, DwaConfig
from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.core.local_controller import LocalController
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet
from mpc_local_planner.evaluation.rollout import (
    Outcome,
    polygon_clearance,
    rollout,
    StopRule,
)

H = 0.2
RADIUS = 0.15
# Sub-steps per control step at which the closed loops below check contact, so that the
# motion between two control steps is checked too, not only where the robot is sampled.
SUBSTEPS = 8


def _config(**changes: object) -> DwaConfig:
    settings = {'control_period': H, 'footprint': Footprint.circle(RADIUS)}
    settings.update(changes)
    return DwaConfig(**settings)


def _overlaps(footprint: Footprint, pose: np.ndarray, obstacle: ConvexPolygon) -> bool:
    """Say whether the footprint at pose meets the obstacle (an independent, exact check).

    Two convex polygons meet iff an edge of one meets the other, or one contains the other.
    """
    corners = footprint.at(pose)
    edges = ObstacleSet([obstacle]).segment_hits(corners, np.roll(corners, -1, axis=0),
                                                 grazing=True)
    if np.any(edges):
        return True
    return bool(np.any(ConvexPolygon.from_vertices(corners).contains(obstacle.vertices)))


def _drive(dwa: Dwa, start: np.ndarray, steps: int, contact) -> tuple[np.ndarray, np.ndarray]:
    """Close the loop with Unicycle.step, checking contact at SUBSTEPS points per step.

    Returns:
        ((steps + 1, 3) states, (steps, 2) commands).

    """
    model = Unicycle(v_max=dwa.config.max_vel_x, omega_max=dwa.config.max_vel_theta)
    x = np.asarray(start, dtype=float)
    states, commands = [x], []
    assert not contact(x)
    for _ in range(steps):
        u = dwa.command(x)
        commands.append(u)
        for _ in range(SUBSTEPS):
            x = model.step(x, u, H / SUBSTEPS)
            assert not contact(x), f'contact at {x.tolist()} under {u.tolist()}'
        states.append(x)
    return np.array(states), np.array(commands)


def _circle_contact(obstacles: list[ConvexPolygon], radius: float = RADIUS):
    clearance = polygon_clearance(obstacles, radius)
    return lambda x: bool(clearance(np.asarray(x)[None, :2])[0] <= 0.0)


# --- the configuration ----------------------------------------------------------------------


def test_default_configuration_is_valid_and_matches_the_unicycle() -> None:
    config = DwaConfig()
    model = Unicycle()
    assert config.max_vel_x == model.v_max and config.max_vel_theta == model.omega_max
    assert config.steps == math.ceil(config.sim_time / config.sim_granularity - 1e-9)


@pytest.mark.parametrize('changes', [
    {'max_vel_x': 0.0},
    {'max_vel_x': math.inf},
    {'min_vel_x': 0.5},  # above max_vel_x
    {'max_vel_theta': -1.0},
    {'acc_lim_x': 0.0},
    {'decel_lim_x': -2.5},  # a magnitude here, not Nav2's negative number
    {'acc_lim_theta': math.nan},
    {'control_period': 0.0},
    {'sim_time': 0.0},
    {'sim_granularity': 2.0},  # longer than sim_time
    {'vx_samples': 1},
    {'vtheta_samples': 20.5},
    {'vx_samples': True},
    {'path_dist_scale': -1.0},
    {'obstacle_scale': math.nan},
    {'local_goal_distance': 0.0},
    {'xy_goal_tolerance': -0.1},
    {'footprint': 0.2},
])
def test_invalid_configurations_are_refused(changes: dict) -> None:
    with pytest.raises(ValueError, match='invalid DWA configuration'):
        DwaConfig(**changes)


# --- the window and the bounds ------------------------------------------------------------


def test_commands_stay_within_the_bounds_and_the_acceleration_window() -> None:
    config = _config(acc_lim_x=0.4, decel_lim_x=0.6, acc_lim_theta=0.4)
    obstacles = [ConvexPolygon.from_box(1.4, 0.6, 1.8, 1.2), ConvexPolygon.from_box(2.6, -0.2,
                                                                                     3.0, 0.3)]
    dwa = Dwa(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]]), config, obstacles)
    states, commands = _drive(dwa, np.array([0.0, -0.2, 0.6]), 120,
                              _circle_contact(obstacles))
    v, omega = commands[:, 0], commands[:, 1]
    assert np.all((v >= config.min_vel_x) & (v <= config.max_vel_x))
    assert np.all(np.abs(omega) <= config.max_vel_theta)
    dv, domega = np.diff(np.vstack([[0.0, 0.0], commands]), axis=0).T
    assert np.all(dv <= config.acc_lim_x * H + 1e-12)
    assert np.all(dv >= -config.decel_lim_x * H - 1e-12)
    assert np.all(np.abs(domega) <= config.acc_lim_theta * H + 1e-12)
    # The window binds (the robot would change faster if it could), and the run is not idle.
    assert np.any(np.isclose(dv, config.acc_lim_x * H))
    assert np.any(np.isclose(np.abs(domega), config.acc_lim_theta * H))
    assert np.hypot(*(states[-1, :2] - [2.0, 2.0])) < 0.1


def test_the_window_is_centred_on_the_given_velocity_or_the_last_command() -> None:
    config = _config(acc_lim_x=0.5, decel_lim_x=0.5, acc_lim_theta=1.0)
    dwa = Dwa(np.array([[0.0, 0.0], [3.0, 0.0]]), config)
    x = np.array([0.0, 0.0, 0.0])
    first = dwa.command(x)  # from rest: at most 0.1 m/s and 0.2 rad/s
    assert 0.0 < first[0] <= 0.1 + 1e-12 and abs(first[1]) <= 0.2 + 1e-12
    assert np.array_equal(dwa.velocity, first)
    measured = dwa.command(x, velocity=np.array([0.3, 1.0]))
    assert measured[0] >= 0.2 - 1e-12 and measured[1] >= 0.8 - 1e-12
    dwa.reset()
    assert np.array_equal(dwa.velocity, np.zeros(2)) and dwa.progress == 0.0


# --- safety --------------------------------------------------------------------------------


def test_stops_before_a_wall_straight_ahead_without_touching_it() -> None:
    wall = [ConvexPolygon.from_box(2.0, -2.0, 2.2, 2.0)]  # across the path, the goal behind
    dwa = Dwa(np.array([[0.0, 0.0], [4.0, 0.0]]), _config(), wall)
    states, commands = _drive(dwa, np.array([0.0, 0.0, 0.0]), 120, _circle_contact(wall))
    clearance = polygon_clearance(wall, RADIUS)(states[:, :2])
    assert np.all(clearance > 0.0)
    assert clearance[-1] < 0.2  # it drove up to the wall (from 1.85 m)...
    assert np.all(np.abs(commands[-10:]) < 1e-3)  # ...and stands there
    assert np.max(commands[:, 0]) == pytest.approx(Unicycle().v_max)  # at full speed before


def test_rectangular_footprint_drives_through_a_gap_its_circumscribed_circle_cannot() -> None:
    # 0.56 m between the walls: the Jackal is 0.43 m wide, its circumscribed circle 0.67 m.
    walls = [ConvexPolygon.from_box(1.0, 0.28, 3.0, 1.0), ConvexPolygon.from_box(1.0, -1.0,
                                                                                 3.0, -0.28)]
    dwa = Dwa(np.array([[0.0, 0.0], [4.0, 0.0]]), _config(footprint=JACKAL), walls)

    def contact(x: np.ndarray) -> bool:
        return any(_overlaps(JACKAL, x, wall) for wall in walls)

    states, _ = _drive(dwa, np.array([0.0, 0.02, 0.05]), 100, contact)
    assert states[-1, 0] > 3.8


def test_rectangular_footprint_turning_near_obstacles_never_overlaps_them() -> None:
    obstacles = [ConvexPolygon.from_box(0.9, 0.35, 1.3, 0.8),
                 ConvexPolygon.from_vertices([[1.8, -0.1], [2.3, -0.5], [2.4, 0.05]]),
                 ConvexPolygon.from_circle(1.5, 1.6, 0.2)]
    dwa = Dwa(np.array([[0.0, 0.0], [2.0, 0.5], [1.2, 2.2]]), _config(footprint=JACKAL),
              ObstacleSet(obstacles))

    def contact(x: np.ndarray) -> bool:
        return any(_overlaps(JACKAL, x, o) for o in obstacles)

    states, commands = _drive(dwa, np.array([0.0, 0.0, 0.0]), 150, contact)
    assert np.max(np.abs(commands[:, 1])) > 0.5  # it turned


def test_clearance_is_a_lower_bound_exact_at_contact() -> None:
    """The geometry under admissibility, against a brute-force oracle at random poses."""
    rng = np.random.default_rng(7)
    obstacles = [ConvexPolygon.from_box(0.0, 0.0, 0.4, 0.3),
                 ConvexPolygon.from_circle(1.0, 0.2, 0.25),
                 ConvexPolygon.from_vertices([[0.3, 0.9], [0.9, 0.7], [0.6, 1.3]])]
    for footprint in (Footprint.circle(0.2), JACKAL):
        dwa = Dwa(np.array([[0.0, 0.0], [1.0, 0.0]]), _config(footprint=footprint), obstacles)
        poses = np.column_stack([rng.uniform(-0.6, 1.6, 400), rng.uniform(-0.6, 1.6, 400),
                                 rng.uniform(-math.pi, math.pi, 400)])
        # Each pose an arc of one sample, every value asked to be exact.
        bound = dwa.clearance(np.array([0.5, 0.5]), poses[:, None, :2], poses[:, None, 2],
                               np.full(len(poses), np.inf))[:, 0]
        for pose, value in zip(poses, bound, strict=True):
            overlap = any(_overlaps(footprint, pose, o) if footprint.vertices is not None
                          else o.distance(pose[:2])[0] <= footprint.radius for o in obstacles)
            assert (value <= 0.0) == overlap
            if not overlap:
                outline = _outline(footprint, pose)
                true = min(float(np.min(o.distance(outline))) for o in obstacles)
                assert value <= true + 1e-9


def _outline(footprint: Footprint, pose: np.ndarray, per_edge: int = 200) -> np.ndarray:
    """Points densely along the footprint's boundary (its distance to a convex obstacle)."""
    corners = footprint.at(pose) if footprint.vertices is not None else None
    if corners is None:
        angles = np.linspace(0.0, 2 * math.pi, 720, endpoint=False)
        return pose[:2] + footprint.radius * np.column_stack([np.cos(angles), np.sin(angles)])
    t = np.linspace(0.0, 1.0, per_edge, endpoint=False)[:, None]
    ends = np.roll(corners, -1, axis=0)
    return np.vstack([a + t * (b - a) for a, b in zip(corners, ends, strict=True)])


# --- getting there ---------------------------------------------------------------------------


def test_reaches_a_goal_in_free_space() -> None:
    dwa = Dwa(np.array([[0.0, 0.0], [1.5, 1.0], [3.0, 1.0]]), _config())
    result = rollout(dwa, Unicycle(), np.array([0.0, 0.0, -0.5]), np.array([3.0, 1.0, 0.0]),
                     h=H, rule=StopRule(time_limit=40.0, position_tolerance=0.05))
    assert result.outcome is Outcome.REACHED
    length = math.hypot(1.5, 1.0) + 1.5
    assert result.end_time < 1.5 * length / Unicycle().v_max
    assert result.steps[-1].s == pytest.approx(1.0, abs=0.05)  # progress over the length


def test_goes_around_a_box_beside_a_straight_path() -> None:
    # The box reaches 0.1 m from the path: a round robot of radius 0.15 on it would touch.
    box = [ConvexPolygon.from_box(1.8, 0.1, 2.2, 0.6)]
    dwa = Dwa(np.array([[0.0, 0.0], [4.0, 0.0]]), _config(), box)
    result = rollout(dwa, Unicycle(), np.array([0.0, 0.0, 0.0]), np.array([4.0, 0.0, 0.0]),
                     h=H, rule=StopRule(time_limit=40.0, position_tolerance=0.05),
                     clearance=polygon_clearance(box, RADIUS))
    assert result.outcome is Outcome.REACHED
    beside = (result.rows[:, 1] > 1.8) & (result.rows[:, 1] < 2.2)
    assert np.max(result.rows[beside, 2]) < 0.1 - RADIUS  # it stepped aside
    states, _ = _drive(Dwa(np.array([[0.0, 0.0], [4.0, 0.0]]), _config(), box),
                       np.array([0.0, 0.0, 0.0]), len(result.rows), _circle_contact(box))
    assert states[-1, 0] > 3.9


def test_it_is_a_local_controller_like_pure_pursuit() -> None:
    dwa = Dwa(config=_config())
    assert isinstance(dwa, LocalController)
    assert dwa.compute(np.array([0.5, 0.0, 0.0]), None, 0.0).reason is Reason.NO_PLAN
    dwa.set_plan(np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]))
    output = dwa.compute(np.array([0.5, 0.0, 0.0]), None, 0.0)
    assert output.u[0] > 0.0 and output.reason is Reason.TRACKING
    assert output.progress == pytest.approx(0.25) and output.compute_time_s >= 0.0
    dwa.set_speed_limit(0.01)
    assert dwa.compute(np.array([0.5, 0.0, 0.0]), None, 0.2).u[0] <= 0.01
    dwa.reset()
    assert dwa.compute(np.array([0.5, 0.0, 0.0]), None, 0.4).reason is Reason.NO_PLAN


# --- invalid input --------------------------------------------------------------------------


@pytest.mark.parametrize('state', [[math.nan, 0.0, 0.0], [0.0, math.inf, 0.0],
                                   [0.0, 0.0, -math.inf], [0.0, 0.0]])
def test_invalid_state_gives_a_zero_command(state: list[float]) -> None:
    dwa = Dwa(np.array([[0.0, 0.0], [2.0, 0.0]]), _config())
    assert dwa.command(np.array([0.2, 0.0, 0.0]))[0] > 0.0
    u = dwa.command(np.array(state))
    assert np.array_equal(u, np.zeros(2)) and np.array_equal(dwa.velocity, np.zeros(2))
    assert dwa.command(np.array([0.2, 0.0, 0.0]))[0] > 0.0  # and it goes on from rest


def test_invalid_velocity_gives_a_zero_command() -> None:
    dwa = Dwa(np.array([[0.0, 0.0], [2.0, 0.0]]), _config())
    u = dwa.command(np.array([0.0, 0.0, 0.0]), velocity=np.array([math.nan, 0.0]))
    assert np.array_equal(u, np.zeros(2))


def test_degenerate_paths_are_refused() -> None:
    with pytest.raises(ValueError):
        Dwa(np.array([[1.0, 1.0], [1.0, 1.0]]))
    dwa = Dwa(np.array([[0.0, 0.0], [1.0, 0.0]]))
    with pytest.raises(ValueError):
        dwa.set_path(np.array([[0.0, math.nan], [1.0, 0.0]]))
