# SPDX-License-Identifier: Apache-2.0
"""The controller's ``footprint`` parameter: precedence, validation, mpc/footprint, reach.

Nav2's precedence, as the simulator and the planner apply it: the parameter's polygon, else
the world file's polygon, else a circle of robot_radius. The DDS tests own the node's inputs
(odometry, a map) and spin until what they wait for arrives.
"""

from __future__ import annotations

import math

from geometry_msgs.msg import PolygonStamped
from nav_msgs.msg import OccupancyGrid
import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter

from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.ros.conversions import yaw_to_quaternion
from mpc_local_planner.ros.mpc_controller_node import FOOTPRINT_TOPIC, MpcControllerNode
from mpc_local_planner.ros.mpc_controller_parameters import (
    build_settings,
    DEFAULTS,
    robot_footprint,
)
from mpc_local_planner.ros.node_main import autostart
from mpc_local_planner.ros.qos import LOCAL_PLAN_QOS, MAP_QOS
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import load_world

NARROW_GAP = load_world(resolve_data_file('narrow_gap'))  # the Jackal's rectangle
JACKAL_TUPLE = tuple((float(x), float(y)) for x, y in JACKAL.vertices)
TRIANGLE = '[[0.3, 0.0], [-0.2, 0.2], [-0.2, -0.2]]'
NOT_CONVEX = '[[0.3, 0.2], [-0.3, 0.2], [0.0, 0.0], [-0.3, -0.2], [0.3, -0.2]]'


# ----------------------------------------------------------------------------- precedence
def test_the_parameters_polygon_then_the_worlds_then_the_circle() -> None:
    # '' (and Nav2's '[]'): the world's polygon
    assert robot_footprint('', NARROW_GAP.footprint) == JACKAL_TUPLE
    assert robot_footprint('[]', NARROW_GAP.footprint) == JACKAL_TUPLE
    # a polygon parameter wins over the world's
    triangle = robot_footprint(TRIANGLE, NARROW_GAP.footprint)
    assert len(triangle) == 3 and triangle != JACKAL_TUPLE
    # no polygon anywhere: a round robot
    assert robot_footprint('', Footprint.circle(0.2)) == ()
    assert robot_footprint('', None) == ()


def test_build_settings_puts_the_footprint_into_the_mpc_config() -> None:
    values = dict(DEFAULTS)
    config, _, _ = build_settings(values, world_radius=NARROW_GAP.robot_radius,
                                  world_footprint=NARROW_GAP.footprint)
    np.testing.assert_allclose(config.robot_footprint.vertices, JACKAL.vertices)
    # a polygon's reach counts its circumscribed radius: the inflation no longer does
    v_max = DEFAULTS['v_max']
    assert config.inflation(v_max) == 0.0
    assert config.reach(v_max) == pytest.approx(v_max * 0.2 * 10 + JACKAL.radius)
    round_config, _, _ = build_settings({**values, 'robot_radius': 0.25})
    assert round_config.footprint == () and round_config.robot_footprint.radius == 0.25


def test_allow_reversing_false_keeps_the_mpc_speed_at_or_above_zero() -> None:
    _, model, _ = build_settings(dict(DEFAULTS))
    assert DEFAULTS['allow_reversing'] is True  # the paper's robot drives backwards too
    np.testing.assert_allclose(model.u_min, [-DEFAULTS['v_max'], -DEFAULTS['omega_max']])
    _, forwards, _ = build_settings({**DEFAULTS, 'allow_reversing': False})
    np.testing.assert_allclose(forwards.u_min, [0.0, -DEFAULTS['omega_max']])
    np.testing.assert_allclose(forwards.u_max, model.u_max)


@pytest.mark.parametrize(('text', 'reason'), [
    ('[[0, 0], [1, 1]]', 'at least 3'),
    (NOT_CONVEX, 'not convex'),
    ('[[0.1, 0.1], [0.2, 0.2], [0.3, 0.3]]', 'collinear'),
    ('not a polygon', 'not of the form'),
    ('[[0.1, 0.1], [-0.1, .nan], [0.1, -0.1]]', 'finite'),
])
def test_a_bad_footprint_is_refused_with_its_reason(text: str, reason: str) -> None:
    with pytest.raises(ValueError, match=reason) as caught:
        build_settings({**DEFAULTS, 'footprint': text})
    assert str(caught.value).startswith('footprint ')


# ----------------------------------------------------------------------------- over DDS
class Listener(Node):
    """Keeps the controller's mpc/footprint messages."""

    def __init__(self, context) -> None:
        super().__init__('footprint_listener', context=context)
        self.footprints: list[PolygonStamped] = []
        self.create_subscription(PolygonStamped, FOOTPRINT_TOPIC, self.footprints.append,
                                 LOCAL_PLAN_QOS)

    def corners(self) -> np.ndarray:
        return np.array([[p.x, p.y] for p in self.footprints[-1].polygon.points])


