# SPDX-License-Identifier: Apache-2.0
"""What mpc_bench measures: each section's runs, returned as plain data (dicts of figures).

The `bench` command (``mpc_bench``) chooses the sections, prints their tables and writes the
JSON; its module docstring says what each section measures and on which scenario.
"""

from __future__ import annotations

import csv
from dataclasses import replace
import math
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np

from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import PathReferenceMPC
from mpc_local_planner.core.mpc.built_nlps import clear_shared_nlps
from mpc_local_planner.core.mpc.compilation import COMPILE_FLAGS, NO_OBSTACLE_COMPILE_FLAGS
from mpc_local_planner.core.obstacles import ConvexPolygon, within_faces
from mpc_local_planner.core.paths import paper_sinusoid, ReferencePath, wrap_angle
from mpc_local_planner.core.planner import RrtStarPlanner
from mpc_local_planner.core.planner_config import PlannerConfig
from mpc_local_planner.evaluation.opti_peer import OptiMpc
from mpc_local_planner.evaluation.rollout import rollout, StopRule
from mpc_local_planner.evaluation.run_row import RunRow
from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.perception.scan_obstacles import ObstacleMemory, scan_to_obstacles
from mpc_local_planner.sim.contact import contact
from mpc_local_planner.sim.laser import SimulatedLaser
from mpc_local_planner.worlds.data_files import BARN_DIR
from mpc_local_planner.worlds.world import load_barn_world, paper_world, World

__all__ = [
    'barn_line_poses',
    'bench_cold_start',
    'bench_control_rate',
    'bench_footprint',
    'bench_laser',
    'bench_rrt',
    'bench_scan_control',
    'bench_scan_obstacles',
    'closed_loop',
    'extra_obstacles',
    'paper_obstacle',
    'stats',
    'verdict',
]

STEP = 0.2
# closed_loop's name of the Opti + IPOPT peer (OptiMpc), in the table's backend column.
PEER = 'opti+ipopt warm'
HORIZONS = (10, 20, 40)
OBSTACLE_COUNTS = (1, 5, 20)
# Stop a closed loop when the robot is this close to the target (and count it as reached;
# headings compared wrapped).
REACHED_POSITION = 0.02
REACHED_HEADING = 0.05
# Perception rows: BARN world 0, the Jackal-like 720-beam laser, the targets they are held to.
BARN_WORLD = 'world_000.json'
BARN_ROBOT_RADIUS = 0.2
LASER_BEAMS = 720
OBSTACLE_TTL = 2.0  # s, the obstacle memory's time to live
# The pose sweep: a 10 Hz laser on a robot driving the start-goal line at 0.5 m/s.
SCAN_PERIOD = 0.1  # s
SWEEP_SPEED = 0.5  # m/s
TARGET_LASER_MS = 2.0
TARGET_SCAN_OBSTACLES_MS = 2.0
TARGET_CONTROL_STEP_MS = 5.0
# Clearance (m) of the RRT* plans the control-step rows follow (for a polygon: of every pose).
PLAN_CLEARANCE = 0.05
# Polygon footprint rows (the "polygon footprint" issue): the Jackal at N = 10, held to these
# targets (medians).
# 'barn_map' is BARN world 0 with its obstacles known (no laser): the MPC's step without the
# perception's share, which 'barn' (scan obstacles, as the perception rows) includes.
FOOTPRINT_SCENARIOS = ('paper', 'barn', 'barn_map')
FOOTPRINT_HORIZON = 10
TARGET_FOOTPRINT_SOLVE_MS = 2.0
TARGET_FOOTPRINT_STEP_MS = TARGET_CONTROL_STEP_MS
# The control-rate rows: commands per second (ControllerSettings.control_frequency, the
# node's default), and the MPC's horizon there.
CONTROL_FREQUENCY = 20.0
RATE_HORIZON = 10
# Cold start (issue 24): the first laser-only BARN run of the paper's MPC, as a new user runs
# it, with an empty compile cache and then again with the cache it filled; the target is for
# the cold one (on a fresh machine, from the command to the finished run).
COLD_START_ARGS = ('--suite', 'barn', '--sensing', '--robot', 'jackal', '--v-max', '2.0',
                   '--omega-max', '4.0', '--worlds', '0', '--jobs', '1')
TARGET_COLD_START_S = 60.0


