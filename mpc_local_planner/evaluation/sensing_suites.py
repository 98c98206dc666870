# SPDX-License-Identifier: Apache-2.0
"""Suites with sensing: obstacles the map lacks, BARN as the challenge runs it, world files.

Every run goes through `navigation.Navigator` (laser, obstacle memory, the planner's grid
with re-planning, the local controller), so the controllers compared see the same scans and
follow the same kind of re-planned paths:

- ``unknown``: random worlds whose planned route is crossed by one to three
  ``unknown_obstacles``; the planner starts from the map of the known ones, the laser shows
  the rest (`unknown_world`).
- ``barn`` with ``--sensing``: no prior map (the planner starts from an empty grid), the
  laser only, the robot's true footprint (``--robot jackal``: the Jackal's rectangle and
  the challenge's speed limits), success within the world's goal tolerance (1 m) before its
  time limit (100 s) with no contact of the true footprint with the true cylinders.
- ``worlds``: every world YAML of a folder, known and unknown obstacles as the files say.

A world's ``moving_obstacles`` move in the run's time (sim/moving.py `WorldClock`, as in the
simulator node): the laser sees them where they are at each scan, the contact check where
they are at each step, and a contact is counted as active (the robot moving) or passive (it
stood still and an obstacle ran into it).

Without ``--sensing`` (``worlds`` only) the laser is off: the controller and the planner know
the map of the known obstacles and nothing else.

The MPCs bound a step's solving by solver iterations (rollout.EVALUATION_BUDGET, the wall
budget's worth on a typical machine), so a run is the same on any machine under any load;
``budget='wall'`` gives the robot's wall-time budget instead, on this machine as loaded now.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math
from pathlib import Path
from typing import Any

import numpy as np

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.controllers import (
    build_controller,
    Built,
    controller_name,
    ControllerName,
    ControllerSetup,
)
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.planner import RrtStarPlanner
from mpc_local_planner.core.planner_config import PlannerConfig
from mpc_local_planner.core.recoveries import Recoveries, RecoverySettings
from mpc_local_planner.evaluation.known_map_worlds import RANDOM_BOUNDS, RANDOM_GOAL, RANDOM_START
from mpc_local_planner.evaluation.metrics import footprint_clearance
from mpc_local_planner.evaluation.mpc_cache import MPC_CACHE, MpcKey
from mpc_local_planner.evaluation.navigation import NavigationSettings, Navigator
from mpc_local_planner.evaluation.rollout import (
    EVALUATION_BUDGET,
    Outcome,
    Rollout,
    rollout,
    StopRule,
)
from mpc_local_planner.perception.grids import PlanningGrid
from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.sim.base import Base
from mpc_local_planner.sim.localizer import Localizer
from mpc_local_planner.sim.moving import ContactKind, WorldClock
from mpc_local_planner.sim.physics import make_physics_base, PLANTS
from mpc_local_planner.sim.reality import POSE_ERROR, Reality, reality_preset
from mpc_local_planner.worlds.map_files import OccupancyMap, rasterize_world
from mpc_local_planner.worlds.world import load_barn_world, World

__all__ = [
    'MAP_RESOLUTION',
    'MpcSetup',
    'Robot',
    'ROBOTS',
    'SensingResult',
    'local_controller',
    'run_navigation',
    'unknown_world',
]

# The grid the planner and the controller's map rectangles use, metres per cell.
MAP_RESOLUTION = 0.05
# Planner clearance beyond the robot (the MPC cuts corners within it): a round robot's, and a
# polygon's (checked pose by pose, it needs less; BARN's gaps are cut for the Jackal).
PLANNER_CLEARANCE = 0.1
POLYGON_CLEARANCE = 0.05
PLANNER_ITERATIONS = 3000
# The planner's wall-time limit in the suites (s): far above what PLANNER_ITERATIONS take
# (under a second on an idle machine), so that the iterations bound planning whatever the
# load, as EVALUATION_BUDGET bounds the MPC's solving. With the planner's default (5 s), on a
# two-core machine loaded to 11 most plans were cut by it: the runs, and the unknown suite's
# worlds (drawn with plans), changed with the load.
PLANNER_TIME_LIMIT = 60.0
PLANNER_RANGE = 0.5
PATH_CAPACITY = 128
# Unknown suite: the random suite's workspace, start and goal; its success tolerance.
UNKNOWN_BOUNDS, UNKNOWN_START, UNKNOWN_GOAL = RANDOM_BOUNDS, RANDOM_START, RANDOM_GOAL
GOAL_TOLERANCE = 0.1
# The paper's MPC arrives (on its pose estimate) within this of the goal: the suites'
# tolerance less what a localized estimate may be off by, so that the truth is within
# reality.true_goal_tolerance(MPC_ARRIVAL) <= GOAL_TOLERANCE, as closed_loop judges a run.
MPC_ARRIVAL = GOAL_TOLERANCE - POSE_ERROR
# NLPs built before the first run: obstacle counts 0..PREPARED_SLOTS. With more active, a
# step's NLP holds the nearest PREPARED_SLOTS (at 2 m/s on BARN the horizon reaches 4 m and
# up to 11 cylinders were active).
PREPARED_SLOTS = 10
UNKNOWN_ATTEMPTS = 50
STALL_SECONDS = 20.0
# With a real robot (reality other than ideal): commands at the node's control_frequency,
# the laser at 10 Hz (the BARN Jackal's UST-10LX does 40; scans cost the perception time),
# and the base integrated in sub-steps of REALITY_SUBSTEP.
CONTROL_FREQUENCY = 20.0
SCAN_PERIOD = 0.1
REALITY_SUBSTEP = 0.01
# The paper's MPC's collision_margin for a real base (m): what a user adds for the tracking
# error of a lagging base (a polygon's default is 0: the NLP's clearance covers the motion of
# the model exactly, not the robot's departures from it).
REALITY_MARGIN = 0.03
# The paper's MPC's input-rate bounds on a real base, as a multiple of the base's
# acceleration limits, and how its inputs act over a step (MpcConfig.input_hold): with a
# first-order hold the velocity ramps between the knots, commanded actuation_delay() ahead,
# so at the base's own limits the lagging base follows the verified motion (the
# measurements behind the choice: docs/real_robot.md).
REALITY_ACCEL_FACTOR = 1.0
REALITY_INPUT_HOLD = 'first_order'
# The physics plant's robot for each of ROBOTS (sim/physics/robots.py).
PHYSICS_ROBOT = {'circle': 'small', 'jackal': 'jackal'}


@dataclass(frozen=True)
class MpcSetup:
    """How the suites set up the MPCs: one value, passed down whole (the defaults: the suites').

    Attributes:
        budget: What bounds a step's solving (SolverSettings.budget): 'iterations', the same
            on any machine under any load, or 'wall', the robot's.
        compile: Compile the MPC's functions (SolverSettings.compile); off, the interpreted
            ones compute the same solutions, more slowly, without gcc.
        input_hold: On a real base, how the paper's MPC's inputs act over a step
            (MpcConfig.input_hold).
        accel_factor: On a real base, the paper's MPC's input-rate bounds as a multiple of
            the base's acceleration limits (MpcConfig.max_accel).

    """

    budget: str = EVALUATION_BUDGET
    compile: bool = True
    input_hold: str = REALITY_INPUT_HOLD
    accel_factor: float = REALITY_ACCEL_FACTOR


@dataclass(frozen=True)
class Robot:
    """A robot the suites drive: its true footprint and speed limits.

    Attributes:
        name: ``circle`` or ``jackal``.
        footprint: The true shape (contacts are measured from it; the MPC and the planner
            take it as it is).
        v_max: Largest forward speed, m/s.
        omega_max: Largest turn rate, rad/s.
        reverses: The MPC may drive it backwards. The Jackal's laser sees 270 degrees: the
            90 behind it are never seen, and at 2 m/s the MPC reversed into a cylinder there
            that it had never seen (laser-only BARN world 223, the only contact of the
            suite). So its MPC drives forwards only, as DWB's default min_vel_x = 0 does;
            it still turns in place.

    """

    name: str
    footprint: Footprint
    v_max: float
    omega_max: float
    reverses: bool = True


ROBOTS = {
    'circle': Robot('circle', Footprint.circle(0.2), v_max=0.31, omega_max=1.9),
    # The BARN challenge's Jackal: its rectangle and its own limits, 2.0 m/s and 4.0 rad/s
    # (jackal_control's control.yaml; config/jackal.yaml), which every headline uses.
    'jackal': Robot('jackal', JACKAL, v_max=2.0, omega_max=4.0, reverses=False),
}


def _vertices(footprint: Footprint) -> tuple[tuple[float, float], ...]:
    if footprint.is_circle:
        return ()
    return tuple((float(x), float(y)) for x, y in footprint.vertices)


def _random_polygon(rng: np.random.Generator, cx: float, cy: float, low: float,
                    high: float) -> ConvexPolygon:
    sides = int(rng.integers(3, 7))
    angles = np.sort(rng.uniform(0.0, 2.0 * math.pi, sides))
    radii = rng.uniform(low, high, sides)
    return ConvexPolygon.from_vertices(
        np.column_stack([cx + radii * np.cos(angles), cy + radii * np.sin(angles)]))


def _grid_planner(occupancy: OccupancyMap, robot: Robot, bounds: tuple[float, float, float, float],
                  seed: int) -> tuple[PlanningGrid, RrtStarPlanner]:
    """Return the planner's grid of a map and the RRT* planner on it (the navigator's)."""
    config = PlannerConfig(
        iterations=PLANNER_ITERATIONS, time_limit=PLANNER_TIME_LIMIT, seed=seed,
        range=PLANNER_RANGE,
        robot_radius=robot.footprint.radius if robot.footprint.is_circle else 0.0,
        footprint=_vertices(robot.footprint),
        clearance=PLANNER_CLEARANCE if robot.footprint.is_circle else POLYGON_CLEARANCE)
    grid = PlanningGrid(occupancy, inflation=config.inflation)
    return grid, RrtStarPlanner.on_grid(grid, config=config, bounds=bounds)


def unknown_world(index: int, seed: int, *, robot: Robot | None = None) -> World:
    """Return world `index` of the unknown suite seeded by `seed` (reproducible).

    Two to four known random polygons between start (0, 0, 0) and goal (6, 0, 0). The
    navigator's own first plan (RRT* on the map of the known ones, planner seed 0, as
    `run_navigation` plans it) is computed, and one to three unknown polygons are put on it
    (centred on the route, between 25 % and 80 % of its length), so every world's first plan
    runs into something the map lacks. A draw is kept when start and goal are clear of
    everything by a margin and a path exists in the true world (RRT* on the known and
    unknown obstacles together), so that every world can be solved.
    """
    robot = robot or ROBOTS['circle']
    rng = np.random.default_rng([seed, index, 7])
    clear = robot.footprint.radius + 0.5
    ends = np.array([UNKNOWN_START[:2], UNKNOWN_GOAL[:2]])
    for _ in range(UNKNOWN_ATTEMPTS):
        known = [_random_polygon(rng, float(rng.uniform(1.3, 4.7)),
                                 float(rng.uniform(-2.2, 2.2)), 0.25, 0.6)
                 for _ in range(int(rng.integers(2, 5)))]
        if any(np.any(o.distance(ends) < clear) for o in known):
            continue
        world = World(name=f'unknown_{index:03d}', bounds=UNKNOWN_BOUNDS,
                      obstacles=tuple(known), start=UNKNOWN_START.copy(),
                      goal=UNKNOWN_GOAL.copy(), footprint=robot.footprint,
                      goal_tolerance=GOAL_TOLERANCE)
        try:
            route = _grid_planner(rasterize_world(world, MAP_RESOLUTION), robot,
                                  world.bounds, 0)[1].plan(world.start, world.goal)
        except PlanningError:
            continue
        lengths = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(route, axis=0).T))])
        unknown = []
        for fraction in np.sort(rng.uniform(0.25, 0.8, int(rng.integers(1, 4)))):
            at = fraction * lengths[-1]
            k = min(int(np.searchsorted(lengths, at, side='right')) - 1, len(route) - 2)
            t = (at - lengths[k]) / max(lengths[k + 1] - lengths[k], 1e-12)
            centre = route[k] + t * (route[k + 1] - route[k])
            unknown.append(_random_polygon(rng, float(centre[0]), float(centre[1]), 0.2, 0.45))
        if any(np.any(o.distance(ends) < clear) for o in unknown):
            continue
        config = PlannerConfig(iterations=PLANNER_ITERATIONS, time_limit=PLANNER_TIME_LIMIT,
                               seed=index, range=PLANNER_RANGE,
                               robot_radius=robot.footprint.radius,
                               clearance=PLANNER_CLEARANCE)
        try:
            RrtStarPlanner(known + unknown, UNKNOWN_BOUNDS, config=config).plan(
                UNKNOWN_START, UNKNOWN_GOAL)
        except PlanningError:
            continue
        return replace(world, unknown_obstacles=tuple(unknown),
                       time_limit=max(60.0, 4.0 * float(lengths[-1]) / robot.v_max))
    msg = f'unknown world {index} (seed {seed}): no solvable draw in {UNKNOWN_ATTEMPTS}'
    raise RuntimeError(msg)


def barn_sensing_world(path: str | Path, robot: Robot) -> World:
    """Return a BARN world for the challenge's conditions: every cylinder unknown to the map."""
    world = load_barn_world(path, footprint=robot.footprint) if not robot.footprint.is_circle \
        else load_barn_world(path, robot_radius=robot.footprint.radius)
    return replace(world, obstacles=(), unknown_obstacles=world.obstacles,
                   true_shapes=world.physical_shapes())


