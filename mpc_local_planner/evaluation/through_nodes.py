# SPDX-License-Identifier: Apache-2.0
"""One suite run through the real node processes: what users run is what is measured.

`evaluate --through-nodes` runs each world as a user runs the package: ``closed_loop`` starts
the map server, the planner, the controller and the simulator as separate processes that
talk over DDS, the controller with the package's own parameter files
(config/mpc_controller.yaml, and config/<robot>.yaml for the Jackal) as shipped. The clock
is a lockstep one (ros/lockstep.py): simulated time waits for every control step and plan,
so a row does not depend on the machine's load, and the controller's solve budget is its
iteration limit (as the in-process suites', design.md section 6) unless ``--budget wall``.

What is the suite's, not the nodes': the world (a BARN world with every cylinder unknown,
written as a world file), the robot's actuator limits (the simulator's saturation), the
referee (arrival is the TRUE position within the suite's goal tolerance, as the in-process
rollout's stop rule) and the stall rule. BARN's robot has no localizer: a real base's
odometry is the pose the nodes have (as the in-process suite runs BARN).

Each run gets a DDS domain of its own (claimed with a lock file, so parallel jobs never
share one) and loopback only.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
from pathlib import Path
import subprocess
import sys
import tempfile
from typing import Any, Iterator

import yaml

from mpc_local_planner.core.controllers import controller_name, ControllerName
from mpc_local_planner.evaluation.run_row import RunRow
from mpc_local_planner.process_ties import tied_environment
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import Circle, World

__all__ = ['DOMAIN_RANGE', 'RUN_WALL_LIMIT', 'node_command', 'run_through_nodes',
           'world_yaml']

# DDS domains the runs claim (one each at a time); ids 1-100 leave 0 (ROS's default) alone.
DOMAIN_RANGE = range(1, 101)
# Wall seconds one run may take before closed_loop gives up (a hung process, not a slow one).
RUN_WALL_LIMIT = 1800.0


@contextlib.contextmanager
def claimed_domain() -> Iterator[int]:
    """Hold a DDS domain id no other run of this machine holds (a lock file per id)."""
    folder = Path(tempfile.gettempdir()) / 'mpc_local_planner_domains'
    folder.mkdir(exist_ok=True)
    for domain in DOMAIN_RANGE:
        handle = open(folder / f'{domain}.lock', 'w')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        try:
            yield domain
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
            handle.close()
        return
    msg = f'every DDS domain of {DOMAIN_RANGE} is in use by other runs'
    raise RuntimeError(msg)


def world_yaml(world: World, path: Path) -> Path:
    """Write world as a world file (its obstacles as they are: circles stay circles).

    Moving obstacles are written as the file gave them (their shape in its own frame and
    their trajectory), so the simulator moves them as the rollout does.
    """
    def shape(item: Any) -> dict[str, Any]:
        if isinstance(item, Circle):
            return {'circle': [float(item.x), float(item.y), float(item.radius)]}
        return {'polygon': item.vertices.tolist()}

    known = len(world.obstacles)
    shapes = list(world.true_shapes) if world.true_shapes else [
        *world.obstacles, *world.unknown_obstacles]
    data: dict[str, Any] = {
        'bounds': [float(v) for v in world.bounds],
        'obstacles': [shape(item) for item in shapes[:known]],
        'unknown_obstacles': [shape(item) for item in shapes[known:]],
        'start': [float(v) for v in world.start],
        'goal': [float(v) for v in world.goal],
    }
    if world.moving_obstacles:
        data['moving_obstacles'] = [dict([next(iter(shape(m.shape).items())),
                                          m.trajectory.spec()])
                                    for m in world.moving_obstacles]
    if world.footprint.is_circle:
        data['robot_radius'] = float(world.robot_radius)
    else:
        data['footprint'] = world.footprint.vertices.tolist()
    if world.time_limit:
        data['time_limit'] = float(world.time_limit)
    if world.goal_tolerance:
        data['goal_tolerance'] = float(world.goal_tolerance)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f'# {world.name}, written for a run through the nodes\n'
                    + yaml.safe_dump(data, sort_keys=False, default_flow_style=None),
                    encoding='utf-8')
    return path


def node_command(world_file: Path, out: Path, *, robot: str, v_max: float, omega_max: float,
                 time_limit: float, goal_tolerance: float, stall_seconds: float, seed: int,
                 reality: str, budget: str, plant: str = 'kinematic',
                 recoveries: bool = False, track_moving: bool = False) -> list[str]:
    """Return the closed_loop command of one run (the user's parameter files as shipped).

    plant is the simulator's (closed_loop --plant: kinematic, or the MuJoCo robot of the
    world's footprint). recoveries is the controller's (on by default in the node, off in
    the suites unless asked: the flag is passed either way, so both paths run the same).
    track_moving is both nodes' (their memories track the scans' clusters; off by default
    in both).
    """
    files = [resolve_data_file('mpc_controller.yaml')]
    if robot == 'jackal':
        files.append(resolve_data_file('jackal.yaml'))
    command = [sys.executable, '-m', 'mpc_local_planner.ros.closed_loop',
               '--world', str(world_file), '--out', str(out), '--path', 'rrt', '--sensing',
               '--separate-processes', '--lockstep', '--no-localizer',
               '--time-limit', repr(float(time_limit)), '--referee-radius',
               repr(float(goal_tolerance)), '--stall-seconds', repr(float(stall_seconds)),
               '--seed', str(int(seed)), '--reality', reality, '--plant', plant,
               '--timeout', repr(RUN_WALL_LIMIT)]
    for file in files:
        command += ['--params-file', str(file)]
    # the robot's motors (the simulator's saturation), not the controller's tuning
    command += ['--param', f'unicycle_simulator.v_max:={float(v_max)!r}',
                '--param', f'unicycle_simulator.omega_max:={float(omega_max)!r}']
    if budget == 'iterations':
        command += ['--param', 'mpc_controller.budget:=iterations']
    command += ['--param', f'mpc_controller.recoveries:={str(bool(recoveries)).lower()}']
    tracking = str(bool(track_moving)).lower()
    command += ['--param', f'mpc_controller.track_moving:={tracking}',
                '--param', f'global_planner.track_moving:={tracking}']
    return command


def run_through_nodes(task: Any, robot: Any, world: World) -> RunRow:
    """Run one navigation task (its robot, its world) through the node processes.

    Returns its runs.csv row without the BARN score (the suite's to add).

    Raises:
        ValueError: for a controller other than the paper's MPC (the only one with a node).

    """
    from mpc_local_planner.evaluation import sensing_suites as suites

    if controller_name(task.controller) is not ControllerName.PROPOSED:
        msg = (f'--through-nodes runs the mpc_controller node: {task.controller} has none '
               '(run it in process, beside)')
        raise ValueError(msg)
    folder = Path(task.through_nodes) / f'{task.suite}_{task.world:03d}'
    world_file = world_yaml(world, folder / 'world.yaml')
    time_limit = float(world.time_limit or 100.0)
    command = node_command(world_file, folder / 'run', robot=task.robot, v_max=robot.v_max,
                           omega_max=robot.omega_max, time_limit=time_limit,
                           goal_tolerance=float(world.goal_tolerance or suites.GOAL_TOLERANCE),
                           stall_seconds=suites.STALL_SECONDS, seed=task.seed,
                           reality=task.reality, budget=task.budget, plant=task.plant,
                           recoveries=task.recoveries, track_moving=task.track_moving)
    row = RunRow(controller=controller_name(task.controller), world=task.world,
                 name=world.name, robot=task.robot, sensing=True, v_max=robot.v_max,
                 reality=task.reality)
    with claimed_domain() as domain:
        # closed_loop (and its nodes) end with this worker, even one killed outright
        env = tied_environment({**os.environ, 'ROS_DOMAIN_ID': str(domain),
                                'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'})
        with open(folder / 'closed_loop.log', 'w', encoding='utf-8') as log:
            code = subprocess.run(command, stdout=log, stderr=subprocess.STDOUT, env=env,
                                  check=False).returncode
    metrics_file = folder / 'run' / 'metrics.json'
    if not metrics_file.exists():
        row.success, row.collision = False, False
        row.stop_reason = f'closed_loop exited {code} without metrics (see {folder})'
        return row
    metrics = json.loads(metrics_file.read_text(encoding='utf-8'))
    reached = metrics.get('referee_time') is not None
    contacts = int(metrics.get('contacts') or 0)
    row.success = reached and contacts == 0 and code == 0
    row.collision = contacts > 0
    row.contacts = int(contacts > 0)
    # the split as the rollout's rows give it: 1 when such a contact happened
    row.active_contacts = int((metrics.get('active_contacts') or 0) > 0)
    row.passive_contacts = int((metrics.get('passive_contacts') or 0) > 0)
    row.time = float(metrics['referee_time'] if reached else metrics['sim_time'])
    row.path_length = metrics.get('path_length')
    row.min_clearance = metrics.get('min_clearance')
    row.solve_ms_median = metrics.get('solve_ms_median')
    row.solve_ms_max = metrics.get('solve_ms_max')
    row.final_distance = metrics.get('true_goal_error')
    row.steps = metrics.get('steps')
    row.solver_failures = metrics.get('solver_failures')
    row.replans = metrics.get('replans')
    row.recoveries = metrics.get('recoveries')
    row.recovery_s = metrics.get('recovery_s')
    stalls = metrics.get('lockstep_stalls') or 0
    row.stop_reason = str(metrics.get('stop_reason')) + (
        f' ({stalls} lockstep stalls)' if stalls else '')
    return row