def paper_obstacle() -> ConvexPolygon:
    """Return the paper's box (1, -1)-(1.5, 1)."""
    return ConvexPolygon.from_box(1.0, -1.0, 1.5, 1.0)


def extra_obstacles(count: int, path: ReferencePath) -> list[ConvexPolygon]:
    """Return count small boxes beside the path, on the side away from the paper's box.

    They sit 0.4 to 0.5 m from the path (the horizon reaches 0.62 m at N = 10), so each one
    enters the problem at some time without blocking the way.
    """
    boxes = []
    centre = np.array([1.25, 0.0])
    for i, s in enumerate(np.linspace(0.03, 0.97, count)):
        pose = path.pose(float(s))
        normal = np.array([-math.sin(pose[2]), math.cos(pose[2])])
        if normal @ (pose[:2] - centre) < 0:
            normal = -normal
        c = pose[:2] + (0.42 + 0.08 * (i % 2)) * normal
        boxes.append(ConvexPolygon.from_box(c[0] - 0.05, c[1] - 0.05, c[0] + 0.05, c[1] + 0.05))
    return boxes


def stats(values: list[float], tail: int = 95) -> dict[str, float]:
    """Return the median, the tail-th percentile (key 'p<tail>') and the max; NaN if empty."""
    a = np.asarray(values, dtype=float)
    key = f'p{tail}'
    if a.size == 0:
        return {'median': math.nan, key: math.nan, 'max': math.nan}
    return {'median': float(np.median(a)), key: float(np.percentile(a, tail)),
            'max': float(np.max(a))}


def closed_loop(solver: str, horizon: int, obstacles: list[ConvexPolygon], *,
                max_steps: int, compile_functions: bool = True) -> dict[str, Any]:
    """Run the paper's scenario in closed loop (evaluation.rollout); return timings and outcome.

    solver is a backend of SolverSettings.solver or PEER (the `OptiMpc` peer). A first closed loop
    builds (for the package's backends, and compiles) the NLPs it meets, and the peer's
    IPOPT instance; the timed one reuses them, the peer starting cold again. A run
    ends within REACHED_POSITION and REACHED_HEADING of the target (headings wrapped) or
    after max_steps solves (every recorded state is solved for, the final one included).
    """
    model, path = Unicycle(), paper_sinusoid()
    if solver == PEER:
        config = MpcConfig(horizon=horizon, step=STEP)
        controller: Any = OptiMpc(model, config, obstacles, path)
    else:
        config = MpcConfig(horizon=horizon, step=STEP,
                           solving=SolverSettings(solver=solver, compile=compile_functions))
        clear_shared_nlps()  # the first run builds its NLPs, as in a new process
        controller = PathReferenceMPC(model, config, obstacles=obstacles, path=path)
    runs = 2
    # No stall rule: a controller that stops in front of the box has its solves there timed
    # for the whole run, as the published tables were.
    rule = StopRule(time_limit=(max_steps - 1) * STEP, position_tolerance=REACHED_POSITION,
                    heading_tolerance=REACHED_HEADING, stall_steps=max_steps + 2)
    warmup: dict[str, Any] = {}
    for run in range(runs):
        result = rollout(controller, model, path.start, path.goal, h=STEP, rule=rule)
        if run == 0 and runs == 2:
            warmup = {'step_ms': stats(list(1e3 * result.step_times))}
            if solver != PEER:
                controller.wait_compiled()
            controller.reset()
    details = [step.detail for step in result.steps]
    iterations = [int(getattr(d, 'iterations', 0)) for d in details]
    in_reach = [d.obstacles_in_reach for d in details if hasattr(d, 'obstacles_in_reach')]
    active = [d.obstacles_active for d in details if hasattr(d, 'obstacles_active')]
    xy = result.rows[:, 1:3]
    return {
        'solver': solver if solver == PEER or not compile_functions else f'{solver}+compiled',
        'horizon': horizon, 'obstacles': len(obstacles), 'steps': len(result.steps),
        'solve_ms': stats(list(1e3 * result.solve_times)),
        'step_ms': stats(list(1e3 * result.step_times)),
        'iterations_median': float(np.median(iterations)),
        'iterations_max': int(np.max(iterations)),
        'in_reach_max': int(max(in_reach, default=len(obstacles))),
        'in_reach_median': float(np.median(in_reach)) if in_reach else float(len(obstacles)),
        'active_max': int(max(active, default=len(obstacles))),
        'active_median': float(np.median(active)) if active else float(len(obstacles)),
        'reached': result.reached, 'outcome': result.outcome.value,
        'path_length': float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1))),
        'collision': any(bool(np.any(o.contains(xy))) for o in obstacles),
        'failures': result.solver_failures,
        'lyapunov_violations': sum(1 for ok in result.lyapunov_ok if ok is False),
        'first_run': warmup,
    }