def _empty_map(bounds: tuple[float, float, float, float]) -> OccupancyMap:
    """Return an all-unknown grid over bounds (the planner's start without a prior map)."""
    xmin, xmax, ymin, ymax = bounds
    width = int(math.ceil((xmax - xmin) / MAP_RESOLUTION))
    height = int(math.ceil((ymax - ymin) / MAP_RESOLUTION))
    return OccupancyMap(np.full((height, width), -1, dtype=np.int8), MAP_RESOLUTION,
                        (xmin, ymin, 0.0))


def controller_setup(name: ControllerName, robot: Robot, world: World, *,
                     setup: MpcSetup = MpcSetup(),
                     reality: Reality | None = None) -> ControllerSetup:
    """Return what the named controller is built from for the robot in world.

    With a real base (reality), the paper's MPC is told its deceleration limits (stops
    brake along the last verified plan, ControllerSettings.max_decel), bounds its input rates
    at setup.accel_factor times the base's (MpcConfig.max_accel) with the input hold
    setup.input_hold (a first-order hold's ramp commanded actuation_delay() ahead) and
    keeps a collision margin for the base's lag (REALITY_MARGIN); see docs/real_robot.md for
    how these were chosen. The tracking MPC is set up as for an ideal robot; the DWA takes
    the base's control period and acceleration limits.
    """
    proposed = name is ControllerName.PROPOSED
    mpc_reality = reality if proposed else None
    accel = mpc_reality.acceleration_limits if mpc_reality is not None else None
    hold = setup.input_hold if accel is not None else 'zero'
    delay = actuation_delay(mpc_reality) if hold == 'first_order' and mpc_reality is not None \
        else 0.0
    model = Unicycle(v_max=robot.v_max, omega_max=robot.omega_max,
                     v_min=None if robot.reverses else 0.0)
    config = MpcConfig(robot_radius=robot.footprint.radius if robot.footprint.is_circle
                       else 0.0, footprint=_vertices(robot.footprint),
                       collision_margin=REALITY_MARGIN if mpc_reality is not None else None,
                       max_accel=tuple(setup.accel_factor * a for a in accel)
                       if accel is not None else None,
                       input_hold=hold,
                       solving=SolverSettings(budget=setup.budget, compile=setup.compile))
    settings = ControllerSettings(xy_goal_tolerance=MPC_ARRIVAL, yaw_goal_tolerance=math.pi,
                                  capacity=PATH_CAPACITY,
                                  max_decel=accel or (math.inf, math.inf),
                                  actuation_delay=delay)
    return ControllerSetup(
        model=model, footprint=robot.footprint, config=config, settings=settings,
        goal_tolerance=float(world.goal_tolerance or GOAL_TOLERANCE),
        control_period=1.0 / CONTROL_FREQUENCY if reality is not None else None,
        acceleration=reality.acceleration if reality is not None else None)


