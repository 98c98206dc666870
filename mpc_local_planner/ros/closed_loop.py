# SPDX-License-Identifier: Apache-2.0
"""closed_loop: planner, controller, simulator and recorder over DDS, to the goal.

By default the four nodes share one process and a SingleThreadedExecutor; with
``--separate-processes`` the planner, the controller and the simulator run as three OS
processes (``python -m mpc_local_planner.<module> --ros-args -p ...``, so no ros2cli is
needed) and this process records and watches. The simulator drives ``/clock`` at ``--rtf``
times real time and every node uses sim time. The run stops when the controller reports
the goal reached, at the world's (or ``--time-limit``) simulated time limit, or at the
``--timeout`` in wall seconds. Then the bag (which records the world in its metadata) is
analysed: ``--out`` receives ``bag/``, ``trajectory.csv``, ``metrics.json`` and
``trajectory.png``. Exit code 0 iff the target was reached without collision.

With ``--path rrt`` no plan may come: a start or goal inside the obstacles as the planner
inflates them (robot radius + clearance) is refused before anything starts, and a goal the
planner cannot reach (walled off) ends the run as soon as the planner says so on
``planner/diagnostics``. Either way the reason is one line on stderr and the exit code is 2,
as for an invalid option.

With ``--respawn`` (separate processes only) a node process that exits is started again, as
launch's ``respawn``, instead of ending the run: kill the controller mid-run and the
simulator stops the robot after ``cmd_timeout``, then the new controller gets ``/plan``
(transient_local) and drives on. A process that refuses its parameters (exit code 2) is not
started again, and at most MAX_RESPAWNS restarts happen per run.

The simulator always holds the TRUE world (the world file's known and unknown obstacles) and
counts contact episodes on ``simulator/contacts``; ``metrics.json`` reports ``contacts`` (and of
them ``active_contacts``, the robot moving, and ``passive_contacts``, run into standing) and a
run with a contact fails (exit code 1). With ``--sensing`` no node but the simulator reads the
world's obstacles: a ``map_server`` serves a map of the KNOWN obstacles (rasterised at
MAP_RESOLUTION into ``--out``/map/), the planner plans on that map and the scans
(``use_map``, ``use_scan``, ``world_file: ''``), the controller avoids what the map and the
laser show (``obstacle_sources: [map, scan]``), and the bag records ``scan`` too. The figure
draws unknown obstacles apart from known ones and, with ``--sensing``, what the controller
avoided (``mpc/obstacles``, namespace ``raw``) at a few instants.

Re-planning is the planner's own: with ``--sensing`` it checks the rest of its plan against
the map and the scans (``replan_check_rate``) and plans anew from the robot's pose when an
obstacle the map did not have blocks it. ``metrics.json`` reports the planner's count of
re-plans in ``replans``.

The robot is the world's (its ``footprint`` polygon, or its ``robot_radius`` circle), or the
one ``--footprint`` (Nav2's "[[x, y], ...]") or ``--robot-radius`` says. That one robot
reaches every node, with or without ``--sensing``: each of simulator, planner and controller
gets it as its ``footprint`` parameter (and ``robot_radius``), so that the simulator counts
contacts of the true shape, the planner plans for it and the MPC keeps it clear. An option
that changes the robot writes the run's world (the world file with that robot) to
``--out``/world/, which the nodes read and the bag records, so that ``analyze_bag`` later
measures the same robot; ``metrics.json`` says which footprint was used (``footprint``,
``footprint_source``), and the figure draws it at a few poses.

For a polygon the planner's clearance is POLYGON_CLEARANCE (0.05 m) instead of its default
(0.1 m): the planner checks the polygon at every pose of the path, turns included, so the
clearance is room for the MPC, not for the shape; 0.05 m exceeds the MPC's own motion
clearance on a straight segment at full speed (h v_max / 2 = 0.031 m), and leaves a 0.60 m
gap open to the 0.43 m wide Jackal (narrow_gap). ``--param global_planner.clearance:=X``
(any node's parameter, as ``-p`` would give it) overrides it.

With ``--drift [RATE]`` the simulated odometry drifts (the real case: ``odom`` is not
``map``): RATE (0.05 = 5 %, the default) of the distance travelled in position and RATE rad
per metre in heading; the simulator's localizer stand-in publishes the true pose with
LOCALIZER_NOISE noise at LOCALIZER_RATE Hz on ``amcl_pose``, and the planner and the
controller compose it with odometry (``localization_topic``). Contacts are the true pose's;
``metrics.json`` has the run's ``drift`` and, in one process, the simulator's true final
pose and its distance to the goal (``true_final_pose``, ``true_goal_error``), which must then
be within reality.true_goal_tolerance of the controller's arrival tolerance
(xy_goal_tolerance + POSE_ERROR) for the run to succeed: what the drifted odometry, or the
controller, believes is not enough.

With ``--reality {ideal,mild,real,harsh}`` (default ideal) the simulator's robot and laser
are that preset of sim/reality.py (the simulator's ``reality`` parameter: command latency,
actuator lag, acceleration limits, odometry noise and drift, laser noise, NaN/-inf beams,
lost scans), the same model the ROS-free rollout uses. A preset whose odometry is not exact
(all but ideal) is run as ``--drift`` is: odometry in ``odom``, the localizer stand-in on
``amcl_pose`` followed by the planner and the controller, and the true final pose within
true_goal_tolerance of the controller's arrival tolerance for success (the node's default
0.1 m: 0.15 m) (``--drift RATE`` then overrides the preset's drift).
``metrics.json`` records the preset in ``reality`` (and its values in ``reality_values``);
``--param unicycle_simulator.NAME:=VALUE`` overrides single fields (``seed`` seeds it).

When the simulated odometry is exact (``--reality ideal`` without ``--drift``) the controller
arrives within PAPER_GOAL_TOLERANCES (the paper's scenario's 0.02 m and 0.05 rad, which the
reported metrics were measured with) instead of the node's defaults, which are for a real
robot's pose: ``--param mpc_controller.xy_goal_tolerance:=0.1`` runs with a real robot's
tolerance. A localized run (``--drift``, or a non-ideal reality) keeps the node's defaults:
its pose estimate jumps by a centimetre or so at each localizer pose, and a unicycle's plan
that must end exactly on the goal pose answers each jump with a manoeuvre of several
centimetres, so within 0.02 m the robot dithered for 40 s (see closed_loop_parameters).
Whether the run reached the target is the controller's verdict (its goal_reached, read from
the bag as analyze_bag reads it), not a tolerance of the analysis.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import math
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import threading
import time
from typing import Any, Sequence

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.exceptions import ParameterException
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode
from rclpy.node import Node
from rclpy.parameter import Parameter

from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.footprint import FROM_WORLD, radius_in_force, resolve
from mpc_local_planner.core.planner import RrtStarPlanner
from mpc_local_planner.core.planner_config import PlannerConfig
from mpc_local_planner.evaluation.analyze_bag import analyze, read_run, summary
from mpc_local_planner.evaluation.plotting import plot_runs
from mpc_local_planner.process_ties import tie_if_asked
from mpc_local_planner.ros.bag_recorder_node import (
    BagRecorderNode,
)
from mpc_local_planner.ros.closed_loop_monitor import (
    flush_recording,
    LoopMonitor,
    recorder_topics,
    SENSED_SNAPSHOTS,
)
from mpc_local_planner.ros.closed_loop_parameters import (
    DEFAULT_DRIFT,
    localized,
    LoopOptions,
    MODULES,
    node_parameters,
    parse_parameter,
    run_world,
)
from mpc_local_planner.ros.closed_loop_processes import (
    node_usage,
    process_sample,
    ProcessSample,
    respawn,
    spawn_all,
    stop_children,
)
from mpc_local_planner.ros.node_main import autostart
from mpc_local_planner.sim.physics import mujoco_missing, PLANTS
from mpc_local_planner.sim.reality import REALITY_PRESETS, true_goal_tolerance
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.map_files import rasterize_world, save_map
from mpc_local_planner.worlds.world import load_world, World

__all__ = ['EXIT_NO_PLAN', 'LoopResult', 'MAP_RESOLUTION', 'check_plannable', 'main',
           'run_closed_loop', 'write_known_map']

# Exit code when no plan can come (as for invalid options: the run was misconfigured).
EXIT_NO_PLAN = 2
# Simulated seconds allowed when the world sets no time_limit.
DEFAULT_TIME_LIMIT = 60.0
# Cell side (m) of the map of the known obstacles that --sensing serves.
MAP_RESOLUTION = 0.05
# With --separate-processes, each node's CPU and memory (metrics.json "node_usage") are
# measured from when the robot is this far (m) from its start to the end of the run: the
# nodes' start (imports, the NLPs built at the first plan) is over, the robot drives.
USAGE_FROM_METRES = 0.1


@dataclass
class LoopResult:
    """How the run ended and what it produced."""

    metrics: dict[str, Any]
    stop_reason: str
    wall_time: float
    sim_time: float
    out: Path
    success: bool


def write_known_map(world: World, folder: Path) -> Path:
    """Rasterise the world's KNOWN obstacles at MAP_RESOLUTION into folder; return the YAML."""
    return save_map(rasterize_world(world, MAP_RESOLUTION), folder, world.name)


