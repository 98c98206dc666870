# SPDX-License-Identifier: Apache-2.0
"""Known-map scenarios: the worlds of the ``random`` and ``barn`` suites without sensing.

A known-map scenario is the easier setting of `evaluate`: every obstacle is known from the
start, the robot is a circle of radius ROBOT_RADIUS, and RRT* plans the reference path once,
on the true map, before the run (the controller never re-plans). Each scenario records
whether that path satisfies the paper's Assumption 1. The suites with sensing (laser,
obstacle memory, re-planning) build their worlds in `sensing_suites` instead.

- `random_world`: random convex obstacles between start (0, 0, 0) and goal (6, 0, 0), the
  first one across the straight line; reproducible from the suite's seed and the index.
- `barn_world`: a BARN world file, its cylinders as octagons (or, with merge, rows of
  touching cylinders as thin rectangles); contact is measured from the exact cylinders.
"""

from __future__ import annotations

from dataclasses import dataclass
import json
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from mpc_local_planner.core.obstacles import ConvexPolygon, segment_collides
from mpc_local_planner.core.planner import PlanningError, RrtStarPlanner
from mpc_local_planner.core.planner_config import PlannerConfig

__all__ = [
    'assumption_1',
    'barn_world',
    'polyline_length',
    'random_world',
    'ROBOT_RADIUS',
    'Scenario',
    'shortcut',
]

# The known-map robot: a circle.
ROBOT_RADIUS = 0.2
# Random suite: the workspace, the start and goal, and success.
RANDOM_BOUNDS = (-1.0, 7.0, -3.0, 3.0)
RANDOM_START = np.array([0.0, 0.0, 0.0])
RANDOM_GOAL = np.array([6.0, 0.0, 0.0])
RANDOM_GOAL_TOLERANCE = 0.05
RANDOM_ATTEMPTS = 50
# The planner grows obstacles by robot radius + clearance; clearance beyond the MPC's own
# collision margin gives the MPC room to cut corners. Tried in order until RRT* finds a path
# (narrow BARN gaps need the smaller ones).
CLEARANCE_EXTRA = (0.05, 0.02, 0.0)
RRT_ITERATIONS = 3000
RRT_TIME_LIMIT = 30.0
BARN_RRT_RANGE = 0.5
RANDOM_V_REF = 0.31  # the time limit scales with the paper's speed, whatever --v-max says


@dataclass
class Scenario:
    """What a run needs of its world: obstacles, start, goal, reference polyline, limits."""

    name: str
    obstacles: tuple[ConvexPolygon, ...]
    start: np.ndarray
    goal: np.ndarray
    bounds: tuple[float, float, float, float]
    waypoints: np.ndarray | None
    planner_clearance: float | None
    assumption_1: bool
    goal_tolerance: float
    time_limit: float
    cylinders: np.ndarray | None = None
    cylinder_radius: float = 0.0
    barn_path_length: float | None = None
    note: str = ''


def assumption_1(
    waypoints: np.ndarray | None, obstacles: Sequence[ConvexPolygon], inflation: float
) -> bool:
    """Say whether the polyline lies in the interior of the free space grown by inflation.

    Every segment must miss every obstacle inflated by `inflation` (the MPC's robot radius
    plus collision margin); the check is exact and counts grazing as touching.
    """
    if waypoints is None or len(waypoints) < 2:
        return False
    grown = [o.inflate(inflation) for o in obstacles]
    return not any(segment_collides(grown, waypoints[i], waypoints[i + 1])
                   for i in range(len(waypoints) - 1))


def shortcut(waypoints: np.ndarray, obstacles: Sequence[ConvexPolygon]) -> np.ndarray:
    """Greedy shortcut: from each kept point, jump to the furthest point in straight view.

    `obstacles` are already inflated as the planner inflated them, so the result keeps the
    planner's clearance (and Assumption 1 whenever the input satisfies it).
    """
    pts = np.asarray(waypoints, dtype=float)
    kept = [0]
    i = 0
    while i < len(pts) - 1:
        j = len(pts) - 1
        while j > i + 1 and segment_collides(obstacles, pts[i], pts[j]):
            j -= 1
        kept.append(j)
        i = j
    return pts[kept]


def _plan(
    obstacles: Sequence[ConvexPolygon],
    bounds: tuple[float, float, float, float],
    start: np.ndarray,
    goal: np.ndarray,
    *,
    seed: int,
    margin: float,
    rrt_range: float,
) -> tuple[np.ndarray | None, float | None, str]:
    """Plan with RRT*, trying the clearances of CLEARANCE_EXTRA beyond the MPC's margin."""
    note = ''
    for extra in CLEARANCE_EXTRA:
        clearance = margin + extra
        config = PlannerConfig(iterations=RRT_ITERATIONS, time_limit=RRT_TIME_LIMIT,
                               seed=seed, range=rrt_range, robot_radius=ROBOT_RADIUS,
                               clearance=clearance)
        try:
            waypoints = RrtStarPlanner(obstacles, bounds, config=config).plan(start, goal)
        except PlanningError as err:
            note = str(err)
            continue
        grown = [o.inflate(config.inflation) for o in obstacles]
        return shortcut(waypoints, grown), clearance, ''
    # Last resort: the robot radius alone (the path then violates Assumption 1).
    config = PlannerConfig(iterations=RRT_ITERATIONS, time_limit=RRT_TIME_LIMIT, seed=seed,
                           range=rrt_range, robot_radius=ROBOT_RADIUS, clearance=0.0)
    try:
        waypoints = RrtStarPlanner(obstacles, bounds, config=config).plan(start, goal)
    except PlanningError as err:
        return None, None, f'no path: {err}; {note}'
    grown = [o.inflate(config.inflation) for o in obstacles]
    return shortcut(waypoints, grown), 0.0, 'planned with robot radius only'