def _mpc(name: ControllerName, built: ControllerSetup, world: World, *,
         prepare: bool = True, budget: str = EVALUATION_BUDGET) -> Built:
    """Return the cached MPC of the setup (MPC_CACHE), reset for a new run in world."""
    key = MpcKey(name, built.model, built.config,
                 built.settings if name is ControllerName.PROPOSED else None)

    def build() -> Built:
        made = build_controller(name, built)
        if name is ControllerName.PROPOSED:
            made.controller.set_plan(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))  # the NLPs
        return made

    made = MPC_CACHE.get(key, build)
    controller: Any = made.controller
    if prepare:
        core = controller.mpc if name is ControllerName.PROPOSED else controller
        MPC_CACHE.prepare_once(key, lambda: _prepare(core, budget))
    if name is ControllerName.PROPOSED:
        controller.clear_path()
        controller.set_obstacles([])
        controller.mpc.reset()
        return made
    controller.set_plan(np.asarray(world.goal, dtype=float)[None, :3])
    controller.set_obstacles([])
    controller.reset()
    return made


def actuation_delay(reality: Reality) -> float:
    """Return how far ahead a first-order hold's ramp is commanded on this base (s).

    Its latency plus its slower lag's time constant: a command acts latency late, and a
    first-order lag follows a ramp its time constant behind.
    """
    return float(reality.latency + max(reality.lag))


