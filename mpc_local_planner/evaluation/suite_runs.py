# SPDX-License-Identifier: Apache-2.0
"""One run of a suite: a Task (a world and a controller) in closed loop, and its runs.csv row.

The `evaluate` command sweeps Tasks over worlds and controllers (locally or on a Dask
cluster, which pickles `run_task` by its name in this module, with its per-process MPC
caches) and summarises the rows. A navigation Task (``--suite unknown``, ``--suite worlds``,
``--sensing``) runs the navigation stack of `sensing_suites`; the others follow the reference
path planned once on the known map (`known_map_worlds`) with the paper's MPC, the tracking
MPC or pure pursuit, through `rollout`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import json
import math
from pathlib import Path
from typing import Any, TYPE_CHECKING

import numpy as np

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.controllers import (
    build_controller,
    controller_name,
    ControllerName,
    ControllerSetup,
)
from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import PathReferenceMPC
from mpc_local_planner.core.paths import WaypointPath, waypoints_to_poses
from mpc_local_planner.core.planner import PlanningError
from mpc_local_planner.evaluation.known_map_worlds import (
    barn_world,
    polyline_length,
    random_world,
    ROBOT_RADIUS,
    Scenario,
)
from mpc_local_planner.evaluation.metrics import compute_metrics
from mpc_local_planner.evaluation.mpc_cache import MPC_CACHE, MpcKey
from mpc_local_planner.evaluation.rollout import (
    circle_clearance,
    Clearance,
    EVALUATION_BUDGET,
    Outcome,
    polygon_clearance,
    Rollout,
    rollout,
    StopRule,
)
from mpc_local_planner.evaluation.run_row import RUN_COLUMNS, RunRow
from mpc_local_planner.evaluation.trajectory import write_trajectory_csv
from mpc_local_planner.worlds.data_files import BARN_DIR

if TYPE_CHECKING:  # the navigation suites' module is imported where it is used
    from mpc_local_planner.evaluation.sensing_suites import Robot, SensingResult
    from mpc_local_planner.worlds.world import World

__all__ = [
    'barn_score',
    'parse_worlds',
    'CONTROLLERS',
    'CSV_COLUMNS',
    'DEFAULT_BARN_DIR',
    'empty_row',
    'finish_row',
    'KNOWN_MAP_CONTROLLERS',
    'navigation_world',
    'run_navigation_task',
    'run_task',
    'save_world',
    'saved_world_path',
    'SUITES',
    'Task',
]

CONTROLLERS = tuple(ControllerName)
# The known-map suites run the first three (DWA and Nav2's regulated pure pursuit run with
# sensing, on re-planned paths: they take the sensed obstacles).
KNOWN_MAP_CONTROLLERS = CONTROLLERS[:3]
SUITES = ('random', 'barn', 'unknown', 'worlds', 'dynamic')
# The suites that always run the navigation stack (laser, re-planning): the others need
# --sensing for it.
NAVIGATION_SUITES = ('unknown', 'worlds', 'dynamic')
CSV_COLUMNS = RUN_COLUMNS
DEFAULT_BARN_DIR = BARN_DIR
PATH_CAPACITY = 128


@dataclass(frozen=True)
class Task:
    """One closed-loop run: a world and a controller."""

    suite: str
    world: int
    controller: str
    seed: int = 0
    v_max: float = 0.31
    omega_max: float = 1.9
    barn_dir: str = ''  # '' for the worlds shipped with the package, wherever it runs
    trajectory_dir: str = ''
    merge: bool = False
    sensing: bool = False
    robot: str = 'circle'
    world_file: str = ''
    budget: str = EVALUATION_BUDGET  # SolverSettings.budget of the MPCs
    compile: bool = True  # SolverSettings.compile of the MPCs
    reality: str = 'ideal'  # sim/reality.py preset: how real the robot is (navigation runs)
    # a folder: the paper's MPC runs through the node processes there (through_nodes.py);
    # '' runs it in process
    through_nodes: str = ''
    plant: str = 'kinematic'  # sim/physics PLANTS: the kinematic Base or MuJoCo's robot
    recoveries: bool = False  # core/recoveries.py around every controller (navigation runs)
    # the memory tracks the scans' clusters and forgets what moving ones built (navigation)
    track_moving: bool = False

    @property
    def navigation(self) -> bool:
        """Run through the navigation stack (laser, re-planning) rather than a fixed path."""
        return self.sensing or self.suite in NAVIGATION_SUITES


def parse_worlds(text: str) -> list[int]:
    """Return the world numbers of a list like '0-99,200-299' or '3,7,10-12', in order."""
    worlds: list[int] = []
    for part in text.split(','):
        part = part.strip()
        if '-' in part:
            lo, hi = (int(v) for v in part.split('-', 1))
            worlds.extend(range(lo, hi + 1))
        elif part:
            worlds.append(int(part))
    return worlds


def barn_score(success: bool, time_s: float | None, barn_path_length: float) -> float:
    """Return the BARN challenge's score of one run.

    The challenge's formula: success * t_opt / clip(t, 2 t_opt, 8 t_opt), with
    t_opt = barn_path_length / 2 and barn_path_length the FULL reference path (start -> the
    world's path file -> goal, as the challenge's run.py adds the two legs). A successful run
    faster than 2 t_opt scores the cap, 0.5.
    """
    if not success or time_s is None:
        return 0.0
    t_opt = barn_path_length / 2.0
    return float(t_opt / np.clip(time_s, 2.0 * t_opt, 8.0 * t_opt))


def _barn_file(task: Task) -> Path:
    """Return the task's BARN world file, on the machine that runs it."""
    return Path(task.barn_dir or DEFAULT_BARN_DIR) / f'world_{task.world:03d}.json'