def check_plannable(world: World, planner_parameters: dict[str, Any]) -> None:
    """Refuse a start or goal that no plan can reach: inside an obstacle as the planner grows it.

    For a round robot the planner grows every obstacle by robot_radius (its parameter, or
    the world's when that is -1: radius_in_force) plus clearance; for a polygon (the
    footprint parameter's, else the world's) it checks the polygon at the pose's heading
    grown by the clearance, as the global_planner node will with these parameters.

    Raises:
        PlanningError: saying which pose is in which inflated obstacle (or out of bounds).

    """
    defaults = PlannerConfig()
    radius = radius_in_force(float(planner_parameters.get('robot_radius', FROM_WORLD)),
                             world.robot_radius)
    clearance = float(planner_parameters.get('clearance', defaults.clearance))
    footprint = resolve(str(planner_parameters.get('footprint', '')),
                        world_footprint=world.footprint)
    polygon = () if footprint.is_circle else tuple(map(tuple, footprint.vertices.tolist()))
    planner = RrtStarPlanner(world.obstacles, world.bounds,
                             config=PlannerConfig(robot_radius=radius, clearance=clearance,
                                                  footprint=polygon))
    for label, pose in (('start', world.start), ('goal', world.goal)):
        try:
            planner.check_endpoint(pose, label)
        except PlanningError as err:
            msg = f'{world.name}: no plan can come: {err}'
            raise PlanningError(msg) from None