def _prepare(mpc: Any, budget: str = EVALUATION_BUDGET) -> None:
    """Build the NLPs for up to PREPARED_SLOTS boxes or octagons in reach; compile them.

    With a wall budget, wait for every compilation before the first run (compiled and
    interpreted functions take different times, and the budget is time). With the
    'iterations' budget the runs start at once: a step that needs an NLP waits for its
    compilation (SolverSettings.budget; the queued one is compiled first), so every solve runs the
    compiled functions whatever the timing, and the rest compile in the background in the
    order they were built: a first run waits for the few shapes it uses, not for all 21
    (minutes); the wait is not counted in the step times (compilation.compile_wait_seconds).
    """
    mpc.prepare(PREPARED_SLOTS)
    if budget != 'iterations':
        mpc.wait_compiled()


def local_controller(name: ControllerName | str, robot: Robot, world: World, *,
                      prepare: bool = True, setup: MpcSetup = MpcSetup(),
                      reality: Reality | None = None) -> Built:
    """Return the named local controller for the robot (tuned to a real base's limits).

    The MPCs come from the process's MPC_CACHE (their NLPs built once), reset for the run;
    the path followers are built new.

    Raises:
        ValueError: for a name that is not a ControllerName.

    """
    key = controller_name(name)
    built = controller_setup(key, robot, world, setup=setup, reality=reality)
    if key in (ControllerName.PROPOSED, ControllerName.TRACKING):
        return _mpc(key, built, world, prepare=prepare, budget=setup.budget)
    return build_controller(key, built)