def _scenario(task: Task, margin: float) -> Scenario:
    if task.suite == 'random':
        return random_world(task.world, task.seed, margin=margin)
    return barn_world(_barn_file(task), seed=task.seed, margin=margin, merge=task.merge)


def _clearance_fn(scenario: Scenario) -> Clearance:
    """Return points (n, 2) -> clearance of the robot circle from the true obstacles."""
    if scenario.cylinders is not None:
        return circle_clearance(scenario.cylinders, scenario.cylinder_radius, ROBOT_RADIUS)
    return polygon_clearance(scenario.obstacles, ROBOT_RADIUS)


PREPARED_SLOTS = 4


def _controller(task: Task, scenario: Scenario, model: Unicycle, config: MpcConfig) -> Any:
    """Return the task's controller for the rollout, set up for the scenario.

    Pure pursuit and the tracking MPC are local controllers (core/controllers.py); the
    paper's MPC runs as it is (PathReferenceMPC.solve), without the controller's arrival and
    braking around it. The MPCs come from the process's MPC_CACHE (their NLPs built once).

    Raises:
        ValueError: for a controller the known-map suites do not run.

    """
    name = controller_name(task.controller)
    if name not in KNOWN_MAP_CONTROLLERS:
        msg = f'unknown controller {task.controller!r}'
        raise ValueError(msg)
    setup = ControllerSetup(model=model, footprint=Footprint.circle(ROBOT_RADIUS),
                            config=config, goal_tolerance=scenario.goal_tolerance)
    if name is ControllerName.PURE_PURSUIT:
        follower = build_controller(name, setup).controller
        follower.set_plan(waypoints_to_poses(scenario.waypoints, float(scenario.start[2]),
                                             float(scenario.goal[2])))
        return follower
    key = MpcKey(name, model, config)
    mpc: Any
    if name is ControllerName.TRACKING:
        mpc = MPC_CACHE.get(key, lambda: build_controller(name, setup).controller)
        mpc.set_plan(np.asarray(scenario.goal, dtype=float)[None, :3])
    else:
        path = WaypointPath(scenario.waypoints, start_heading=float(scenario.start[2]),
                            goal_heading=float(scenario.goal[2]), capacity=PATH_CAPACITY)
        mpc = MPC_CACHE.get(key, lambda: PathReferenceMPC(model, config, path=path))
        mpc.set_path(path)
    # every obstacle: the MPC checks those within reach and gives multipliers to those near
    # its candidate trajectory (constraint generation, see mpc.py)
    mpc.set_obstacles(scenario.obstacles)
    # build the NLPs before the first run, as a robot does at start-up: built mid-step they
    # would cost that step its time budget (their compilation goes on in the background, as
    # in the node: waiting for it takes minutes on a fresh machine)
    MPC_CACHE.prepare_once(key, lambda: mpc.prepare(PREPARED_SLOTS))
    mpc.reset()
    return mpc


