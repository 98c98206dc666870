# SPDX-License-Identifier: Apache-2.0
"""The world at a time: the laser sees moving obstacles where they are; contacts told apart."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.evaluation.rollout import ControlStep, Outcome, rollout, StopRule
from mpc_local_planner.sim.contact import footprint_distances
from mpc_local_planner.sim.laser import SimulatedLaser
from mpc_local_planner.sim.moving import ContactCounter, ContactKind, WorldClock
from mpc_local_planner.worlds.world import World, world_from_dict

ROBOT = Footprint.circle(0.2)


def crossing_world(trajectory: dict[str, Any], radius: float = 0.3) -> World:
    return world_from_dict({'bounds': [-1.0, 10.0, -3.0, 3.0], 'start': [0.0, 0.0, 0.0],
                            'goal': [9.0, 0.0, 0.0], 'obstacles': [{'box': [8.0, 2.0, 9.0, 3.0]}],
                            'moving_obstacles': [{'circle': [0.0, 0.0, radius], **trajectory}]},
                           name='crossing')


def test_the_laser_sees_a_moving_circle_where_it_is_at_the_scans_time() -> None:
    # a disk crossing the laser's forward axis at x = 4: at y = 0 at t = 0 and t = 2
    world = crossing_world({'sinusoid': {'centre': [4.0, 0.0], 'amplitude': [0.0, 2.0],
                                         'period': 4.0}})
    laser = SimulatedLaser(WorldClock.from_world(world), beams=721, fov=math.pi)
    ahead = 360  # the middle beam looks along +x
    at_zero = laser.scan((0.0, 0.0, 0.0), stamp=0.0)
    assert at_zero.ranges[ahead] == pytest.approx(4.0 - 0.3)
    # at t = 1 it is at y = 2: the beam towards (4, 2) hits it, the forward one does not
    later = laser.scan((0.0, 0.0, 0.0), stamp=1.0)
    assert math.isinf(later.ranges[ahead])
    towards = ahead + round(math.atan2(2.0, 4.0) / later.angle_increment)
    assert later.ranges[towards] == pytest.approx(math.hypot(4.0, 2.0) - 0.3, abs=2e-3)
    # the same t gives the same scan, to the last digit
    again = laser.scan((0.0, 0.0, 0.0), stamp=1.0)
    assert np.array_equal(again.ranges, later.ranges)


def test_a_world_without_moving_obstacles_keeps_its_one_static_geometry() -> None:
    world = world_from_dict({'bounds': [0, 4, 0, 4], 'start': [0.5, 0.5, 0.0],
                             'goal': [3.5, 3.5, 0.0], 'obstacles': [{'circle': [2, 2, 0.5]}]},
                            name='still')
    clock = WorldClock.from_world(world)
    assert clock.at(0.0) is clock.static and clock.at(7.3) is clock.static
    assert len(clock.static) == 1


def test_the_contact_check_sees_the_moving_obstacle_at_the_time_asked() -> None:
    world = crossing_world({'constant_velocity': {'start': [3.0, -2.0], 'velocity': [0.0, 1.0]}})
    clock = WorldClock.from_world(world)
    robot = np.array([[3.0, 0.0, 0.0]])
    assert footprint_distances(clock.at(0.0), ROBOT, robot)[0] == pytest.approx(2.0 - 0.5)
    assert footprint_distances(clock.at(2.0), ROBOT, robot)[0] == pytest.approx(-0.5)


def test_the_contact_counter_counts_episodes_by_who_caused_them() -> None:
    counter = ContactCounter()
    assert counter.update(True, 0.5, 0.0) is ContactKind.ACTIVE
    assert counter.update(True, 0.0, 0.0) is None  # the same episode
    assert counter.update(False, 0.0, 0.0) is None
    assert counter.update(True, 0.0, 0.001) is ContactKind.PASSIVE  # hit while standing
    assert counter.update(False, 0.0, 0.0) is None
    assert counter.update(True, 0.0, 0.3) is ContactKind.ACTIVE  # turning in place sweeps
    assert (counter.active, counter.passive, counter.total) == (2, 1, 3)


class Constant:
    """A controller that always commands the same input."""

    def __init__(self, u: tuple[float, float]) -> None:
        self.u = np.array(u, dtype=float)

    def step(self, x: np.ndarray) -> ControlStep:
        return ControlStep(u=self.u)


def crossing_rollout(world: World, u: tuple[float, float]) -> Any:
    clock = WorldClock.from_world(world)

    def clearance_at(pose: np.ndarray, t: float) -> float:
        return float(footprint_distances(clock.at(t), ROBOT, pose[None, :3])[0])

    rule = StopRule(time_limit=20.0, position_tolerance=0.1, stall_steps=10_000)
    return rollout(Constant(u), Unicycle(v_max=1.0), world.start, world.goal, h=0.1, rule=rule,
                   clearance_at=clearance_at)


def test_a_robot_driving_into_a_crossing_obstacle_has_an_active_contact() -> None:
    # the walker crosses y = 0 at x = 3 at t = 2 .. 3; the robot at 1 m/s gets there then
    world = crossing_world({'waypoints': {'points': [[3.0, -2.5], [3.0, 2.5]],
                                          'speed': 1.0}})
    run = crossing_rollout(world, (1.0, 0.0))
    assert run.outcome is Outcome.COLLISION
    assert run.contact is ContactKind.ACTIVE


def test_a_stopped_robot_hit_by_a_crossing_obstacle_has_a_passive_contact() -> None:
    world = crossing_world({'waypoints': {'points': [[0.0, -2.5], [0.0, 2.5]],
                                          'speed': 1.0}})
    run = crossing_rollout(world, (0.0, 0.0))
    assert run.outcome is Outcome.COLLISION
    assert run.contact is ContactKind.PASSIVE
    assert run.end_time == pytest.approx(2.0, abs=0.11)  # 2.5 - 0.5 m at 1 m/s


def test_a_static_clearance_run_is_unchanged_by_the_moving_path() -> None:
    world = crossing_world({'waypoints': {'points': [[0.0, -2.5], [0.0, 2.5]],
                                          'speed': 1.0}})
    rule = StopRule(time_limit=2.0, position_tolerance=0.1, stall_steps=10_000)
    run = rollout(Constant((1.0, 0.0)), Unicycle(), world.start, world.goal, h=0.1, rule=rule)
    assert run.outcome is Outcome.TIME_LIMIT and run.contact is None