@dataclass
class SensingResult:
    """A navigation run and what it needs for its row."""

    run: Rollout
    navigator: Navigator | None
    contacts: int
    min_clearance: float
    note: str = ''
    active_contacts: int = 0
    passive_contacts: int = 0


def run_navigation(world: World, controller: str, robot: Robot, *, sensing: bool = True,
                   seed: int = 0, h: float = 0.2, prepare: bool = True,
                   setup: MpcSetup = MpcSetup(), reality: str | Reality = 'ideal',
                   localized: bool | None = None, plant: str = 'kinematic',
                   recoveries: bool = False, record: bool = False,
                   track_moving: bool = False,
                   lead_in: np.ndarray | None = None) -> SensingResult:
    """Drive robot through world with the named controller, perception and re-planning.

    Args:
        world: Known obstacles (the planner's map) and unknown ones (only the laser sees).
        controller: ``proposed``, ``tracking``, ``pure_pursuit``, ``dwa`` or
            ``regulated_pure_pursuit``.
        robot: Its footprint and speed limits (the world's own footprint is not used).
        sensing: The laser is on (scans mark the planner's grid and fill the controller's
            memory); off, only the map of the known obstacles is known.
        seed: The planner's seed.
        h: Control period, seconds.
        prepare: Build and compile the MPC's NLPs before the run (once per process), as a
            robot does at start-up; off, they are built when first needed (mid-run: slow
            first steps), which is enough for tests that do not time steps.
        setup: How the MPCs solve (their budget, compiled or not) and how the paper's MPC
            acts on a real base.
        reality: How real the robot is (sim/reality.py: a preset's name or a Reality).
            Ideal: the model takes each command exactly every h, odometry is the pose, the
            laser is exact (every suite before). Otherwise the robot is a `Base` with that
            reality (seeded with seed), commanded at CONTROL_FREQUENCY (the MPC still
            predicts in steps of h), the laser scans every SCAN_PERIOD through its
            ScanChannel, and every controller sees odometry, not the true pose; when the
            odometry is not exact, corrected by a `Localizer` (the simulator's stand-in
            for AMCL, as closed_loop runs it): the pose in map, as the nodes compose it.
        localized: Whether a robot whose odometry is not exact has that localizer; None:
            it has. BARN's robot has none (odometry and a laser, no map, a goal relative to
            its start and reached within 1 m): suite_runs passes False for BARN.
        plant: ``kinematic`` (the `Base` above) or ``mujoco``: the rigid-body robot of
            sim/physics/ (PHYSICS_ROBOT[robot.name]) among the world's obstacles, its
            odometry from its wheels and its laser cast by the engine; it is run as a real
            robot (commanded at CONTROL_FREQUENCY, controllers set up as for a real base of
            this reality, whose latency and odometry noise it adds).
        recoveries: Run the recovery behaviours around the controller (`recovery_setup`:
            back out along the trail, spin, wait), as the controller node runs them; off,
            the controller's answer always stands.
        record: Keep every step's inputs in the navigator's `recorded` (Navigator), for
            a replay of the same states through other controllers.
        track_moving: The controller's memory tracks the scans' small clusters and forgets
            what moving ones built (NavigationSettings.track_moving); off, the world is
            taken as static.
        lead_in: (K, 4) rows [t, x, y, theta] of the poses the robot drove over before
            world.start, oldest first, t < 0 (`Navigator.lead_in`: its laser's view from
            them and its trail), to resume a run from a recorded state; None: the run starts
            afresh.

    Raises:
        ValueError: for a plant that is not one of sim/physics PLANTS, or a malformed lead_in.
        RuntimeError: for the mujoco plant when MuJoCo is not installed.

    """
    if isinstance(reality, str):
        reality = reality_preset(reality)
    if plant not in PLANTS:
        msg = f'unknown plant {plant!r}; choose one of {", ".join(PLANTS)}'
        raise ValueError(msg)
    physics = plant == 'mujoco'
    real = not reality.ideal or physics
    known = rasterize_world(world, MAP_RESOLUTION) if world.obstacles else \
        _empty_map(world.bounds)
    grid, planner = _grid_planner(known, robot, world.bounds, seed)
    local = local_controller(controller, robot, world, prepare=prepare, setup=setup,
                              reality=reality if real else None)
    model = Unicycle(v_max=robot.v_max, omega_max=robot.omega_max)
    if physics:
        base: Any = make_physics_base(model, reality.with_seed(seed), world.start,
                                      robot=PHYSICS_ROBOT[robot.name],
                                      footprint=robot.footprint,
                                      shapes=world.physical_shapes(), dt=REALITY_SUBSTEP,
                                      moving=world.moving_obstacles)
    else:
        base = Base(model, reality.with_seed(seed), world.start, dt=REALITY_SUBSTEP) \
            if real else None
    period = 1.0 / CONTROL_FREQUENCY if real else h
    settings = NavigationSettings(sense=sensing, scan_period=SCAN_PERIOD if real else None,
                                  track_moving=track_moving)
    clock = WorldClock.from_world(world) if world.moving_obstacles else None
    navigator = Navigator(local.controller,
                          clock if clock is not None else TrueGeometry(world.physical_shapes()),
                          grid,
                          planner, world.goal, reach=local.reach, h=period,
                          known_map=known if world.obstacles else None,
                          settings=settings, footprint=robot.footprint, base=base,
                          recoveries=recovery_setup(robot) if recoveries else None,
                          record=record)
    if lead_in is not None:  # before the engine's laser: the lead-in's poses are not the base's
        navigator.lead_in(lead_in)
    if physics:  # the engine casts the beams, with the laser's settings
        laser = navigator.laser
        navigator.laser = base.laser(fov=laser.fov, beams=laser.beams,
                                     range_min=laser.range_min, range_max=laser.range_max)
    clearance = footprint_clearance(world.physical_shapes(), robot.footprint)
    # a robot may wait in front of an obstacle for a re-plan: standing still ends a run after
    # STALL_SECONDS, not the rollout's default 5 s
    rule = StopRule(time_limit=float(world.time_limit or 100.0),
                    position_tolerance=float(world.goal_tolerance or GOAL_TOLERANCE),
                    stall_steps=int(STALL_SECONDS / period))
    # odometry that drifts is corrected by a localizer, as closed_loop --reality runs the
    # nodes (its poses seeded per run, as the base's)
    drifts = real and not reality.ideal_base
    localizer = Localizer(seed=seed) if drifts and localized is not False else None
    clearance_at = None
    if clock is not None:
        def clearance_at(pose: np.ndarray, t: float) -> float:
            return clock.clearance(robot.footprint, pose, t)
    run = rollout(navigator, base if base is not None else model, world.start, world.goal,
                  h=period, rule=rule, clearance=clearance, localizer=localizer,
                  clearance_at=clearance_at)
    if clearance_at is None:
        closest = float(np.min(clearance(run.rows[:, 1:4])))
    else:
        closest = min(clearance_at(row[1:4], float(row[0])) for row in run.rows)
    contacts = int(run.outcome is Outcome.COLLISION or closest <= 0.0)
    passive = int(run.contact is ContactKind.PASSIVE)
    return SensingResult(run=run, navigator=navigator, contacts=contacts,
                         min_clearance=closest, active_contacts=contacts - passive,
                         passive_contacts=passive)