def empty_row(task: Task, scenario: Scenario | None, reason: str) -> RunRow:
    """Return the row of a run that did not run (or failed): its identity and the reason."""
    row = RunRow(controller=controller_name(task.controller), world=task.world,
                 success=False, collision=False, stop_reason=reason, v_max=task.v_max,
                 robot=task.robot, sensing=task.sensing)
    if scenario is not None:
        row.name = scenario.name
        row.assumption_1 = scenario.assumption_1
        row.planner_clearance = scenario.planner_clearance
        if scenario.barn_path_length is not None:
            row.barn_score = 0.0
    return row


def finish_row(row: RunRow, run: Rollout, goal: np.ndarray, *, min_clearance: float,
               barn_length: float | None) -> RunRow:
    """Fill in the row's outcome from the run, by one rule for every suite; return the row.

    A run touched an obstacle when it ended in a collision or its true footprint's least
    clearance is <= 0; the BARN score counts only with a BARN path length.
    """
    data = run.rows
    metrics = compute_metrics(data, goal=goal, obstacles=(),
                              solver_failures=run.solver_failures)
    collision = run.outcome is Outcome.COLLISION or min_clearance <= 0.0
    row.success, row.collision, row.contacts = run.reached, collision, int(collision)
    row.time = run.end_time
    row.path_length = metrics['path_length']
    row.min_clearance = min_clearance
    row.solve_ms_median = metrics['solve_ms_median']
    row.solve_ms_max = metrics['solve_ms_max']
    row.final_distance = math.hypot(data[-1, 1] - goal[0], data[-1, 2] - goal[1])
    row.steps = len(data)
    row.solver_failures = run.solver_failures
    row.stop_reason = run.outcome.value + (f': {run.note}' if run.note else '')
    if barn_length is not None:
        row.barn_score = barn_score(run.reached, run.end_time if run.reached else None,
                                    barn_length)
    return row


def navigation_world(task: Task) -> tuple[Robot, World, float | None]:
    """Return the robot, the world and the BARN path length (else None) of a navigation task.

    The robot is the task's (its footprint, its speed limits); the world is the suite's:
    the unknown or dynamic suite's generated one, a world file with the robot's footprint,
    or a BARN world with its obstacles unknown.
    """
    from mpc_local_planner.evaluation import sensing_suites as suites
    from mpc_local_planner.worlds.world import load_world

    robot = replace(suites.ROBOTS[task.robot], v_max=task.v_max, omega_max=task.omega_max)
    if task.suite == 'unknown':
        return robot, suites.unknown_world(task.world, task.seed, robot=robot), None
    if task.suite == 'dynamic':
        from mpc_local_planner.evaluation.dynamic_worlds import dynamic_world

        return robot, dynamic_world(task.world, task.seed, footprint=robot.footprint), None
    if task.suite == 'worlds':
        world = load_world(task.world_file)
        return robot, replace(world, footprint=robot.footprint, robot_radius=0.0), None
    path = _barn_file(task)
    barn_length = float(json.loads(path.read_text(encoding='utf-8'))['barn_path_length'])
    return robot, suites.barn_sensing_world(path, robot), barn_length


def drive_task(task: Task, robot: Robot, world: World) -> SensingResult:
    """Drive one navigation task in process, as its sweep does (the run behind a row).

    Raises:
        PlanningError: if no first plan can be made.

    """
    from mpc_local_planner.evaluation import sensing_suites as suites

    return suites.run_navigation(world, task.controller, robot,
                                 sensing=task.sensing or task.suite in ('unknown', 'dynamic'),
                                 seed=task.seed,
                                 setup=suites.MpcSetup(budget=task.budget, compile=task.compile),
                                 reality=task.reality,
                                 # BARN's robot has odometry and a laser, no localizer
                                 localized=task.suite != 'barn', plant=task.plant,
                                 recoveries=task.recoveries, track_moving=task.track_moving)