def run_closed_loop(options: LoopOptions, *, ros_args: Sequence[str] = ()) -> LoopResult:
    """Run the loop to the goal or a limit, then analyse its bag.

    Raises:
        FileNotFoundError: if the world file does not exist.
        ValueError: on an invalid option (e.g. --path analytic on a world without one).
        PlanningError: with --path rrt, if no plan can come (a start or goal inside an
            inflated obstacle, found before anything starts) or the planner says it found
            none (the run ends at once; the bag is kept, not analysed).

    """
    source_file = resolve_data_file(options.world)
    world = load_world(source_file)
    if not options.rtf > 0:
        msg = f'--rtf must be > 0, got {options.rtf}'
        raise ValueError(msg)
    if options.respawn and not options.separate_processes:
        msg = '--respawn needs --separate-processes'
        raise ValueError(msg)
    if options.respawn and options.lockstep:
        # a restarted node has taken none of the messages so far: the clock would wait
        msg = '--respawn and --lockstep do not go together'
        raise ValueError(msg)
    world_file, world, robot_source = run_world(options, source_file, world,
                                                Path(options.out) / 'world')
    params = node_parameters(options, world_file, world,
                             map_file=Path(options.out) / 'map' / f'{world.name}.yaml')
    if options.path == 'rrt':
        check_plannable(world, params['global_planner'])
    time_limit = options.time_limit or world.time_limit or DEFAULT_TIME_LIMIT
    out = Path(options.out)
    out.mkdir(parents=True, exist_ok=True)
    if options.sensing:
        params['map_server']['yaml_filename'] = str(write_known_map(world, out / 'map'))
    bag = out / 'bag'
    if bag.exists():
        shutil.rmtree(bag)

    context = Context()
    rclpy.init(args=['--ros-args', *ros_args] if ros_args else None, context=context)
    nodes: list[Node] = []
    children: dict[str, subprocess.Popen] = {}
    respawns: list[dict[str, Any]] = []
    # one thread: with rclpy 7.1 a MultiThreadedExecutor spun with spin_once piles up
    # pending callback futures faster than 2 cores drain them, and the loop collapses
    # (seen at rtf 4: 7 control steps in 40 s wall); the simulator advances simulated
    # time per tick, so a solve that blocks the thread only slows the loop, never skews it
    executor = SingleThreadedExecutor(context=context)
    start = time.monotonic()
    stop_reason = 'timeout'
    plan_failure: str | None = None
    sim_time = math.nan
    try:
        sim = [Parameter('use_sim_time', value=True)]
        recorder = BagRecorderNode(context=context, parameter_overrides=[
            *sim, Parameter('output', value=str(bag)),
            Parameter('world_file', value=str(world_file)),
            *(Parameter(k, value=v)
              for k, v in recorder_topics(sensing=options.sensing).items()),
            Parameter('lockstep', value=options.lockstep)])
        monitor = LoopMonitor(context=context, parameter_overrides=sim, sensing=options.sensing,
                              goal=world.goal, referee_radius=options.referee_radius,
                              stall_seconds=options.stall_seconds)
        nodes += [recorder, monitor]
        if options.separate_processes:
            children = spawn_all(params, out / 'logs')
        else:
            nodes += _create_nodes(params, context)
        for node in nodes:
            executor.add_node(node)
        deadline = start + options.timeout
        usage_from: dict[str, tuple[float, float, ProcessSample]] = {}
        while True:
            executor.spin_once(timeout_sec=0.05)
            sim_time = monitor.sim_time()
            if children and not usage_from and monitor.true_pose is not None and np.hypot(
                    *(monitor.true_pose[:2] - world.start[:2])) >= USAGE_FROM_METRES:
                usage_from = _samples(children, sim_time)
            if monitor.goal_reached:
                stop_reason = 'goal reached'
                break
            if monitor.referee_time is not None:
                stop_reason = f'within {options.referee_radius:g} m of the goal (referee)'
                break
            if monitor.stalled:
                stop_reason = f'stood still for {options.stall_seconds:g} s'
                break
            if monitor.plan_failure is not None:
                plan_failure = monitor.plan_failure
                stop_reason = f'no plan: {plan_failure}'
                break
            if sim_time > time_limit:
                stop_reason = f'simulated time limit ({time_limit:g} s)'
                break
            if time.monotonic() > deadline:
                stop_reason = f'wall-clock timeout ({options.timeout:g} s)'
                break
            dead = [name for name, c in children.items() if c.poll() is not None]
            if dead and not respawn(options, dead, children, params, out / 'logs', respawns,
                                     sim_time):
                name = dead[0]
                stop_reason = f'{name} exited (code {children[name].returncode})'
                break
        usage = node_usage(usage_from, _samples(children, sim_time))
        flush_recording(executor, recorder, monitor)
        from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode
        truth = [n.state for n in nodes if isinstance(n, UnicycleSimulatorNode)]
    finally:
        wall_time = time.monotonic() - start
        stop_children(list(children.values()))
        executor.shutdown()
        for node in reversed(nodes):
            node.destroy_node()
        rclpy.try_shutdown(context=context)

    if plan_failure is not None:
        msg = f'{world.name}: no plan came: {plan_failure}'
        raise PlanningError(msg)
    run_info = {'stop_reason': stop_reason, 'wall_time': wall_time, 'sim_time': sim_time,
                'separate_processes': options.separate_processes, 'rtf': options.rtf,
                'respawns': respawns, 'sensing': options.sensing,
                'contacts': monitor.contacts, 'active_contacts': monitor.active_contacts,
                'passive_contacts': monitor.passive_contacts, 'replans': monitor.replans,
                'path_source': options.path, 'world': str(source_file),
                'world_file': str(world_file), 'footprint_source': robot_source,
                'drift': options.drift, 'reality': options.reality, 'plant': options.plant,
                'reality_values': _run_reality(params), 'node_usage': usage}
    if not truth and monitor.true_pose is not None:  # the simulator's ground truth topic
        truth = [monitor.true_pose]
    if truth:  # the simulator's true pose, whatever odometry said
        run_info['true_final_pose'] = [float(v) for v in truth[0]]
        run_info['true_goal_error'] = float(np.hypot(*(truth[0][:2] - world.goal[:2])))
    if options.referee_radius is not None:
        run_info['referee_radius'] = options.referee_radius
        run_info['referee_time'] = monitor.referee_time
    run_info['stalled'] = monitor.stalled
    run_info['lockstep'] = options.lockstep
    if options.lockstep:
        run_info['lockstep_stalls'] = monitor.lockstep_stalls
    shape = '' if world.footprint.is_circle else ', polygon footprint'
    title = (f'{world.name}: {options.path} path, rtf {options.rtf:g}'
             + (', sensing' if options.sensing else '') + shape)
    # arrival as analyze_bag judges the same bag: the controller's own verdict
    metrics = analyze(bag, out, extra=run_info, title=title)
    if options.sensing or world.unknown_obstacles:
        _plot_sensing(bag, out / 'trajectory.png', world, monitor.sensed, title)
    reached = (monitor.referee_time is not None if options.referee_radius is not None
               else bool(metrics.get('reached')))
    success = reached and not metrics.get('collision') and not monitor.contacts
    if localized(options) and truth and options.referee_radius is None:
        # arrival is declared on the estimate: the truth within the controller's tolerance
        # plus the estimate's error
        xy = float(params['mpc_controller'].get('xy_goal_tolerance',
                                                ControllerSettings().xy_goal_tolerance))
        success = success and run_info['true_goal_error'] <= true_goal_tolerance(xy)
    return LoopResult(metrics=metrics, stop_reason=stop_reason, wall_time=wall_time,
                      sim_time=sim_time, out=out, success=success)