def _random_polygon(rng: np.random.Generator, cx: float, cy: float) -> ConvexPolygon:
    sides = int(rng.integers(3, 7))
    angles = np.sort(rng.uniform(0.0, 2.0 * math.pi, sides))
    radii = rng.uniform(0.25, 0.65, sides)
    points = np.column_stack([cx + radii * np.cos(angles), cy + radii * np.sin(angles)])
    return ConvexPolygon.from_vertices(points)


def random_world(index: int, seed: int, *, margin: float) -> Scenario:
    """Return random world `index` of the suite seeded by `seed` (reproducible).

    Three to six random convex polygons (3 to 6 vertices, 0.25 to 0.65 m from their centre)
    between start and goal; the first sits across the straight line. Draws are repeated until
    start and goal are clear (by robot radius + margin + 0.3 m) and RRT* finds a path.
    """
    rng = np.random.default_rng([seed, index])
    free = ROBOT_RADIUS + margin + 0.3
    for attempt in range(RANDOM_ATTEMPTS):
        count = int(rng.integers(3, 7))
        obstacles = []
        for i in range(count):
            cx = float(rng.uniform(1.3, 4.7))
            cy = float(rng.uniform(-0.3, 0.3) if i == 0 else rng.uniform(-2.0, 2.0))
            obstacles.append(_random_polygon(rng, cx, cy))
        ends = np.array([RANDOM_START[:2], RANDOM_GOAL[:2]])
        if any(np.any(o.distance(ends) < free) for o in obstacles):
            continue
        plan_seed = int(rng.integers(0, 2**31 - 2))
        waypoints, clearance, note = _plan(obstacles, RANDOM_BOUNDS, RANDOM_START, RANDOM_GOAL,
                                           seed=plan_seed, margin=margin, rrt_range=0.0)
        if waypoints is None:
            continue
        return Scenario(
            name=f'random_{index:03d}', obstacles=tuple(obstacles), start=RANDOM_START.copy(),
            goal=RANDOM_GOAL.copy(), bounds=RANDOM_BOUNDS, waypoints=waypoints,
            planner_clearance=clearance,
            assumption_1=assumption_1(waypoints, obstacles, ROBOT_RADIUS + margin),
            goal_tolerance=RANDOM_GOAL_TOLERANCE,
            time_limit=max(60.0, 4.0 * polyline_length(waypoints) / RANDOM_V_REF),
            note=note or (f'attempt {attempt}' if attempt else ''))
    msg = f'random world {index} (seed {seed}): no plannable draw in {RANDOM_ATTEMPTS}'
    raise RuntimeError(msg)


def polyline_length(waypoints: np.ndarray) -> float:
    """Return the length of the polyline through the waypoints."""
    return float(np.sum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1)))


def barn_world(path: Path, *, seed: int, margin: float, merge: bool = False) -> Scenario:
    """Load a BARN world, plan its reference path and check Assumption 1.

    With merge, rows of touching cylinders become thin rectangles (obstacle_merging) for the
    planner and the MPC; contact is still measured from the exact cylinders.
    """
    import dataclasses

    from mpc_local_planner.worlds.merging import merge_cylinders
    from mpc_local_planner.worlds.world import load_barn_world

    world = load_barn_world(path, robot_radius=ROBOT_RADIUS)
    data = json.loads(Path(path).read_text(encoding='utf-8'))
    if merge:
        merged = merge_cylinders(np.asarray(data['cylinders'], dtype=float).reshape(-1, 2),
                                 float(data['cylinder_radius']))
        world = dataclasses.replace(world, obstacles=tuple(merged))
    index = int(''.join(ch for ch in path.stem if ch.isdigit()) or 0)
    waypoints, clearance, note = _plan(world.obstacles, world.bounds, world.start, world.goal,
                                       seed=seed + index, margin=margin,
                                       rrt_range=BARN_RRT_RANGE)
    inflated = [o.inflate(ROBOT_RADIUS + margin) for o in world.obstacles]
    ends_clear = not any(bool(o.contains(np.array([p[:2] for p in (world.start, world.goal)]))
                              .any()) for o in inflated)
    ok = ends_clear and assumption_1(waypoints, world.obstacles, ROBOT_RADIUS + margin)
    if not ends_clear:
        note = (note + '; ' if note else '') + 'start or goal inside the MPC-inflated obstacles'
    return Scenario(
        name=path.stem, obstacles=world.obstacles, start=world.start, goal=world.goal,
        bounds=world.bounds, waypoints=waypoints, planner_clearance=clearance, assumption_1=ok,
        goal_tolerance=float(world.goal_tolerance or 1.0),
        time_limit=float(world.time_limit or 100.0),
        cylinders=np.asarray(data['cylinders'], dtype=float).reshape(-1, 2),
        cylinder_radius=float(data['cylinder_radius']),
        barn_path_length=float(data['barn_path_length']), note=note)