def bench_rrt(repeats: int) -> dict[str, Any]:
    """Time RrtStarPlanner for 1000 iterations on config/worlds/rrt_cluttered.yaml."""
    from mpc_local_planner.core.planner import PlannerConfig, RrtStarPlanner
    from mpc_local_planner.worlds.data_files import resolve_data_file
    from mpc_local_planner.worlds.world import load_world

    world = load_world(resolve_data_file('worlds/rrt_cluttered.yaml'))
    times = []
    for seed in range(repeats):
        planner = RrtStarPlanner(world.obstacles, world.bounds, config=PlannerConfig(
            iterations=1000, seed=seed, robot_radius=float(world.robot_radius),
            time_limit=60.0))
        start = time.perf_counter()
        planner.plan(world.start, world.goal)
        times.append(1e3 * (time.perf_counter() - start))
    return {'iterations': 1000, 'plans': repeats, 'plan_ms': stats(times)}


def _barn_world() -> World:
    return load_barn_world(BARN_DIR / BARN_WORLD, robot_radius=BARN_ROBOT_RADIUS)


def barn_line_poses(world: World, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Return up to count poses along start-goal, heading to the goal, and their stamps.

    The poses are SWEEP_SPEED * SCAN_PERIOD apart from the start on (the scans a robot
    driving the line would take), at most to the goal; those where the robot's disk would
    touch an obstacle are left out.

    Returns:
        ((K, 3) x, y, yaw; (K,) stamps in seconds).

    """
    start, goal = world.start[:2], world.goal[:2]
    length = float(np.hypot(*(goal - start)))
    yaw = math.atan2(goal[1] - start[1], goal[0] - start[0])
    geometry = TrueGeometry.from_world(world)
    distance = np.arange(count) * SWEEP_SPEED * SCAN_PERIOD
    distance = distance[distance <= length]
    points = start + (distance / length)[:, None] * (goal - start)
    free = np.array([not contact(geometry, float(p[0]), float(p[1]), world.robot_radius)
                     for p in points])
    poses = np.column_stack([points, np.full(len(points), yaw)])[free]
    return poses, distance[free] / SWEEP_SPEED


def _timed_ms(function: Any, *args: Any, **kwargs: Any) -> tuple[float, Any]:
    start = time.perf_counter()
    result = function(*args, **kwargs)
    return 1e3 * (time.perf_counter() - start), result


def bench_laser(poses: int) -> dict[str, Any]:
    """Time SimulatedLaser.scan (720 beams) on BARN world 0 at poses along its start-goal line."""
    world = _barn_world()
    laser = SimulatedLaser(TrueGeometry.from_world(world), beams=LASER_BEAMS)
    sweep, stamps = barn_line_poses(world, poses)
    laser.scan(sweep[0])  # first call outside the timing
    times = [_timed_ms(laser.scan, pose, stamp=stamp)[0]
             for pose, stamp in zip(sweep, stamps, strict=True)]
    return {'world': BARN_WORLD, 'beams': LASER_BEAMS, 'scans': len(times),
            'scan_ms': stats(times), 'target_ms': TARGET_LASER_MS}


def bench_scan_obstacles(poses: int) -> dict[str, Any]:
    """Time scan_to_obstacles and ObstacleMemory.update on BARN world 0 along its line.

    The scans are taken in order along the line as a robot driving it would take them
    (`barn_line_poses`), so that the memory holds what it would remember (update includes
    scan_to_obstacles).
    """
    world = _barn_world()
    laser = SimulatedLaser(TrueGeometry.from_world(world), beams=LASER_BEAMS)
    sweep, stamps = barn_line_poses(world, poses)
    scans = [laser.scan(pose, stamp=stamp) for pose, stamp in zip(sweep, stamps, strict=True)]
    convert, pieces = [], []
    for scan, pose in zip(scans, sweep, strict=True):
        ms, obstacles = _timed_ms(scan_to_obstacles, scan, pose)
        convert.append(ms)
        pieces.append(len(obstacles))
    memory = ObstacleMemory(OBSTACLE_TTL)
    update, remembered = [], []
    for scan, pose in zip(scans, sweep, strict=True):
        update.append(_timed_ms(memory.update, scan, pose)[0])
        remembered.append(len(memory))
    return {'world': BARN_WORLD, 'beams': LASER_BEAMS, 'scans': len(scans),
            'scan_to_obstacles_ms': stats(convert), 'memory_update_ms': stats(update),
            'obstacles_per_scan_median': float(np.median(pieces)),
            'remembered_median': float(np.median(remembered)),
            'remembered_max': int(max(remembered)), 'ttl_s': OBSTACLE_TTL,
            'target_ms': TARGET_SCAN_OBSTACLES_MS}


def _reference(world: World, footprint: Footprint | None = None) -> tuple[np.ndarray, str]:
    """Return (M, 3) poses of an RRT* path of the world (or its straight line) and its kind.

    With a polygon footprint the plan is made for it (RrtStarPlanner checks every pose of the
    path, turns in place included, to keep PLAN_CLEARANCE): the MPC's Assumption 1 asks
    the followed path to be clear for the robot's actual shape, and a plan for a disc says
    nothing about a rectangle's corners.
    """
    robot: dict[str, Any] = ({'robot_radius': world.robot_radius} if footprint is None
                             else {'footprint': footprint})
    config = PlannerConfig(iterations=3000, time_limit=30.0, seed=0, range=0.5,
                           clearance=PLAN_CLEARANCE, **robot)
    try:
        points = RrtStarPlanner(world.obstacles, world.bounds, config=config).plan(
            world.start, world.goal)
        kind = f'RRT* ({len(points)} waypoints)'
        if footprint is not None:
            length = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
            kind = (f'RRT* plan for the footprint ({len(points)} waypoints, {length:.2f} m, '
                    f'clearance {PLAN_CLEARANCE:g} m)')
    except PlanningError:
        points = np.array([world.start[:2], world.goal[:2]])
        kind = 'straight start-goal line (RRT* found no path)'
    headings = np.arctan2(np.diff(points[:, 1]), np.diff(points[:, 0]))
    yaw = np.concatenate([[world.start[2]], headings[1:], [world.goal[2]]])
    return np.column_stack([points, yaw]), kind


def _control_run(world: World, poses: np.ndarray, steps: int, controller: MpcController,
                 *, sensing: bool = True) -> dict[str, Any]:
    """Drive the plan in closed loop for at most steps control steps; return what was timed.

    sensing: obstacles come from the simulated laser through the obstacle memory, and the
    timed step includes the memory's update and set_obstacles (a robot without a map does
    that work every step); else the controller keeps the obstacles it was built with (the
    world's, known) and the timed step is MpcController.compute alone. Contacts are checked
    with the world's footprint at the robot's heading (exact for a polygon).
    """
    model = controller.model
    config = controller.config
    geometry = TrueGeometry.from_world(world)
    laser = SimulatedLaser(geometry, beams=LASER_BEAMS) if sensing else None
    memory = ObstacleMemory(OBSTACLE_TTL)
    controller.set_plan(poses)
    # config.reach covers a polygon's circumscribed radius too; 0.5 m more so that an
    # obstacle is known before the horizon can reach it
    reach = config.reach(float(model.u_max[0])) + 0.5
    x = np.array(world.start, dtype=float)
    update_ms, set_solve_ms, step_ms, nlp_ms = [], [], [], []
    in_memory, in_reach, active = [], [], []
    contacts, reached, failures, timeouts = 0, False, 0, 0
    for k in range(steps):
        t = k * config.step
        scan = laser.scan(x, stamp=t) if laser is not None else None
        start = time.perf_counter()
        if scan is not None:
            memory.update(scan, x)
            nearby = within_faces(memory.obstacles(x[:2], reach),
                                  config.solving.faces_per_obstacle)
        middle = time.perf_counter()
        if scan is not None:
            controller.set_obstacles(nearby)
        output = controller.compute(x, None, t)
        end = time.perf_counter()
        update_ms.append(1e3 * (middle - start))
        set_solve_ms.append(1e3 * (end - middle))
        step_ms.append(1e3 * (end - start))
        solution = output.solution
        if scan is not None:
            in_memory.append(len(memory))
            in_reach.append(len(nearby))
        elif solution is not None:
            in_reach.append(solution.obstacles_in_reach)
        if solution is not None:
            nlp_ms.append(1e3 * solution.solve_time_s)
            active.append(solution.obstacles_active)
            failures += int(not solution.success)
            # MpcSolution.timed_out: the step's solving ran out of config.solve_budget()
            timeouts += int(getattr(solution, 'timed_out', False))
        if output.reason is Reason.GOAL_REACHED:
            reached = True
            break
        x = model.step(x, output.u, config.step)
        contacts += int(contact(geometry, float(x[0]), float(x[1]), world.footprint,
                                float(x[2])))
    goal_distance = float(np.hypot(x[0] - world.goal[0], x[1] - world.goal[1]))
    return {'steps': len(step_ms), 'step_ms': stats(step_ms),
            'memory_update_ms': stats(update_ms), 'set_and_solve_ms': stats(set_solve_ms),
            'solve_ms': stats(nlp_ms),
            'remembered_median': float(np.median(in_memory)) if in_memory else 0.0,
            'in_reach_median': float(np.median(in_reach)) if in_reach else 0.0,
            'in_reach_max': int(max(in_reach, default=0)),
            'active_median': float(np.median(active)) if active else 0.0,
            'active_max': int(max(active, default=0)),
            'reached': reached, 'goal_distance': goal_distance,
            'heading_error': abs(float(wrap_angle(x[2] - world.goal[2]))),
            'contact_steps': contacts, 'not_solved_steps': failures,
            'timed_out_steps': timeouts}


def bench_scan_control(steps: int) -> dict[str, Any]:
    """Time the control step with scan obstacles on BARN world 0 (ROS-free, N = 10).

    Each step: the laser scans from the true world (not timed), then the timed part: the
    obstacle memory's update, the remembered obstacles within the horizon's reach (fitted
    to the NLP's faces per obstacle, as the controller node fits them) set on the
    MpcController, and its compute (the MPC solve and its checks); the plant is
    Unicycle().step. A first, untimed run along the same path builds (and compiles) the NLPs
    the timed run meets.
    """
    world = _barn_world()
    poses, kind = _reference(world)
    config = MpcConfig(horizon=10, step=STEP, robot_radius=world.robot_radius)
    settings = ControllerSettings(xy_goal_tolerance=0.1, yaw_goal_tolerance=math.pi,
                                  capacity=2 * len(poses) + 1)
    controller = MpcController(Unicycle(), config, settings=settings)
    _control_run(world, poses, steps, controller)  # builds the NLPs it meets
    controller.mpc.wait_compiled()
    controller.clear_path()
    result = _control_run(world, poses, steps, controller)
    return {'world': BARN_WORLD, 'horizon': config.horizon, 'solver': config.solving.solver,
            'reference': kind, 'target_ms': TARGET_CONTROL_STEP_MS, 'max_steps': steps,
            **result}


def _footprint_world(scenario: str, footprint: Footprint) -> World:
    """Return the scenario's world with the robot's shape set to footprint."""
    if scenario == 'paper':
        return replace(paper_world(), footprint=footprint, robot_radius=0.0)
    if scenario in ('barn', 'barn_map'):
        return load_barn_world(BARN_DIR / BARN_WORLD, footprint=footprint)
    msg = f'unknown footprint scenario {scenario!r}; expected one of {FOOTPRINT_SCENARIOS}'
    raise ValueError(msg)


def bench_footprint(scenario: str, steps: int, *, footprint: Footprint = JACKAL,
                    compile_functions: bool = True) -> dict[str, Any]:
    """Time the control step of a polygon footprint, N = 10, along an RRT* plan made for it.

    scenario 'paper': the paper's box, start and goal; the obstacles are known (set once, as
    in the paper's rows) and the timed step is MpcController.compute. The paper's sinusoid
    is not the reference: it crosses the box for the Jackal's rectangle (Assumption 1 fails
    for that path: the MPC stops in front of the box, and its solves there are slow), so the
    path is an RRT* plan for the footprint (PLAN_CLEARANCE) between the same poses.
    scenario 'barn': BARN world 0 with scan obstacles, the same timed step as
    bench_scan_control (memory update, set_obstacles, compute), along the world's RRT* plan
    for the footprint. 'barn_map': the same world and plan with its obstacles known (set
    once) and the step MpcController.compute, as on the paper's box: what the MPC costs
    without the perception's share.

    A first, untimed run along the same plan builds the NLPs it meets; with
    compile_functions it also waits for their compilation (gcc, about a minute per NLP
    shape on a loaded two-core machine, cached on disk: slow the first time only), which is
    set-up, not a step's work. The solve time is MpcSolution.solve_time_s (the NLP solver
    calls); the step time is the whole timed step.
    """
    world = _footprint_world(scenario, footprint)
    poses, kind = _reference(world, footprint)
    vertices = tuple((float(px), float(py)) for px, py in np.asarray(footprint.vertices))
    config = MpcConfig(horizon=FOOTPRINT_HORIZON, step=STEP, footprint=vertices,
                       solving=SolverSettings(compile=compile_functions))
    # the paper's rows stop within REACHED_POSITION and REACHED_HEADING; BARN scores the
    # position only, as bench_scan_control does
    tolerances = ((REACHED_POSITION, REACHED_HEADING) if scenario == 'paper'
                  else (0.1, math.pi))
    settings = ControllerSettings(xy_goal_tolerance=tolerances[0],
                                  yaw_goal_tolerance=tolerances[1],
                                  capacity=2 * len(poses) + 1)
    sensing = scenario == 'barn'
    known = () if sensing else world.obstacles
    clear_shared_nlps()  # warmup_s: the NLPs' builds, as in a new process
    controller = MpcController(Unicycle(), config, obstacles=known, settings=settings)
    started = time.perf_counter()
    _control_run(world, poses, steps, controller, sensing=sensing)  # builds the NLPs
    controller.mpc.wait_compiled()
    warmup_s = time.perf_counter() - started
    controller.clear_path()
    result = _control_run(world, poses, steps, controller, sensing=sensing)
    label = {'paper': "paper's box, RRT* for it", 'barn': 'BARN world 0, scans, RRT* for it',
             'barn_map': 'BARN world 0, map, RRT* for it'}[scenario]
    return {'scenario': scenario, 'label': label,
            'world': 'paper_obstacle' if scenario == 'paper' else BARN_WORLD,
            'footprint': [list(v) for v in vertices], 'horizon': config.horizon,
            'solver': config.solving.solver if not compile_functions
            else f'{config.solving.solver}+compiled',
            'obstacles': 'scan' if sensing else 'known', 'reference': kind,
            'max_steps': steps, 'warmup_s': warmup_s,
            'target_solve_ms': TARGET_FOOTPRINT_SOLVE_MS,
            'target_step_ms': TARGET_FOOTPRINT_STEP_MS,
            'solve_verdict': verdict(result['solve_ms'], TARGET_FOOTPRINT_SOLVE_MS),
            'step_verdict': verdict(result['step_ms'], TARGET_FOOTPRINT_STEP_MS),
            **result}


def _rate_run(controller: MpcController, calls: int) -> dict[str, Any]:
    """Drive the paper's sinusoid with compute at CONTROL_FREQUENCY; time each call."""
    model, dt = controller.model, 1.0 / CONTROL_FREQUENCY
    controller.set_path(paper_sinusoid())
    x = np.array(paper_sinusoid().start, dtype=float)
    solves, holds, reached = [], [], False
    for k in range(calls):
        start = time.perf_counter()
        output = controller.compute(x, None, k * dt)
        elapsed = 1e3 * (time.perf_counter() - start)
        # a solve: fresh with a solution; a hold: not fresh (stops and turns are neither)
        if output.fresh and output.solution is not None:
            solves.append(elapsed)
        elif not output.fresh:
            holds.append(elapsed)
        if output.reason is Reason.GOAL_REACHED:
            reached = True
            break
        x = model.step(x, output.u, dt)
    return {'solve_calls': solves, 'hold_calls': holds, 'reached': reached,
            'calls': k + 1 if calls else 0}


