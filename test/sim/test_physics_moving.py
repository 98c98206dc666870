# SPDX-License-Identifier: Apache-2.0
"""The MuJoCo plant moves the world's moving obstacles: its laser sees them, they push."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.sim.laser import SimulatedLaser
from mpc_local_planner.sim.moving import WorldClock
from mpc_local_planner.sim.reality import Reality
from mpc_local_planner.worlds.world import World, world_from_dict

mujoco = pytest.importorskip('mujoco', reason='the [physics] extra is not installed')

from mpc_local_planner.sim.physics.plant import PhysicsBase  # noqa: E402 (needs mujoco)


def walkers() -> World:
    """A disk swinging across the robot's forward axis and a box sliding beside it."""
    return world_from_dict({
        'bounds': [-5.0, 5.0, -5.0, 5.0], 'start': [0.0, 0.0, 0.0], 'goal': [4.0, 0.0, 0.0],
        'obstacles': [{'circle': [-3.0, 0.0, 0.3]}],
        'moving_obstacles': [
            {'circle': [0.0, 0.0, 0.3],
             'sinusoid': {'centre': [3.0, 0.0], 'amplitude': [0.0, 2.0], 'period': 4.0}},
            {'polygon': [[-0.3, -0.2], [0.3, -0.2], [0.3, 0.2], [-0.3, 0.2]],
             'constant_velocity': {'start': [0.0, 2.5], 'velocity': [1.0, 0.0]}}]},
        name='walkers')


def test_the_engines_laser_sees_moving_obstacles_where_the_exact_laser_does() -> None:
    world = walkers()
    base = PhysicsBase(Unicycle(v_max=2.0, omega_max=4.0), Reality(), world.start,
                       robot='jackal', footprint=JACKAL, shapes=world.physical_shapes(),
                       moving=world.moving_obstacles)
    laser = base.laser(fov=2.0 * math.pi, beams=361, range_min=0.05, range_max=10.0)
    exact = SimulatedLaser(WorldClock.from_world(world), fov=2.0 * math.pi, beams=361,
                           range_min=0.05, range_max=10.0)
    seen = []
    for t in (0.0, 0.5, 1.3, 2.0):
        base.advance(t)
        scan, reference = laser.scan(base.pose, stamp=t), exact.scan(base.pose, stamp=t)
        hit = np.isfinite(reference.ranges)
        assert np.array_equal(np.isfinite(scan.ranges), hit), t
        assert np.max(np.abs(scan.ranges[hit] - reference.ranges[hit])) < 1e-6, t
        seen.append(scan.ranges)
    assert not np.array_equal(seen[0], seen[1])  # they moved between the scans


def test_a_moving_obstacle_pushes_a_robot_that_stands_in_its_way() -> None:
    world = world_from_dict({
        'bounds': [-5.0, 5.0, -5.0, 5.0], 'start': [0.0, 0.0, 0.0], 'goal': [4.0, 0.0, 0.0],
        'moving_obstacles': [{'circle': [0.0, 0.0, 0.3],
                              'constant_velocity': {'start': [0.0, 2.0],
                                                    'velocity': [0.0, -0.5]}}]},
        name='pusher')
    base = PhysicsBase(Unicycle(v_max=2.0, omega_max=4.0), Reality(), world.start,
                       robot='jackal', footprint=JACKAL, moving=world.moving_obstacles)
    base.advance(6.0)  # it reaches the robot's side (y = 0.215 + 0.3) at t = 2.97
    assert base.pose[1] < -0.5  # shoved along, the mocap body is not pushed back