@pytest.mark.dds
def test_mpc_footprint_shows_the_polygon_in_force_and_a_bad_one_is_refused(ros) -> None:
    node = ros.add(MpcControllerNode(context=ros.context, parameter_overrides=[
        Parameter('world_file', value='narrow_gap')]))
    assert autostart(node) is None
    listener = ros.add(Listener(ros.context))
    probe = ros.probe()
    pose = np.array([1.0, -0.2, 0.4])

    def shows(vertices: np.ndarray) -> bool:
        probe.publish_odom(pose)  # fresh odometry: the footprint is drawn at it
        return (bool(listener.footprints) and len(listener.corners()) == len(vertices)
                and np.allclose(listener.corners(), vertices, atol=1e-6))

    # the world's rectangle, turned with the heading
    assert ros.spin_until(lambda: shows(JACKAL.at(pose)), timeout=30.0)
    assert listener.footprints[-1].header.frame_id == 'map'
    # at run time: a polygon replaces it (the NLP is rebuilt), a bad one is refused
    [result] = node.set_parameters([Parameter('footprint', value=TRIANGLE)])
    assert result.successful, result.reason
    triangle = Footprint.polygon([[0.3, 0.0], [-0.2, 0.2], [-0.2, -0.2]])
    assert ros.spin_until(lambda: shows(triangle.at(pose)), timeout=30.0)
    [refused] = node.set_parameters([Parameter('footprint', value=NOT_CONVEX)])
    assert not refused.successful and 'not convex' in refused.reason
    assert node.get_parameter('footprint').value == TRIANGLE
    assert len(node.controller.config.footprint) == 3
    # '' falls back to the world's polygon
    [back] = node.set_parameters([Parameter('footprint', value='')])
    assert back.successful, back.reason
    assert ros.spin_until(lambda: shows(JACKAL.at(pose)), timeout=30.0)


def grid_with_block(xmin: float, xmax: float, ymin: float, ymax: float) -> OccupancyGrid:
    """A 4 m x 4 m map around the origin at 0.05 m, occupied in the given box."""
    resolution, size = 0.05, 80
    msg = OccupancyGrid()
    msg.header.frame_id = 'map'
    msg.info.width = msg.info.height = size
    msg.info.resolution = resolution
    msg.info.origin.position.x = msg.info.origin.position.y = -2.0
    msg.info.origin.orientation = yaw_to_quaternion(0.0)
    centres = -2.0 + resolution * (np.arange(size) + 0.5)
    xs, ys = np.meshgrid(centres, centres)  # rows: y, columns: x
    occupied = (xs > xmin) & (xs < xmax) & (ys > ymin) & (ys < ymax)
    msg.data = [100 if cell else 0 for cell in occupied.ravel()]
    return msg


@pytest.mark.dds
def test_map_obstacles_a_polygons_corner_can_reach_are_handed_to_the_mpc(ros) -> None:
    # horizon travel 0.31 m/s x 0.2 s x 10 = 0.62 m, no inflation for a polygon, margin 0.5 m:
    # without the Jackal's circumscribed radius (0.333 m) the window would end at 1.12 m and
    # leave out the block 1.25 m ahead, which a corner of the turning rectangle can reach
    node = ros.add(MpcControllerNode(context=ros.context, parameter_overrides=[
        Parameter('world_file', value=''), Parameter('obstacle_sources', value=['map']),
        Parameter('footprint', value=str(JACKAL.vertices.tolist()))]))
    assert autostart(node) is None
    probe = ros.probe()
    io = ros.add(Node('map_probe', context=ros.context))
    map_pub = io.create_publisher(OccupancyGrid, 'map', MAP_QOS)
    map_pub.publish(grid_with_block(1.25, 1.35, -0.1, 0.1))
    reach = node.controller.config.reach(0.31)
    assert 1.12 < 1.25 < reach + 0.5 - 0.1

    def sees_block() -> bool:
        probe.publish_odom(np.zeros(3))
        return any(math.isclose(float(np.min(o.vertices[:, 0])), 1.25, abs_tol=0.03)
                   for o in node.controller.obstacles)

    assert ros.spin_until(sees_block, timeout=30.0)


def test_max_solve_time_reaches_the_mpc_config_and_minus_one_means_half_the_step() -> None:
    config, _, _ = build_settings({**DEFAULTS, 'max_solve_time': 0.05})
    assert config.solving.max_solve_time == 0.05 and config.solve_budget() == 0.05
    config, _, _ = build_settings(dict(DEFAULTS))
    assert config.solving.max_solve_time is None and config.solve_budget() == DEFAULTS['step'] / 2


def test_the_flat_parameters_fill_the_solver_settings_and_every_reason_is_given() -> None:
    config, _, _ = build_settings({**DEFAULTS, 'solver': 'ipopt', 'max_iterations': 50,
                                   'obstacle_slots': 2})
    assert (config.solving.solver, config.solving.max_iterations,
            config.solving.obstacle_slots) == ('ipopt', 50, 2)
    # a problem value and a solver value both wrong: both reasons, not the first only
    with pytest.raises(ValueError, match=r'solver must be one of .*step must be > 0'):
        build_settings({**DEFAULTS, 'solver': 'sqp', 'step': 0.0})