def bench_control_rate(calls: int, *, compile_functions: bool = True) -> dict[str, Any]:
    """Time MpcController.compute at CONTROL_FREQUENCY on the paper's scenario (N = 10).

    A closed loop on the model (the plant integrates each call's command over 1 /
    CONTROL_FREQUENCY) with calls at t = k / CONTROL_FREQUENCY: the MPC solves at one call
    in step * CONTROL_FREQUENCY (four at h = 0.2 s), the others apply the last verified
    plan's input after the safety checks. An untimed first run builds (and compiles) the
    NLPs. Reported apart: the solving calls, the holding calls, and all calls together.
    """
    config = MpcConfig(horizon=RATE_HORIZON, step=STEP,
                       solving=SolverSettings(compile=compile_functions))
    settings = ControllerSettings(xy_goal_tolerance=REACHED_POSITION,
                                  yaw_goal_tolerance=REACHED_HEADING,
                                  control_frequency=CONTROL_FREQUENCY)
    controller = MpcController(Unicycle(), config, obstacles=[paper_obstacle()],
                               settings=settings)
    _rate_run(controller, calls)  # builds the NLPs it meets
    controller.mpc.wait_compiled()
    controller.clear_path()
    run = _rate_run(controller, calls)
    solves, holds = run['solve_calls'], run['hold_calls']
    return {'frequency': CONTROL_FREQUENCY, 'step': STEP, 'horizon': config.horizon,
            'solver': config.solving.solver if not compile_functions
            else f'{config.solving.solver}+compiled',
            'max_calls': calls, 'calls': run['calls'], 'reached': run['reached'],
            'solves': len(solves), 'holds': len(holds),
            # p99: a timer's period must hold the tail, not the median
            'solve_ms': stats(solves, tail=99), 'hold_ms': stats(holds, tail=99),
            'all_ms': stats(solves + holds, tail=99)}