def _samples(children: dict[str, subprocess.Popen], sim_time: float
             ) -> dict[str, tuple[float, float, ProcessSample]]:
    """Return each running node process's CPU time and memory now, with sim and wall time."""
    samples = {}
    for name, child in children.items():
        sample = process_sample(child.pid) if child.poll() is None else None
        if sample is not None:
            samples[name] = (sim_time, time.monotonic(), sample)
    return samples


def _run_reality(params: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Return the simulator's reality as the run set it: the preset with its overrides.

    An infinite value (no acceleration limit) is None: metrics.json stays standard JSON.
    """
    from mpc_local_planner.ros.unicycle_simulator_parameters import reality_from_parameters

    def finite(value: Any) -> Any:
        if isinstance(value, list):
            return [finite(v) for v in value]
        return None if isinstance(value, float) and not math.isfinite(value) else value

    values = reality_from_parameters(params['unicycle_simulator']).as_dict()
    return {name: finite(value) for name, value in values.items()}


def _plot_sensing(bag: Path, png: Path, world: World,
                  sensed: Sequence[tuple[float, list[np.ndarray]]], title: str) -> None:
    """Redraw the run's figure with the unknown obstacles and a few sensed snapshots."""
    run = read_run(bag)
    step = max(1, len(run.predictions) // 8)
    picks = sorted({int(round(i)) for i in np.linspace(0, len(sensed) - 1,
                                                        min(SENSED_SNAPSHOTS, len(sensed)))})
    plot_runs(png, world=world, reference=run.plan, runs=[('mpc_controller', run.rows)],
              predictions=run.predictions[::step], title=title, show_unknown=True,
              sensed=[sensed[i] for i in picks] if sensed else (), footprint=world.footprint)


def _create_nodes(params: dict[str, dict[str, Any]], context: Context) -> list[Node]:
    """Create (map server,) planner, controller and simulator; autostart the lifecycle ones.

    Raises:
        ValueError: if a node refuses its parameters, or a lifecycle node does not configure
            or activate (the nodes created so far are destroyed).

    """
    from mpc_local_planner.ros.global_planner_node import GlobalPlannerNode
    from mpc_local_planner.ros.map_server_node import MapServerNode
    from mpc_local_planner.ros.mpc_controller_node import MpcControllerNode
    from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode

    # the simulator last: the clock starts once everyone listens
    classes = (('map_server', MapServerNode), ('global_planner', GlobalPlannerNode),
               ('mpc_controller', MpcControllerNode),
               ('unicycle_simulator', UnicycleSimulatorNode))
    nodes: list[Node] = []
    for name, node_class in classes:
        if name not in params:  # map_server: only with --sensing
            continue
        overrides = [Parameter(k, value=v) for k, v in params[name].items()]
        try:
            node = node_class(context=context, parameter_overrides=overrides)
        except (ParameterException, ValueError, TypeError, OSError) as err:
            node, problem = None, f'refusing to start: {err}'
        else:
            nodes.append(node)
            # as run_node does: configured and activated unless autostart is false
            problem = autostart(node) if isinstance(node, LifecycleNode) else None
        if problem is not None:
            for created in reversed(nodes):
                created.destroy_node()
            msg = f'{name}: {problem}'
            raise ValueError(msg)
    return nodes


def _terminate(signum: int, frame: Any) -> None:
    raise SystemExit(128 + signum)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the closed loop from the command line; exit 0 iff the target was reached safely."""
    # SIGTERM (a sweep that gives up on a run, a job scheduler) ends the run as Ctrl-C does:
    # through the finally blocks, which stop the node processes (else they outlive it)
    if threading.current_thread() is not threading.main_thread():
        return _main(argv)
    tie_if_asked()  # started by a sweep: end with it (process_ties)
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        return _main(argv)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _main(argv: Sequence[str] | None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args: list[str] = []
    if '--ros-args' in argv:
        index = argv.index('--ros-args')
        argv, ros_args = argv[:index], argv[index + 1:]
    parser = argparse.ArgumentParser(prog='closed_loop', description=__doc__.splitlines()[0])
    defaults = LoopOptions()
    parser.add_argument('--world', default=defaults.world,
                        help="world file (a path, or a name in config/worlds/ with or without "
                             "'.yaml')")
    parser.add_argument('--out', default=defaults.out, help='output directory')
    parser.add_argument('--path', choices=('rrt', 'analytic'), default=defaults.path,
                        help="reference: the world's analytic path or an RRT* plan")
    parser.add_argument('--rtf', type=float, default=defaults.rtf,
                        help='real-time factor of the simulated clock')
    parser.add_argument('--timeout', type=float, default=defaults.timeout,
                        help='wall-clock limit (s)')
    parser.add_argument('--time-limit', type=float, default=None,
                        help="simulated-time limit (s; default: the world's, else "
                             f'{DEFAULT_TIME_LIMIT:g})')
    parser.add_argument('--seed', type=int, default=defaults.seed, help='RRT* seed')
    parser.add_argument('--separate-processes', action='store_true',
                        help='run planner, controller and simulator as separate processes')
    parser.add_argument('--sensing', action='store_true',
                        help='the planner and the controller know only a map of the known '
                             "obstacles and the simulator's laser scans; unknown obstacles "
                             'are found by the laser')
    parser.add_argument('--drift', type=float, nargs='?', const=DEFAULT_DRIFT, default=0.0,
                        metavar='RATE',
                        help='the odometry drifts by RATE of the distance travelled (and '
                             'RATE rad/m in heading; default 5 %%), and the nodes follow a '
                             'localizer stand-in on amcl_pose')
    parser.add_argument('--reality', choices=tuple(REALITY_PRESETS), default=defaults.reality,
                        help="how real the simulator's robot and laser are (sim/reality.py): "
                             'ideal (exact), mild, real or harsh (latency, lag, acceleration '
                             'limits, odometry noise and drift, laser noise, NaN/-inf beams, '
                             'lost scans); a non-ideal one runs with the localizer, as --drift')
    parser.add_argument('--params-file', action='append', default=[], metavar='FILE',
                        help='a ros__parameters YAML file for the nodes (repeatable, e.g. '
                             'config/mpc_controller.yaml and config/jackal.yaml): each node '
                             "takes its sections' values over closed_loop's own choices; "
                             '--param still wins')
    parser.add_argument('--lockstep', action='store_true',
                        help='the simulated clock waits for every node: each control step '
                             'and plan is computed at a standstill of simulated time, so a '
                             'run is the same under any load (--rtf is then unused)')
    parser.add_argument('--referee-radius', type=float, default=None, metavar='R',
                        help="end the run as reached when the robot's TRUE position is "
                             'within R m of the goal (a referee, as BARN judges); default: '
                             "the controller's own arrival")
    parser.add_argument('--stall-seconds', type=float, default=None, metavar='S',
                        help='end the run when the robot has stood still S simulated seconds')
    parser.add_argument('--no-localizer', action='store_true',
                        help='with odometry that is not exact (--drift, a non-ideal '
                             '--reality): no localizer stand-in; the nodes take odometry as '
                             "the pose (BARN's robot)")
    parser.add_argument('--plant', choices=PLANTS, default=defaults.plant,
                        help="the simulator's plant: kinematic, or mujoco (a rigid body with "
                             'wheels and slip, odometry from the wheels, the [physics] extra; '
                             'the Jackal for a polygon footprint, else the small robot: '
                             '--param unicycle_simulator.physics.robot:=... chooses); it runs '
                             'with the localizer, as --drift')
    parser.add_argument('--respawn', action='store_true',
                        help='with --separate-processes: start a node process that exits '
                             'again instead of ending the run (a restart drill)')
    robot = parser.add_mutually_exclusive_group()
    robot.add_argument('--footprint', default=None,
                       help="the robot's convex polygon instead of the world's, Nav2's form "
                            "'[[x, y], ...]' (robot frame, x forward), for every node")
    robot.add_argument('--robot-radius', type=float, default=None,
                       help="a round robot of this radius (m) instead of the world's, for "
                            'every node')
    parser.add_argument('--param', action='append', default=[], metavar='NODE.NAME:=VALUE',
                        help="a node's parameter, applied last (repeatable), e.g. "
                             f'global_planner.clearance:=0.05; NODE is one of {sorted(MODULES)}')
    args = parser.parse_args(argv)
    if args.plant == 'mujoco' and mujoco_missing() is not None:
        parser.error(f'--plant mujoco: {mujoco_missing()}')
    try:
        extra: dict[str, dict[str, Any]] = {}
        for text in args.param:
            node, name, value = parse_parameter(text)
            extra.setdefault(node, {})[name] = value
        options = LoopOptions(world=args.world, out=args.out, path=args.path, rtf=args.rtf,
                              timeout=args.timeout, time_limit=args.time_limit,
                              seed=args.seed, separate_processes=args.separate_processes,
                              respawn=args.respawn, sensing=args.sensing, drift=args.drift,
                              reality=args.reality, lockstep=args.lockstep, plant=args.plant,
                              params_files=tuple(args.params_file),
                              referee_radius=args.referee_radius,
                              localizer=not args.no_localizer,
                              stall_seconds=args.stall_seconds,
                              footprint=args.footprint, robot_radius=args.robot_radius,
                              extra_parameters=extra)
        result = run_closed_loop(options, ros_args=ros_args)
    except PlanningError as err:
        print(f'closed_loop: {err}', file=sys.stderr, flush=True)
        return EXIT_NO_PLAN
    except (FileNotFoundError, ValueError) as err:
        print(f'closed_loop: {err}', file=sys.stderr, flush=True)
        return 2
    print(f'stopped: {result.stop_reason} after {result.wall_time:.1f} s wall, '
          f'{result.sim_time:.1f} s simulated')
    print(summary(result.metrics))
    print(f'contacts: {result.metrics.get("contacts")}')
    print(f'outputs in {result.out.resolve()}: bag/, trajectory.csv, metrics.json, '
          'trajectory.png' + (', map/' if options.sensing else ''))
    return 0 if result.success else 1


if __name__ == '__main__':
    sys.exit(main())
