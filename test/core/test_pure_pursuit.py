# SPDX-License-Identifier: Apache-2.0
"""The pure-pursuit baselines, the classic follower and Nav2's regulated one.

The classic follower reaches the end of simple paths within the unicycle's bounds; the
regulated one (RPP) scales its lookahead and speed as Nav2 does and checks its arc.
"""

import numpy as np
import pytest

from mpc_local_planner.core.baselines.pure_pursuit import PurePursuit, PurePursuitConfig
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.obstacles import ConvexPolygon


def _follow(waypoints, start, steps=2000, h=0.1):
    model = Unicycle()
    follower = PurePursuit(np.array(waypoints, dtype=float),
                           PurePursuitConfig(v_max=model.v_max, omega_max=model.omega_max))
    x = np.array(start, dtype=float)
    inputs = []
    for _ in range(steps):
        u = follower.command(x)
        inputs.append(u)
        if not np.any(u):
            break
        x = model.step(x, u, h)
    return x, np.array(inputs), follower


def test_straight_path_is_followed_to_its_end() -> None:
    x, inputs, _ = _follow([[0, 0], [3, 0]], [0, 0, 0])
    assert np.hypot(x[0] - 3, x[1]) <= 0.03
    assert not np.any(inputs[-1])  # stopped at the end
    assert np.all(np.abs(inputs[:, 0]) <= 0.31 + 1e-12)
    assert np.all(np.abs(inputs[:, 1]) <= 1.9 + 1e-12)


def test_l_shaped_path_is_followed_to_its_end_close_to_the_corner() -> None:
    x, inputs, follower = _follow([[0, 0], [2, 0], [2, 2]], [0, 0.1, 0.5])
    assert np.hypot(x[0] - 2, x[1] - 2) <= 0.03
    assert follower.progress == pytest.approx(follower.length, abs=0.05)
    assert np.all(np.abs(inputs[:, 1]) <= 1.9 + 1e-12)


def test_robot_facing_away_turns_in_place_first() -> None:
    follower = PurePursuit(np.array([[0.0, 0.0], [2.0, 0.0]]))
    u = follower.command(np.array([0.0, 0.0, np.pi]))
    assert u[0] == 0.0 and abs(u[1]) == pytest.approx(1.9)


def test_degenerate_paths_and_settings_are_refused() -> None:
    with pytest.raises(ValueError):
        PurePursuit(np.array([[1.0, 1.0], [1.0, 1.0]]))
    with pytest.raises(ValueError):
        PurePursuitConfig(lookahead=0.0)


# --- Nav2's Regulated Pure Pursuit (PurePursuitConfig.regulated) --------------------------

JACKAL_V, JACKAL_OMEGA = 2.0, 4.0
STRAIGHT = np.array([[0.0, 0.0], [5.0, 0.0]])


def _regulated(waypoints=STRAIGHT, footprint=JACKAL):
    config = PurePursuitConfig.regulated(JACKAL_V, JACKAL_OMEGA, footprint=footprint)
    return PurePursuit(np.array(waypoints, dtype=float), config)


def test_the_lookahead_scales_with_the_measured_speed_within_nav2s_bounds() -> None:
    follower = _regulated()
    assert [follower.lookahead(v) for v in (0.0, 0.4, -0.4, 2.0)] == pytest.approx(
        [0.3, 0.6, 0.6, 0.9])
    assert PurePursuit(STRAIGHT).lookahead(2.0) == 0.4  # the classic one is fixed
    # without a measured speed, the last command's: at rest the shortest, then at speed
    follower.command(np.array([0.0, 0.0, 0.0]))
    assert follower.command(np.array([0.0, 0.0, 0.0]))[0] == pytest.approx(JACKAL_V)


def test_the_speed_is_regulated_by_the_arcs_curvature_as_nav2_does() -> None:
    follower = _regulated()
    x = np.array([0.0, -0.2, 0.0])  # 0.2 m right of the path, heading along it
    v, omega = follower.command(x, velocity=np.zeros(2))  # lookahead 0.3: aim at (0.3, 0)
    aim_y, aim_distance2 = 0.2, 0.3**2 + 0.2**2  # the aim point in the robot's frame
    curvature = 2.0 * aim_y / aim_distance2
    assert v == pytest.approx(JACKAL_V * (1.0 / curvature) / 0.9)  # radius / min_radius
    assert omega == pytest.approx(v * curvature)
    # on the path, far from its end: full speed, no turn
    v, omega = _regulated().command(np.zeros(3), velocity=np.array([2.0, 0.0]))
    assert (v, omega) == (pytest.approx(JACKAL_V), pytest.approx(0.0))