def verdict(figures: dict[str, float], target: float) -> str:
    """Say whether the median meets the target, as every target row of the tables does."""
    return 'met' if figures['median'] <= target else 'MISSED'


def _evaluate_once(controllers: str, cache: Path, out: Path) -> dict[str, Any]:
    """Run the cold-start command in a fresh interpreter; return its wall time and row."""
    command = [sys.executable, '-m', 'mpc_local_planner.evaluation.evaluate', *COLD_START_ARGS,
               '--controllers', controllers, '--out', str(out)]
    env = {**os.environ, 'MPC_LOCAL_PLANNER_CACHE': str(cache)}
    start = time.perf_counter()
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        msg = f'{" ".join(command)} failed: {done.stderr.strip()[-500:]}'
        raise RuntimeError(msg)
    with open(out / 'runs.csv', encoding='utf-8', newline='') as f:
        row = RunRow.from_csv(next(csv.DictReader(f)))
    solve = row.solve_ms_median
    return {'seconds': seconds, 'solve_ms_median': solve if solve is not None else math.nan,
            'success': bool(row.success)}


def bench_cold_start(repeats: int, *, controllers: str = 'proposed') -> dict[str, Any]:
    """Time the first BARN run from an empty compile cache, then again with the cache full.

    Each repeat gets a fresh temporary cache folder ($MPC_LOCAL_PLANNER_CACHE: the user's
    own cache is not touched) and runs the command twice in new interpreters: cold (every
    NLP built, its C generated and compiled) and warm (the libraries loaded from the cache).
    """
    cold, warm = [], []
    libraries: list[int] = []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory(prefix='mpc_cold_start_') as tmp:
            cache = Path(tmp) / 'cache'
            cache.mkdir()
            cold.append(_evaluate_once(controllers, cache, Path(tmp) / 'cold'))
            libraries.append(len(list(cache.glob('*.so'))))
            warm.append(_evaluate_once(controllers, cache, Path(tmp) / 'warm'))
    return {
        'command': ' '.join(['evaluate', *COLD_START_ARGS, '--controllers', controllers]),
        'repeats': repeats, 'target_cold_s': TARGET_COLD_START_S,
        'compile_flags': list(COMPILE_FLAGS),
        'no_obstacle_compile_flags': list(NO_OBSTACLE_COMPILE_FLAGS),
        'cold_s': stats([r['seconds'] for r in cold]),
        'warm_s': stats([r['seconds'] for r in warm]),
        'cold_solve_ms_median': float(np.median([r['solve_ms_median'] for r in cold])),
        'warm_solve_ms_median': float(np.median([r['solve_ms_median'] for r in warm])),
        'success': all(r['success'] for r in cold + warm),
        'libraries_after_cold': libraries,
    }
