# SPDX-License-Identifier: Apache-2.0
"""The dynamic suite's worlds: BARN-like static clutter and cylinders that move, from a seed.

Following DynaBARN's description (Nair et al. 2022, the moving-obstacle worlds the BARN
challenge added in 2025): each world is a 12 m x 6 m field with start (0, 0, 0) and goal
(10, 0, 0), static cylinders that no map holds (the laser finds them, as in BARN), and
cylinders of radius 0.15-0.5 m moving at 0.2-1.5 m/s on the three motion profiles of
worlds/motion.py: constant velocity reflected off a box, a loop of waypoints (DynaBARN's
smooth polynomial paths, here as polylines), and a sinusoid across the route. World
`index` of `DYNAMIC_WORLDS` grows harder with it, by the number of moving cylinders (2 to 8)
and their top speed (0.5 to 1.5 m/s).

Every world is written as a world file's mapping and read by `world_from_dict`, so what a
suite runs is what a world file says (and a run through the nodes can write it out). A draw is
kept when the moving cylinders stay off the start's and the goal's surroundings (no robot
is run into while it waits there, and none stands on the goal) and a path exists among the
static cylinders (RRT* as the suites plan), so every world can be solved by waiting for a gap.
"""

from __future__ import annotations

from dataclasses import replace
import math
from typing import Any

import numpy as np

from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.planner import RrtStarPlanner
from mpc_local_planner.core.planner_config import PlannerConfig
from mpc_local_planner.worlds.world import World, world_from_dict

__all__ = [
    'DYNAMIC_WORLDS',
    'dynamic_world',
    'dynamic_world_data',
    'PROFILES',
]

# The suite's size: DynaBARN has 60 worlds.
DYNAMIC_WORLDS = 60
# The field, the start and the goal (BARN's 10 m run, along +x).
BOUNDS = (-1.0, 11.0, -3.0, 3.0)
START = (0.0, 0.0, 0.0)
GOAL = (10.0, 0.0, 0.0)
# Moving cylinders keep within these x (the start's and the goal's surroundings stay clear).
MOVING_X = (1.5, 8.5)
# Static cylinders: how many, their radii, and how far they keep from the start and goal.
STATIC_COUNT = 8
STATIC_RADIUS = (0.1, 0.2)
STATIC_CLEAR = 1.0
# Moving cylinders: radius range, slowest speed, and the top speed from easy to hard.
MOVING_RADIUS = (0.15, 0.5)
MIN_SPEED = 0.2
TOP_SPEED = (0.5, 1.5)
MOVING_COUNT = (2, 8)
# The motion profiles, in the order the cylinders of a world take them.
PROFILES = ('constant_velocity', 'waypoints', 'sinusoid')
# Seconds a run may take: the 10 m at a walking pace, with waits for gaps.
TIME_LIMIT = 60.0
# Draws tried per world before giving up (a draw fails only when no static path exists).
ATTEMPTS = 50
# The solvability check's planner (as the suites plan for the Jackal).
CHECK_ITERATIONS = 3000
CHECK_RANGE = 0.5
CHECK_CLEARANCE = 0.05


def difficulty(index: int) -> float:
    """Return world index's difficulty in [0, 1] (the last world of the suite is 1)."""
    return min(max(index, 0) / (DYNAMIC_WORLDS - 1), 1.0)


def dynamic_world_data(index: int, seed: int, rng: np.random.Generator | None = None
                       ) -> dict[str, Any]:
    """Return one draw of world index as a world file's mapping (no solvability check).

    rng: the draw's generator (default: seeded by seed and index, the first draw).
    """
    rng = rng if rng is not None else np.random.default_rng([seed, index, 35])
    level = difficulty(index)
    statics = []
    while len(statics) < STATIC_COUNT:
        x, y = rng.uniform(1.0, 9.0), rng.uniform(-2.6, 2.6)
        if min(math.dist((x, y), START[:2]), math.dist((x, y), GOAL[:2])) > STATIC_CLEAR:
            statics.append({'circle': [round(float(x), 3), round(float(y), 3),
                                       round(float(rng.uniform(*STATIC_RADIUS)), 3)]})
    count = MOVING_COUNT[0] + int(round(level * (MOVING_COUNT[1] - MOVING_COUNT[0])))
    top = TOP_SPEED[0] + level * (TOP_SPEED[1] - TOP_SPEED[0])
    moving = [_moving_cylinder(PROFILES[(index + j) % len(PROFILES)], rng, top)
              for j in range(count)]
    return {'bounds': list(BOUNDS), 'obstacles': [], 'unknown_obstacles': statics,
            'moving_obstacles': moving, 'start': list(START), 'goal': list(GOAL),
            'time_limit': TIME_LIMIT}