def run_navigation_task(task: Task) -> RunRow:
    """Run one world x controller through the navigation stack; return its runs.csv row."""
    from mpc_local_planner.evaluation import sensing_suites as suites

    robot, world, barn_length = navigation_world(task)
    row = RunRow(controller=controller_name(task.controller), world=task.world,
                 name=world.name, robot=task.robot,
                 sensing=task.sensing or task.suite in ('unknown', 'dynamic'),
                 v_max=robot.v_max,
                 reality=task.reality)
    try:
        result = drive_task(task, robot, world)
    except PlanningError as err:
        row.success, row.collision, row.stop_reason = False, False, f'no plan: {err}'
        row.barn_score = 0.0 if barn_length is not None else None
        return row
    run = result.run
    if task.trajectory_dir:
        folder = Path(task.trajectory_dir)
        folder.mkdir(parents=True, exist_ok=True)
        write_trajectory_csv(folder / f'{task.controller}_{task.world:03d}.csv', run.rows)
        plans = result.navigator.log.plans if result.navigator is not None else []
        for number, (_, waypoints, _) in enumerate(plans):
            np.savetxt(folder / f'plan_{task.controller}_{task.world:03d}_{number}.csv',
                       waypoints, delimiter=',', header='x,y', comments='')
    row = replace(row, **suites.result_fields(result))
    return finish_row(row, run, np.asarray(world.goal, dtype=float),
                      min_clearance=result.min_clearance, barn_length=barn_length)


def run_task(task: Task) -> RunRow:
    """Run one world x controller in closed loop and return its runs.csv row."""
    if task.through_nodes:
        from mpc_local_planner.evaluation.through_nodes import run_through_nodes

        robot, world, barn_length = navigation_world(task)
        row = run_through_nodes(task, robot, world)
        if barn_length is not None:
            row.barn_score = barn_score(bool(row.success), row.time if row.success else None,
                                        barn_length)
        return row
    if task.navigation:
        return run_navigation_task(task)
    model = Unicycle(v_max=task.v_max, omega_max=task.omega_max)
    config = MpcConfig(robot_radius=ROBOT_RADIUS,
                       solving=SolverSettings(budget=task.budget, compile=task.compile))
    margin = config.inflation(model.v_max) - ROBOT_RADIUS
    scenario = _scenario(task, margin)
    if controller_name(task.controller) is not ControllerName.TRACKING \
            and scenario.waypoints is None:
        return empty_row(task, scenario, 'no reference path: ' + scenario.note)
    controller = _controller(task, scenario, model, config)
    clearance = _clearance_fn(scenario)
    goal = np.asarray(scenario.goal, dtype=float)
    # success is a position within the goal tolerance: neither suite asks for a heading
    rule = StopRule(time_limit=scenario.time_limit,
                    position_tolerance=scenario.goal_tolerance)
    run = rollout(controller, model, scenario.start, goal, h=config.step, rule=rule,
                  clearance=clearance)
    data = run.rows
    if task.trajectory_dir:
        folder = Path(task.trajectory_dir)
        folder.mkdir(parents=True, exist_ok=True)
        write_trajectory_csv(folder / f'{task.controller}_{task.world:03d}.csv', data)
        if scenario.waypoints is not None:
            np.savetxt(folder / f'path_{task.world:03d}.csv', scenario.waypoints,
                       delimiter=',', header='x,y', comments='')
        if task.suite == 'random':
            save_world(folder, scenario, task.world)
    row = empty_row(task, scenario, '')
    row.reference_length = (polyline_length(scenario.waypoints)
                            if scenario.waypoints is not None else None)
    row.replans = 0
    if len(run.step_times):
        row.step_ms_median = float(np.median(run.step_times)) * 1e3
        row.step_ms_max = float(np.max(run.step_times)) * 1e3
    return finish_row(row, run, goal, min_clearance=float(np.min(clearance(data[:, 1:3]))),
                      barn_length=scenario.barn_path_length)


def saved_world_path(folder: Path, world: int) -> Path:
    """Return where save_world writes a random world beside its runs."""
    return folder / f'world_{world:03d}.json'


def save_world(folder: Path, scenario: Scenario, world: int) -> None:
    """Write what a random world's figure needs (obstacles, start, goal) beside its runs."""
    data = {'name': scenario.name, 'bounds': list(scenario.bounds),
            'obstacles': [o.vertices.tolist() for o in scenario.obstacles],
            'start': np.asarray(scenario.start, dtype=float).tolist(),
            'goal': np.asarray(scenario.goal, dtype=float).tolist(),
            'goal_tolerance': scenario.goal_tolerance}
    saved_world_path(folder, world).write_text(json.dumps(data) + '\n', encoding='utf-8')
