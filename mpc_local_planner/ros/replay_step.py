# SPDX-License-Identifier: Apache-2.0
r"""Replay one control step of a recorded run: what the controller knew there, and what it does.

    python3 -m mpc_local_planner.ros.replay_step BAG --step 200 \\
        --params-file config/mpc_controller.yaml --params-file config/jackal.yaml \\
        [--param collision_margin=0.0] [--solves 4]

"Why did the robot stop here?" is a question about a state the controller was in, which a
rerun rarely reaches again. A bag of the run (closed_loop's, or bag_recorder's with the scan)
holds what made that state: the scans, the odometry, the plan and the controller's
diagnostics. This tool builds the controller's obstacle memory again from the scans, with
the node's own perception code (each scan placed with the odometry interpolated at its
stamp, remembered for ``obstacle_memory`` seconds, fitted into pieces), and the controller
from the node's parameters (the files and ``--param`` overrides, as the node reads them).
At the step's recorded pose, twist and plan it then solves ``--solves`` times with the robot
standing there, and prints what it did each time beside what the node recorded, and the
footprint's clearance from the remembered obstacles.

It replays the state, not the history: the node's warm start, its last plan and its shifted
candidate are not in a bag, so a moving robot's step can differ from the recording, while a
standing robot's (which starts over anyway) is the one the node solved. ``--param`` asks
what another setting would have done there. The NLPs are built as the node builds them
(``prepare``: up to ``obstacle_slots`` held, the nearest) but not compiled (a replay takes
seconds, not the minutes compilation takes), and a wall-time budget is replayed as the
iterations budget (``budget: iterations``, what closed_loop's lockstep runs use), since the
replay's time is not the robot's: the solver's iterations are the node's.
Exit code 2 with one line on stderr for a bag that is missing, holds no diagnostics, or a
step that is not in it.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
import sys
from typing import Any, NamedTuple, Sequence

import numpy as np
from rosbags.highlevel import AnyReader
import yaml

from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.margin_relief import footprint_clearance_at
from mpc_local_planner.perception.local_obstacles import LocalObstacles, SENSING_MARGIN
from mpc_local_planner.perception.scan_obstacles import ObstacleMemory
from mpc_local_planner.perception.scans import Scan
from mpc_local_planner.ros.closed_loop_parameters import file_parameters
from mpc_local_planner.ros.conversions import (
    odometry_to_state,
    odometry_twist,
    path_to_poses,
    scan_from_message,
    stamp_to_seconds,
)
from mpc_local_planner.ros.mpc_controller_parameters import build_settings, DEFAULTS

__all__ = ['main', 'Recording', 'read_recording', 'replay']

EXIT_UNUSABLE = 2


class Recording(NamedTuple):
    """What a bag holds of a run, as the controller received it."""

    scans: list[Scan]
    odometry: np.ndarray  # (n, 6): stamp, x, y, yaw (unwrapped), v, omega
    plans: list[tuple[float, np.ndarray]]  # (receipt time, (m, 3) poses)
    steps: list[tuple[str, dict[str, str]]]  # the diagnostics: (message, values)


def read_recording(bag: str | Path, *, scan_topic: str = '/scan', odom_topic: str = '/odom',
                   plan_topic: str = '/plan',
                   diagnostics_topic: str = '/mpc/diagnostics') -> Recording:
    """Read the scans, odometry, plans and controller diagnostics of a bag.

    Each message is read with the nodes' own conversions (ros/conversions.py), so a pose the
    controller would refuse is refused here too.

    Raises:
        FileNotFoundError: if the bag does not exist.
        ValueError: if it has no controller diagnostics or no odometry, or a pose has no
            orientation or a non-finite position.

    """
    bag = Path(bag)
    if not bag.exists():
        msg = f'bag not found: {bag}'
        raise FileNotFoundError(msg)
    scans, odometry, plans, steps = [], [], [], []
    with AnyReader([bag]) as reader:
        wanted = [c for c in reader.connections
                  if c.topic in (scan_topic, odom_topic, plan_topic, diagnostics_topic)]
        for connection, stamp, raw in reader.messages(connections=wanted):
            msg = reader.deserialize(raw, connection.msgtype)
            if connection.topic == scan_topic:
                scans.append(scan_from_message(msg))
            elif connection.topic == odom_topic:
                odometry.append((stamp_to_seconds(msg.header.stamp), *odometry_to_state(msg),
                                 *odometry_twist(msg)))
            elif connection.topic == plan_topic:
                plans.append((stamp * 1e-9, path_to_poses(msg)))
            else:
                steps += [(s.message, {v.key: v.value for v in s.values}) for s in msg.status]
    if not steps:
        msg = f'{bag} has no controller diagnostics on {diagnostics_topic}'
        raise ValueError(msg)
    if not odometry:
        msg = f'{bag} has no odometry on {odom_topic}'
        raise ValueError(msg)
    table = np.array(sorted(odometry), dtype=float)
    table[:, 3] = np.unwrap(table[:, 3])
    return Recording(scans, table, plans, steps)


def _pose_at(odometry: np.ndarray, t: float) -> np.ndarray:
    """The odometry pose at t, interpolated (held at the ends), as the node places a scan."""
    return np.array([np.interp(t, odometry[:, 0], odometry[:, k]) for k in (1, 2, 3)])


def replay(recording: Recording, step: int, values: dict[str, Any], *, solves: int = 1
           ) -> list[str]:
    """Return the lines that say what was recorded at step and what the controller does now.

    Raises:
        IndexError: if the recording has no such step.
        ValueError: if the step has no recorded state, or no plan had come by then.

    """
    message, recorded = recording.steps[step]
    try:
        t = float(recorded['state_time'])
        pose = np.array([float(recorded[k]) for k in ('x', 'y', 'theta')])
        twist = np.array([float(recorded[k]) for k in ('v', 'omega')])
    except (KeyError, ValueError) as err:
        msg = f'step {step} has no recorded state ({err})'
        raise ValueError(msg) from err
    plans = [poses for received, poses in recording.plans if received <= t]
    if not plans or not np.all(np.isfinite(pose)):
        msg = f'step {step} ({message!r}) has no plan or no pose to replay'
        raise ValueError(msg)
    config, model, settings = build_settings(values)
    config = replace(config, solving=replace(config.solving, compile=False,
                                             budget='iterations'))
    memory = ObstacleMemory(float(values['obstacle_memory']))
    laser = [float(v) for v in values['laser_pose']]
    for scan in recording.scans:
        if scan.stamp <= t:
            memory.update(scan, _pose_at(recording.odometry, scan.stamp), laser_pose=laser,
                          body=config.robot_footprint)
    local = LocalObstacles(config.solving.faces_per_obstacle, memory=memory)
    local.scan_updated()
    near = local.near(pose[:2], config.reach(float(model.u_max[0])) + SENSING_MARGIN)
    controller = MpcController(model, config, obstacles=near, settings=settings)
    controller.set_plan(plans[-1])
    controller.prepare()
    clearance = footprint_clearance_at(config.robot_footprint, pose, near)
    lines = [f'step {step} at {t:.2f} s, recorded: {message} | '
             f"{recorded.get('status', '')} | pose {np.round(pose, 3).tolist()} "
             f'twist {np.round(twist, 3).tolist()}',
             f'{len(near)} remembered obstacles in reach; the footprint is {clearance:.4f} m '
             f'from the nearest (collision_margin {config.collision_margin})']
    for k in range(solves):
        output = controller.compute(pose, twist if k == 0 else np.zeros(2),
                                    t + k * config.step)
        solution = output.solution
        said = '' if solution is None else (
            f' | {solution.status} | {solution.iterations} iterations, '
            f'{solution.obstacles_active} held of {solution.obstacles_in_reach}')
        detail = f' ({output.detail})' if output.detail else ''
        lines.append(f'replayed solve {k}: {output.reason.value}{detail} '
                     f'u {np.round(output.u, 3).tolist()}{said}')
    return lines


def parameter_values(params_files: Sequence[str], overrides: Sequence[str]) -> dict[str, Any]:
    """Return the controller's parameters as the node reads them.

    The defaults, then the files' mpc_controller sections, then ``name=value`` overrides
    (YAML values).

    Raises:
        ValueError: for an unreadable file, a malformed override or an unknown name.

    """
    values = dict(DEFAULTS)
    for path in params_files:
        values.update(file_parameters(path, 'mpc_controller'))
    for item in overrides:
        name, sep, text = item.partition('=')
        if not sep:
            msg = f'--param wants name=value, got {item!r}'
            raise ValueError(msg)
        values[name.strip()] = yaml.safe_load(text)
    unknown = sorted(set(values) - set(DEFAULTS))
    if unknown:
        msg = f'unknown mpc_controller parameters: {unknown}'
        raise ValueError(msg)
    return values


def main(argv: Sequence[str] | None = None) -> int:
    """Print a replayed step; exit 0, or 2 with one line on stderr when it cannot be had."""
    parser = argparse.ArgumentParser(prog='replay_step', description=__doc__.splitlines()[0])
    parser.add_argument('bag', help="the run's bag (a folder)")
    parser.add_argument('--step', type=int, required=True,
                        help='the index of the control step among the diagnostics '
                             '(negative: from the end)')
    parser.add_argument('--params-file', action='append', default=[],
                        help="the controller's params file (repeatable; later ones win)")
    parser.add_argument('--param', action='append', default=[],
                        help='name=value over the files (repeatable)')
    parser.add_argument('--solves', type=int, default=1,
                        help='solves made at the recorded state (the robot standing there)')
    args = parser.parse_args(argv)
    try:
        values = parameter_values(args.params_file, args.param)
        recording = read_recording(args.bag)
        lines = replay(recording, args.step, values, solves=max(1, args.solves))
    except (FileNotFoundError, IndexError, ValueError) as err:
        problem = f'no step {args.step} in the bag' if isinstance(err, IndexError) else err
        print(f'replay_step: {problem}', file=sys.stderr)
        return EXIT_UNUSABLE
    print('\n'.join(lines))
    return 0


if __name__ == '__main__':
    sys.exit(main())