def _moving_cylinder(profile: str, rng: np.random.Generator, top: float) -> dict[str, Any]:
    """Return a moving cylinder's world-file entry on the profile, within MOVING_X."""
    radius = float(rng.uniform(*MOVING_RADIUS))
    speed = float(rng.uniform(MIN_SPEED, top))
    xlow, xhigh = MOVING_X[0] + radius, MOVING_X[1] - radius
    ylow, yhigh = BOUNDS[2] + radius, BOUNDS[3] - radius
    entry: dict[str, Any] = {'circle': [0.0, 0.0, round(radius, 3)]}
    if profile == 'constant_velocity':
        heading = float(rng.uniform(-math.pi, math.pi))
        entry['constant_velocity'] = {
            'start': [float(rng.uniform(xlow, xhigh)), float(rng.uniform(ylow, yhigh))],
            'velocity': [speed * math.cos(heading), speed * math.sin(heading)],
            'bounds': [MOVING_X[0], MOVING_X[1], BOUNDS[2], BOUNDS[3]]}
    elif profile == 'waypoints':
        points = [[float(rng.uniform(xlow, xhigh)), float(rng.uniform(ylow, yhigh))]
                  for _ in range(int(rng.integers(3, 5)))]
        entry['waypoints'] = {'points': points, 'speed': speed, 'mode': 'loop'}
    else:  # a sinusoid across the route, its swing inside the field
        centre = np.array([rng.uniform(xlow + 0.5, xhigh - 0.5), rng.uniform(-1.0, 1.0)])
        angle = math.pi / 2 + float(rng.uniform(-0.6, 0.6))
        direction = np.array([math.cos(angle), math.sin(angle)])
        room = min((xhigh - centre[0]) / max(abs(direction[0]), 1e-9),
                   (centre[0] - xlow) / max(abs(direction[0]), 1e-9),
                   (yhigh - abs(centre[1])) / abs(direction[1]))
        length = float(min(rng.uniform(1.0, 2.2), room))
        entry['sinusoid'] = {'centre': centre.tolist(), 'amplitude': (length * direction).tolist(),
                             'period': 2.0 * math.pi * length / speed,  # top speed = speed
                             'phase': float(rng.uniform(0.0, 2.0 * math.pi))}
    return entry


def dynamic_world(index: int, seed: int, *, footprint: Footprint | None = None) -> World:
    """Return world index of the dynamic suite seeded by seed (reproducible).

    footprint: the robot's `Footprint` (the world's, for the planner's check and the runs);
    None: a point robot's check.

    Raises:
        ValueError: for a negative index.
        RuntimeError: if no draw in ATTEMPTS has a path among its static cylinders.

    """
    if index < 0:
        msg = f'dynamic world index must be >= 0, got {index}'
        raise ValueError(msg)
    rng = np.random.default_rng([seed, index, 35])
    radius = footprint.radius if footprint is not None else 0.0
    for _ in range(ATTEMPTS):
        world = world_from_dict(dynamic_world_data(index, seed, rng),
                                name=f'dynamic_{index:03d}')
        config = PlannerConfig(iterations=CHECK_ITERATIONS, seed=index, range=CHECK_RANGE,
                               robot_radius=radius, clearance=CHECK_CLEARANCE)
        try:
            RrtStarPlanner(list(world.unknown_obstacles), BOUNDS, config=config).plan(
                np.array(START), np.array(GOAL))
        except PlanningError:
            continue
        if footprint is not None:
            world = replace(world, footprint=footprint, robot_radius=0.0)
        return world
    msg = f'dynamic world {index} (seed {seed}): no solvable draw in {ATTEMPTS}'
    raise RuntimeError(msg)