def recovery_setup(robot: Robot) -> Recoveries:
    """Return the recovery behaviours for robot, as the controller node sets them up.

    A robot that may reverse does not back out (its MPC plans backwards itself).
    """
    return Recoveries(robot.footprint, v_max=robot.v_max, omega_max=robot.omega_max,
                      settings=RecoverySettings(back_out=not robot.reverses))


def result_fields(result: SensingResult) -> dict[str, Any]:
    """Return the runs.csv fields a navigation run adds."""
    log = result.navigator.log if result.navigator is not None else None
    recoveries = result.navigator.recoveries if result.navigator is not None else None
    control = np.asarray(log.control_seconds if log else [], dtype=float) * 1e3
    plans = np.asarray(log.plan_seconds if log else [], dtype=float)
    return {
        'contacts': result.contacts,
        'active_contacts': result.active_contacts,
        'passive_contacts': result.passive_contacts,
        'replans': log.replans if log else 0,
        'replan_failures': log.replan_failures if log else 0,
        'step_ms_median': float(np.median(control)) if len(control) else math.nan,
        'step_ms_max': float(np.max(control)) if len(control) else math.nan,
        'plan_s_max': float(np.max(plans)) if len(plans) else math.nan,
        'recoveries': recoveries.started if recoveries is not None else None,
        'recovery_s': (sum(r.end - r.start for r in recoveries.log)
                       if recoveries is not None else None),
    }