def test_the_regulated_speed_keeps_its_floor_and_slows_on_the_approach() -> None:
    slow = PurePursuit(STRAIGHT, PurePursuitConfig.regulated(0.5, 4.0, footprint=JACKAL))
    # the arc of the curvature test (radius 0.325 m) would mean 0.18 m/s at 0.5 m/s: the
    # regulation's floor is 0.25 (regulated_linear_scaling_min_speed)
    v, omega = slow.command(np.array([0.0, -0.2, 0.0]), velocity=np.zeros(2))
    curvature = 2.0 * 0.2 / (0.3**2 + 0.2**2)
    assert 0.5 * (1.0 / curvature) / 0.9 < 0.25
    assert v == pytest.approx(0.25) and omega == pytest.approx(0.25 * curvature)
    # 0.3 m before the end: the speed scaled by 0.3 / 0.6 (approach_velocity_scaling_dist)
    short = _regulated([[0.0, 0.0], [0.3, 0.0]])
    v, _ = short.command(np.zeros(3), velocity=np.array([2.0, 0.0]))
    assert v == pytest.approx(JACKAL_V * 0.3 / 0.6)


def test_a_collision_on_the_commanded_arc_within_the_lookahead_stops_the_robot() -> None:
    x, moving = np.array([0.0, 0.0, 0.0]), np.array([2.0, 0.0])
    near = ConvexPolygon.from_box(1.0, -0.1, 1.2, 0.1)  # the nose reaches 0.254 + 0.9 m
    far = ConvexPolygon.from_box(1.2, -0.1, 1.4, 0.1)
    follower = _regulated()
    follower.set_obstacles([near])
    assert not follower.command(x, velocity=moving).any() and follower.collision_ahead
    follower.set_obstacles([far])  # beyond the aim point: not checked yet
    assert follower.command(x, velocity=moving)[0] > 0.0 and not follower.collision_ahead
    classic = PurePursuit(STRAIGHT, PurePursuitConfig(v_max=2.0, omega_max=4.0))
    classic.set_obstacles([near])  # the classic follower has no collision detection
    assert classic.command(x)[0] > 0.0


def test_a_robot_already_touching_an_obstacle_gets_no_command_as_in_nav2() -> None:
    follower = _regulated()
    # a post 4 mm into the rectangle's back: every pose ahead clears it, the pose now does not
    follower.set_obstacles([ConvexPolygon.from_box(-0.26, -0.02, -0.25, 0.02)])
    assert not follower.command(np.zeros(3), velocity=np.array([2.0, 0.0])).any()
    assert follower.collision_ahead


def test_a_turn_in_place_that_would_sweep_into_an_obstacle_is_refused() -> None:
    behind = np.array([[0.0, 0.0], [-3.0, 0.0]])
    x = np.array([0.0, 0.0, 0.0])  # facing away from the path: it rotates to it
    follower = _regulated(behind)
    v, omega = follower.command(x)
    assert v == 0.0 and abs(omega) == pytest.approx(1.8)  # rotate_to_heading_angular_vel
    # a post 0.27-0.31 m ahead: the nose clears it, the corners (0.333 m out) do not
    follower.set_obstacles([ConvexPolygon.from_box(0.27, -0.02, 0.31, 0.02)])
    assert not follower.command(x).any() and follower.collision_ahead


@pytest.mark.parametrize('field, value', [
    ('lookahead_time', -1.0), ('regulated_min_radius', float('nan')),
    ('collision_time', float('inf')), ('min_lookahead', 0.0), ('turn_rate', -0.1)])
def test_bad_regulation_settings_are_refused(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        PurePursuitConfig(**{field: value})
    with pytest.raises(ValueError, match='min_lookahead must be <= max_lookahead'):
        PurePursuitConfig(min_lookahead=1.0, max_lookahead=0.5)
    with pytest.raises(ValueError, match='footprint of some size'):
        PurePursuitConfig(collision_time=1.0)  # a point robot: no outline to check
