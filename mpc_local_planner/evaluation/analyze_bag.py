# SPDX-License-Identifier: Apache-2.0
"""analyze_bag: trajectory, metrics and plot of a closed-loop run, from its rosbag2.

Reads ``/odom``, ``/cmd_vel``, ``/plan``, ``/local_plan`` and ``/mpc/diagnostics`` with the
rosbags library (no ROS needed). One trajectory row per control step comes from the
controller's diagnostics, which carry the measured state and the command; for a bag without
those keys (another controller, or ``ros2 bag record`` of only odom and cmd_vel) the rows are
rebuilt from odometry, with the command from its twist.

The obstacles come from the world the bag's metadata records (bag_recorder's ``world_file``
parameter; closed_loop sets it), or from ``--world``, which takes precedence. A bag that
records no world, analysed without ``--world``, is refused: clearance and collisions against
a guessed world would be wrong.

Arrival is the controller's (its goal_reached; for odometry rows, its rule with the node's
defaults: see analyze), as closed_loop reports it: the two tools judge a bag alike.

Clearance and collision are measured as the simulator counts contacts: the world's exact
shapes (known and unknown obstacles, circles as circles) against the robot's TRUE footprint
at each pose (its polygon turned with the heading, or its circle): the world's ``footprint``
or ``robot_radius``, or ``--footprint`` (Nav2's "[[x, y], ...]"), which takes precedence.
``metrics.json`` says which footprint was used (``footprint``), and the figure draws it at a
few poses of the run. The world's moving obstacles count where they are at each row's time.

Usage: ``analyze_bag BAG --out DIR [--world WORLD] [--footprint "[[x, y], ...]"]``.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
import sys
import tempfile
from typing import Any, NamedTuple, Sequence

import numpy as np
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores
import yaml

from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.diagnostics import (
    BagKey,
    CONTROLLER_DIAGNOSTICS_TOPIC,
    ControllerDiagnostics,
    Key,
)
from mpc_local_planner.core.footprint import Footprint, parse_footprint
from mpc_local_planner.core.mpc import LyapunovCase, PlanSource
from mpc_local_planner.evaluation.trajectory import TRAJECTORY_INDEX
from mpc_local_planner.sim.moving import WorldClock
from mpc_local_planner.worlds.world import load_world, World

__all__ = ['BagRun', 'GROUND_TRUTH', 'analyze', 'describe_footprint', 'main', 'read_run',
           'recorded_world']

# The simulator's ground truth topic (ros/unicycle_simulator_parameters.GROUND_TRUTH_TOPIC;
# this layer does not import ros/): closed_loop's bags record it.
GROUND_TRUTH = 'simulator/ground_truth'


class BagRun(NamedTuple):
    """What a closed-loop bag holds, as arrays.

    Attributes:
        rows: (n, 9) trajectory rows t, x, y, theta, v, omega, s, V_N, solve_ms; t starts
            at 0 at the first control step that solved the MPC (waiting steps are dropped).
        plan: (M, 3) the last global plan, or None.
        predictions: the local plans (each (N+1, 3)) in order.
        lyapunov_ok: per row, the controller's V_N decrease check (None when not checked,
            and on the rows between two solves, which repeat the held solve's check).
        lyapunov_cases: per row as lyapunov_ok, whether the proof covers that check.
        solver_failures: control steps whose input did not come from a converged solve.
        goal_reached: the controller reported the goal reached.
        counts: messages per topic.
        arrived: per row, the controller's verdict (its goal_reached); None when the rows
            come from odometry (no verdict recorded).
        odometry_speed: (m, 2) the odometry's times (the rows' clock) and forward speeds
            (its twist: what the wheels measure), one per message; (0, 2) without /odom.
        start: the bag's time (s) of the rows' 0; the steps' state_time is on the bag's clock.
        steps: per row, the controller's step as it reported it; None when the rows come
            from odometry.
        prediction_times: per local plan, its stamp on the rows' clock.
        odometry_poses: (m, 4) t, x, y, theta of each odometry message (the rows' clock).
        ground_truth: (k, 4) t, x, y, theta of the simulator's ground truth (the rows'
            clock), when read_run was asked for it; (0, 4) otherwise or without it.

    """

    rows: np.ndarray
    plan: np.ndarray | None
    predictions: list[np.ndarray]
    lyapunov_ok: list[bool | None]
    lyapunov_cases: list[LyapunovCase | None]
    solver_failures: int
    goal_reached: bool
    counts: dict[str, int]
    arrived: list[bool] | None = None
    odometry_speed: np.ndarray = np.zeros((0, 2))
    start: float = 0.0
    steps: list[ControllerDiagnostics] | None = None
    prediction_times: np.ndarray = np.zeros(0)
    odometry_poses: np.ndarray = np.zeros((0, 4))
    ground_truth: np.ndarray = np.zeros((0, 4))


def _yaw(q: Any) -> float:
    norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
    if norm < 1e-9:
        return math.nan
    x, y, z, w = q.x / norm, q.y / norm, q.z / norm, q.w / norm
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _stamp(header: Any) -> float:
    return float(header.stamp.sec) + 1e-9 * float(header.stamp.nanosec)


def _poses(path_msg: Any) -> np.ndarray:
    return np.array([[p.pose.position.x, p.pose.position.y, _yaw(p.pose.orientation)]
                     for p in path_msg.poses]).reshape(-1, 3)


def read_run(bag: str | Path, *, odom_topic: str = '/odom', cmd_vel_topic: str = '/cmd_vel',
             plan_topic: str = '/plan', local_plan_topic: str = '/local_plan',
             diagnostics_topic: str = '/' + CONTROLLER_DIAGNOSTICS_TOPIC,
             ground_truth_topic: str | None = None) -> BagRun:
    """Read a closed-loop bag into arrays.

    The topics are the bag's names; ground_truth_topic (nav_msgs/Odometry, e.g. '/' +
    GROUND_TRUTH) is read only when given.

    Raises:
        FileNotFoundError: if the bag does not exist.
        ValueError: if the bag has neither diagnostics nor odometry.

    """
    bag = Path(bag)
    if not bag.exists():
        msg = f'bag not found: {bag}'
        raise FileNotFoundError(msg)
    typestore = get_typestore(Stores.ROS2_JAZZY)
    odom: list[tuple[float, float, float, float, float, float]] = []
    truth: list[tuple[float, float, float, float]] = []
    diags: list[tuple[float, dict[str, str]]] = []  # (stamp, the status's values)
    plan = None
    predictions: list[np.ndarray] = []
    prediction_stamps: list[float] = []
    counts: dict[str, int] = {}
    with Reader(bag) as reader:
        wanted = {odom_topic, cmd_vel_topic, plan_topic, local_plan_topic, diagnostics_topic,
                  ground_truth_topic} - {None}
        connections = [c for c in reader.connections if c.topic in wanted]
        for connection, _, data in reader.messages(connections=connections):
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
            msg = typestore.deserialize_cdr(data, connection.msgtype)
            if connection.topic == odom_topic:
                p = msg.pose.pose
                odom.append((_stamp(msg.header), p.position.x, p.position.y,
                             _yaw(p.orientation), msg.twist.twist.linear.x,
                             msg.twist.twist.angular.z))
            elif connection.topic == ground_truth_topic:
                p = msg.pose.pose
                truth.append((_stamp(msg.header), p.position.x, p.position.y,
                              _yaw(p.orientation)))
            elif connection.topic == plan_topic:
                plan = _poses(msg)
            elif connection.topic == local_plan_topic:
                predictions.append(_poses(msg))
                prediction_stamps.append(_stamp(msg.header))
            elif connection.topic == diagnostics_topic and msg.status:
                values = {kv.key: kv.value for kv in msg.status[0].values}
                diags.append((_stamp(msg.header), values))

    lyapunov: list[bool | None] = []
    cases: list[LyapunovCase | None] = []
    failures = 0
    goal_reached = False
    rows: list[list[float]] = []
    arrived: list[bool] | None = None
    steps: list[ControllerDiagnostics] | None = None
    if diags and Key.X.value in diags[0][1]:
        started = False
        arrived = []
        steps = []
        for t, values in diags:
            step = ControllerDiagnostics.from_values(values)
            started = started or step.source is not None  # the first MPC step
            if not started:
                continue
            rows.append([t, step.x, step.y, step.theta, step.v, step.omega, step.s, step.value,
                         step.solve_ms])
            # a row between two solves repeats the held solve's figures: its check is that
            # solve's, counted once (a bag without the solved key counts every row)
            solved = step.solved or Key.SOLVED.value not in values
            lyapunov.append(step.lyapunov_ok if solved else None)
            cases.append(step.lyapunov_case if solved else None)
            if step.source not in (None, PlanSource.SOLVER):
                failures += 1
            goal_reached = goal_reached or step.goal_reached
            arrived.append(step.goal_reached)
            steps.append(step)
    elif odom:
        # a bag without our diagnostics: one row per odometry message, the command from
        # the odometry's twist (what the base executes)
        for t, x, y, theta, v, omega in odom:
            rows.append([t, x, y, theta, v, omega, math.nan, math.nan, math.nan])
    else:
        msg = f'{bag}: no {diagnostics_topic} with states and no {odom_topic}: nothing to analyse'
        raise ValueError(msg)
    start = float(rows[0][0]) if rows else 0.0  # the rows' clock: 0 at the first row

    def on_rows_clock(samples: list, columns: int) -> np.ndarray:
        timed = np.array(samples, dtype=float).reshape(-1, columns)
        timed[:, 0] -= start
        return timed

    return BagRun(rows=on_rows_clock(rows, 9), plan=plan, predictions=predictions,
                  lyapunov_ok=lyapunov, lyapunov_cases=cases, solver_failures=failures,
                  goal_reached=goal_reached, counts=counts, arrived=arrived,
                  odometry_speed=on_rows_clock([(t, v) for t, _, _, _, v, _ in odom], 2),
                  start=start, steps=steps,
                  prediction_times=on_rows_clock(prediction_stamps, 1)[:, 0],
                  odometry_poses=on_rows_clock([o[:4] for o in odom], 4),
                  ground_truth=on_rows_clock(truth, 4))


def recorded_world(bag: str | Path) -> World | None:
    """Return the world a bag's metadata records (bag_recorder's world_file), or None.

    The world is loaded from the recorded contents, under the recorded file name (its suffix
    picks the format, its stem is the world's name), so the file need not exist any more.

    Raises:
        FileNotFoundError: if the bag has no metadata.yaml.
        ValueError: if the recorded world does not load (WorldError).

    """
    metadata = Path(bag) / 'metadata.yaml'
    if not metadata.is_file():
        msg = f'bag not found (no metadata.yaml): {bag}'
        raise FileNotFoundError(msg)
    info = yaml.safe_load(metadata.read_text(encoding='utf-8')) or {}
    custom = (info.get('rosbag2_bagfile_information') or {}).get('custom_data') or {}
    contents = custom.get(BagKey.WORLD.value)
    if contents is None:
        return None
    name = Path(str(custom.get(BagKey.WORLD_FILE.value) or 'world.yaml')).name
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / name
        path.write_text(str(contents), encoding='utf-8')
        return load_world(path)


def describe_footprint(footprint: Footprint) -> dict[str, Any]:
    """Return the footprint as metrics.json reports it (what clearance was measured from).

    ``{'shape': 'circle', 'radius': r}`` or ``{'shape': 'polygon', 'vertices': [[x, y], ...],
    'radius': r}`` (r: the circumscribed radius), vertices counter-clockwise in the robot
    frame, as Nav2's footprint parameter takes them.
    """
    if footprint.is_circle:
        return {'shape': 'circle', 'radius': float(footprint.radius)}
    return {'shape': 'polygon', 'vertices': footprint.vertices.tolist(),
            'radius': float(footprint.radius)}


def _with_moving(metrics: dict[str, Any], rows: np.ndarray, world: World,
                 robot: Footprint) -> dict[str, Any]:
    """Return min_clearance and collision with the moving obstacles where they were.

    Each row's pose against the moving obstacles at the row's time; the static part of the
    clearance is compute_metrics' own.
    """
    clock = WorldClock((), world.moving_obstacles)
    columns = [TRAJECTORY_INDEX[name] for name in ('x', 'y', 'theta')]
    moving = min(clock.clearance(robot, row[columns], row[TRAJECTORY_INDEX['t']])
                 for row in rows)
    static = metrics.get('min_clearance')
    closest = moving if static is None else min(static, moving)
    return {'min_clearance': closest, 'collision': bool(metrics.get('collision')) or moving < 0}


def analyze(bag: str | Path, out: str | Path, *, world_file: str | Path | None = None,
            footprint: Footprint | None = None, title: str = '',
            extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write trajectory.csv, metrics.json and trajectory.png of a bag into out.

    The goal is the last pose of the plan (else the world's goal); the obstacles are the
    world's exact shapes (known and unknown): world_file if given, else the world the bag
    records. Clearance is measured from footprint if given, else the world's footprint (its
    polygon, or its circle). extra is merged into the metrics.

    Arrival is the controller's: a run has reached the target when its last control step
    says goal_reached, and time_to_target is when it said so from then on. A recording
    without the controller's diagnostics is judged by the controller's own rule
    (ControllerSettings.goal_check) with the node's default tolerances. closed_loop reports
    exactly this: one definition, whichever tool reads the bag (metrics.json's arrival).

    The path length is the distance the odometry's speed (its twist) integrates to, up to
    the arrival, when the bag has odometry that reports one: the poses of a localized robot
    jump at every localizer correction, and odometry's own poses carry its noise, so the
    polyline through them measures the noise as much as the motion.

    Returns:
        The metrics (also written to metrics.json).

    Raises:
        FileNotFoundError: if the bag or world_file does not exist.
        ValueError: if neither world_file is given nor the bag records its world, or the bag
            holds nothing to analyse (no control step, no odometry).

    """
    from mpc_local_planner.evaluation.metrics import arrivals, compute_metrics
    from mpc_local_planner.evaluation.plotting import plot_runs
    from mpc_local_planner.evaluation.trajectory import write_trajectory_csv
    from mpc_local_planner.worlds.data_files import resolve_data_file

    if world_file is not None:
        world = load_world(resolve_data_file(world_file))
    else:
        world = recorded_world(bag)
        if world is None:
            msg = (f'{bag}: the bag does not record its world (bag_recorder without '
                   'world_file): give the world with --world')
            raise ValueError(msg)
    run = read_run(bag, ground_truth_topic='/' + GROUND_TRUTH)
    if not len(run.rows):
        msg = f'{bag}: no control step with the MPC and no odometry: nothing to analyse'
        raise ValueError(msg)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    goal = run.plan[-1] if run.plan is not None and len(run.plan) else np.asarray(world.goal)
    reference_length = None
    if run.plan is not None and len(run.plan) > 1:
        reference_length = float(np.sum(np.linalg.norm(np.diff(run.plan[:, :2], axis=0),
                                                       axis=1)))
    robot = footprint if footprint is not None else world.footprint
    goal = np.asarray(goal, dtype=float)
    if run.arrived is not None:
        arrived = np.array(run.arrived, dtype=bool)
        arrival = "the controller's goal_reached"
    else:
        settings = ControllerSettings()
        arrived = arrivals(run.rows, goal, settings)
        arrival = (f"the controller's goal check with its defaults (xy_goal_tolerance "
                   f'{settings.xy_goal_tolerance:g} m, yaw_goal_tolerance '
                   f'{settings.yaw_goal_tolerance:g} rad)')
    metrics = compute_metrics(
        run.rows, goal=goal, obstacles=list(world.physical_shapes()),
        footprint=robot, reference_length=reference_length,
        solver_failures=run.solver_failures, lyapunov_ok=run.lyapunov_ok,
        lyapunov_cases=run.lyapunov_cases, arrived=arrived,
        odometry_speed=run.odometry_speed if np.any(run.odometry_speed[:, 1]) else None)
    metrics.update(_true_clearance(metrics, run, world, robot))
    if run.steps is not None:
        metrics.update(_recoveries(run))
    if world.moving_obstacles and len(run.rows):
        metrics.update(_with_moving(metrics, run.rows, world, robot))
    metrics['arrival'] = arrival
    metrics['controller_goal_reached'] = run.goal_reached
    metrics['messages'] = run.counts
    metrics['world_name'] = world.name
    metrics['footprint'] = describe_footprint(robot)
    metrics.update(extra or {})
    write_trajectory_csv(out / 'trajectory.csv', run.rows)
    (out / 'metrics.json').write_text(json.dumps(metrics, indent=2, default=_json_default) + '\n',
                                      encoding='utf-8')
    step = max(1, len(run.predictions) // 8)
    plot_runs(out / 'trajectory.png', world=world, reference=run.plan,
              runs=[('mpc_controller', run.rows)], predictions=run.predictions[::step],
              title=title or f'{Path(bag).name}', footprint=robot)
    return metrics


def _recoveries(run: BagRun) -> dict[str, Any]:
    """Return how many recoveries the controller started and their seconds, in all.

    A recovery is a stretch of steps whose reason is Reason.RECOVERY (core/recoveries.py);
    its seconds run from its first step to the first step after it.
    """
    assert run.steps is not None
    times = run.rows[:, 0]
    started, seconds = 0, 0.0
    for i, step in enumerate(run.steps):
        if step.reason is not Reason.RECOVERY:
            continue
        if i == 0 or run.steps[i - 1].reason is not Reason.RECOVERY:
            started += 1
        if i + 1 < len(times):
            seconds += float(times[i + 1] - times[i])
    return {'recoveries': started, 'recovery_s': seconds}


def _true_clearance(metrics: dict[str, Any], run: BagRun, world: World,
                    robot: Footprint) -> dict[str, Any]:
    """Return min_clearance and collision from the simulator's true poses, when recorded.

    The rows are the poses the controller had (odometry, or the localizer's estimate): on a
    plant whose odometry drifts (the MuJoCo Jackal's wheels slip) they can pass through a
    cylinder the robot never touched, or past one it did. Where the bag holds the ground
    truth, the clearance is the truth's, as the simulator's contact count is; the estimate's
    stays as min_clearance_estimate.
    """
    from mpc_local_planner.evaluation.metrics import footprint_clearance

    shapes = list(world.physical_shapes())
    if not len(run.ground_truth) or not shapes:
        return {}
    true = float(np.min(footprint_clearance(shapes, robot)(run.ground_truth[:, 1:4])))
    return {'min_clearance_estimate': metrics.get('min_clearance'), 'min_clearance': true,
            'collision': bool(true < 0)}


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def summary(metrics: dict[str, Any]) -> str:
    """Return a few lines for a terminal."""
    def fmt(key: str, unit: str = '', digits: int = 3) -> str:
        value = metrics.get(key)
        if isinstance(value, float):
            return f'{value:.{digits}f}{unit}'
        return f'{value}{unit}'

    return '\n'.join([
        f"reached: {metrics.get('reached')}   collision: {metrics.get('collision')}",
        f"final error: {fmt('final_position_error', ' m')}, "
        f"{fmt('final_heading_error', ' rad')}",
        f"time to target: {fmt('time_to_target', ' s', 1)}   path length: "
        f"{fmt('path_length', ' m', 2)}   min clearance: {fmt('min_clearance', ' m')}",
        f"solve time median/p95/max: {fmt('solve_ms_median', '', 1)}/"
        f"{fmt('solve_ms_p95', '', 1)}/{fmt('solve_ms_max', ' ms', 1)}   "
        f"solver failures: {metrics.get('solver_failures')}   steps: {metrics.get('steps')}",
        _lyapunov_text(metrics),
        *([f'clearance measured from the footprint: {_footprint_text(metrics["footprint"])}']
          if metrics.get('footprint') else []),
    ])


def _lyapunov_text(metrics: dict[str, Any]) -> str:
    """Return the V_N checks as a line: those the proof covers apart from the others."""
    by_case = metrics.get('lyapunov_by_case')
    if not by_case:
        return (f"V_N violations: {metrics.get('lyapunov_violations')} of "
                f"{metrics.get('lyapunov_checks')} checks")
    covered = by_case.get(LyapunovCase.COVERED.value, {'checks': 0, 'violations': 0})
    text = (f"V_N violations: {covered['violations']} of {covered['checks']} checks the proof "
            'covers')
    others = {case: counts for case, counts in by_case.items()
              if case != LyapunovCase.COVERED.value}
    if others:
        checks = sum(counts['checks'] for counts in others.values())
        violations = sum(counts['violations'] for counts in others.values())
        detail = ', '.join(f"{case.replace('_', ' ')} {counts['violations']}/{counts['checks']}"
                           for case, counts in others.items())
        text += f'; {violations} of {checks} where the problem changed ({detail})'
    return text


def _footprint_text(footprint: dict[str, Any]) -> str:
    """Return describe_footprint's record as a few words."""
    if footprint.get('shape') == 'polygon':
        return f"polygon {footprint.get('vertices')}"
    return f"circle of radius {footprint.get('radius')} m"


def main(argv: Sequence[str] | None = None) -> int:
    """Analyse a bag from the command line; return 0 iff the target was reached safely."""
    parser = argparse.ArgumentParser(prog='analyze_bag', description=__doc__.splitlines()[0])
    parser.add_argument('bag', help='rosbag2 directory (mcap or sqlite3)')
    parser.add_argument('--out', required=True, help='directory for the outputs')
    parser.add_argument('--world', default=None,
                        help='world file with the obstacles (default: the world the bag '
                             'records; a bag that records none needs this)')
    parser.add_argument('--footprint', default=None,
                        help="the robot's convex polygon that clearance is measured from, "
                             "Nav2's form '[[x, y], ...]' (robot frame, x forward; default: "
                             "the world's footprint or robot_radius)")
    args = parser.parse_args(argv)
    try:
        footprint = None
        if args.footprint is not None:
            footprint = parse_footprint(args.footprint)
            if footprint.is_circle:
                msg = f'--footprint {args.footprint!r}: give a polygon "[[x, y], ...]"'
                raise ValueError(msg)
        metrics = analyze(args.bag, args.out, world_file=args.world, footprint=footprint)
    except (FileNotFoundError, ValueError) as err:
        print(f'analyze_bag: {err}', file=sys.stderr)
        return 2
    print(summary(metrics))
    print(f'outputs in {Path(args.out).resolve()}')
    return 0 if metrics.get('reached') and not metrics.get('collision') else 1


if __name__ == '__main__':
    sys.exit(main())