def plot_navigation_runs(target: Path, worlds: list[tuple[str, World]], controller: str,
                         robot: Robot, *, seed: int = 0, prepare: bool = True,
                         setup: MpcSetup = MpcSetup(), reality: str = 'ideal',
                         localized: bool | None = None, plant: str = 'kinematic',
                         recoveries: bool = False, track_moving: bool = False) -> Path:
    """Draw laser-only runs: the true obstacles, what was sensed, every plan, the footprint.

    Each world is run again (the runs are deterministic) with the navigator's log at hand:
    the true obstacles grey (the cylinders as circles), the obstacles the controller avoided
    at a few instants dashed, every plan the planner made (the first dotted, the re-plans
    thin), and the trajectory with the robot's footprint at a few poses.

    Args:
        target: The PNG to write.
        worlds: (title, world) per panel.
        controller: The local controller to run.
        robot: Its footprint and speed limits.
        seed: The planner's seed.
        prepare: Build the MPC's NLPs before the runs (see run_navigation).
        setup: How the MPCs are set up (see run_navigation).
        reality: How real the robot is (see run_navigation), as the suite ran it.
        localized: Whether a real robot has a localizer (see run_navigation).
        plant: The robot's plant (see run_navigation).
        recoveries: Run the recovery behaviours (see run_navigation).
        track_moving: Track moving clusters in the memory (see run_navigation).

    Returns:
        target.

    """
    import matplotlib

    matplotlib.use('Agg')
    from matplotlib.patches import Circle as CirclePatch
    from matplotlib.patches import Polygon as PolygonPatch
    import matplotlib.pyplot as plt

    from mpc_local_planner.evaluation.plotting import draw_footprints, draw_sensed
    from mpc_local_planner.worlds.world import Circle

    # panels 3 inches wide, as tall as the worlds' shape asks (BARN's: tall, capped)
    ratio = max((b[3] - b[2]) / (b[1] - b[0]) for b in (w.bounds for _, w in worlds))
    height = min(max(3.0 * ratio + 1.2, 2.8), 6.5)
    fig, axes = plt.subplots(1, len(worlds), figsize=(3.0 * len(worlds), height),
                             squeeze=False)
    for ax, (title, world) in zip(axes[0], worlds, strict=True):
        result = run_navigation(world, controller, robot, seed=seed, prepare=prepare,
                                setup=setup, reality=reality, localized=localized,
                                plant=plant, recoveries=recoveries,
                                track_moving=track_moving)
        for shape in world.physical_shapes():
            if isinstance(shape, Circle):
                ax.add_patch(CirclePatch((shape.x, shape.y), shape.radius, color='0.6'))
            else:
                ax.add_patch(PolygonPatch(shape.vertices, closed=True, color='0.6'))
        log = result.navigator.log
        picks = np.linspace(0, len(log.sensed) - 1, min(3, len(log.sensed))).astype(int)
        draw_sensed(ax, [(log.sensed[i][0], [o.vertices for o in log.sensed[i][1]])
                         for i in sorted(set(picks.tolist()))])
        for k, (_, plan, _) in enumerate(log.plans):
            ax.plot(plan[:, 0], plan[:, 1], ':' if k == 0 else '-', color='tab:green',
                    linewidth=1.2 if k == 0 else 0.7,
                    label=('first plan' if k == 0 else
                           're-plans' if k == 1 else None))
        rows = result.run.rows
        ax.plot(rows[:, 1], rows[:, 2], color='tab:blue', linewidth=1.5, label=controller)
        draw_footprints(ax, robot.footprint, rows)
        ax.plot(*world.goal[:2], '*', color='black', markersize=10)
        ax.set_title(f'{title}\n{result.run.outcome.value} in {result.run.end_time:.1f} s, '
                     f'{log.replans} re-plans', fontsize=8)
        ax.set_aspect('equal')
        xmin, xmax, ymin, ymax = world.bounds
        ax.set_xlim(xmin, xmax)
        ax.set_ylim(ymin, ymax)
        ax.tick_params(labelsize=7)
    axes[0][0].legend(fontsize=6, loc='lower left')
    fig.suptitle(f'Laser only: {controller}, {robot.name} robot ({robot.v_max:g} m/s)',
                 fontsize=10)
    fig.tight_layout()
    target.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(target, dpi=110)
    plt.close(fig)
    return target
