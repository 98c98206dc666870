# SPDX-License-Identifier: Apache-2.0
"""Do the MPC's predictions match what a lagging base does? One step ahead, on BARN runs.

Runs the paper's MPC on BARN worlds (laser sensing, the suites' set-up) with a `real` base
(sim/base.py: latency, first-order lag, acceleration limits) and compares, at every
solve, the motion the plan predicts over its first step h with the motion the base made
in the h that followed: the relative pose x_0^{-1} x_1 of the prediction against
p(t)^{-1} p(t + h) of the TRUE pose. Relative motions, so that odometry's drift and noise
(what x_0 is measured from) do not count: only the actuation's departure from the model.

    PYTHONPATH=. python3 -m mpc_local_planner.evaluation.prediction_error --worlds 0-9

or, from recorded runs of the nodes (closed_loop's bags, which hold the simulator's ground
truth; a bag without it is measured against its odometry, the truth of an ideal plant):

    python3 -m mpc_local_planner.evaluation.prediction_error --bag OUT/nodes/*/run/bag

prints, per variant (the zero hold at twice the base's limits as the Jackal ran before, the
first-order hold at the base's own limits), the median, 95th percentile and maximum of the
position and heading errors (docs/real_robot.md, "Predictions against the base").
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import json
from pathlib import Path
import sys
from typing import Any

import numpy as np

from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.mpc import PlanSource
from mpc_local_planner.evaluation import sensing_suites as suites
from mpc_local_planner.evaluation.analyze_bag import GROUND_TRUTH, read_run
from mpc_local_planner.evaluation.rollout import Rollout
from mpc_local_planner.evaluation.suite_runs import barn_score, DEFAULT_BARN_DIR, parse_worlds
from mpc_local_planner.perception.localization import compose, invert

__all__ = ['VARIANTS', 'bag_one_step_errors', 'one_step_errors', 'relative_motion', 'run_variant']

# name: how the MPC is set up for the base: the zero hold at twice the base's limits (the
# Jackal before), the first-order hold at them; and the other two for comparison
VARIANTS = {
    'zoh-2x': suites.MpcSetup(input_hold='zero', accel_factor=2.0),
    'foh-1x': suites.MpcSetup(input_hold='first_order', accel_factor=1.0),
    'zoh-1x': suites.MpcSetup(input_hold='zero', accel_factor=1.0),
    'foh-2x': suites.MpcSetup(input_hold='first_order', accel_factor=2.0),
}


def relative_motion(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return pose b in the frame of pose a: (dx, dy, dtheta), dtheta wrapped."""
    return compose(invert(np.asarray(a[:3], dtype=float)), np.asarray(b[:3], dtype=float))


def one_step_errors(run: Rollout, h: float) -> list[tuple[float, float]]:
    """Return (position, heading) errors of each applied plan's first step h against the truth.

    The run's rows hold the true pose at each control instant and its steps the controller's
    answers, one per row. Each solve that applied a plan (TRACKING or CANDIDATE, fresh: a
    stop's prediction stands while the base brakes) is compared, as relative motions, with
    the true motion from its instant to the row h later; solves with no row h later (the
    run's end) are left out.
    """
    times, truth = run.rows[:, 0], run.rows[:, 1:4]
    errors = []
    for row, step in enumerate(run.steps):
        detail = step.detail
        if (step.prediction is None or detail is None or not detail.fresh
                or detail.reason not in (Reason.TRACKING, Reason.CANDIDATE)):
            continue
        later = int(np.searchsorted(times, times[row] + h - 1e-6))
        if later >= len(times) or abs(times[later] - times[row] - h) > 1e-6:
            continue
        x_pred = np.asarray(step.prediction)
        predicted = relative_motion(x_pred[0], x_pred[1])
        actual = relative_motion(truth[row], truth[later])
        errors.append((float(np.hypot(*(predicted[:2] - actual[:2]))),
                       abs(float(predicted[2] - actual[2]))))
    return errors


def run_variant(worlds: list[int], variant: suites.MpcSetup, *, reality: str = 'real',
                v_max: float = 2.0, omega_max: float = 4.0) -> dict[str, Any]:
    """Run BARN worlds with the MPC set up as variant; return the errors and the outcomes."""
    robot = replace(suites.ROBOTS['jackal'], v_max=v_max, omega_max=omega_max)
    h = MpcConfig().step  # the suites' MPC's step
    errors: list[tuple[float, float]] = []
    outcomes = []
    for index in worlds:
        path = DEFAULT_BARN_DIR / f'world_{index:03d}.json'
        world = suites.barn_sensing_world(path, robot)
        result = suites.run_navigation(world, 'proposed', robot, sensing=True, seed=0,
                                       setup=variant, reality=reality, localized=False)
        run = result.run
        errors += one_step_errors(run, h)
        length = float(json.loads(path.read_text(encoding='utf-8'))['barn_path_length'])
        success = run.outcome.name == 'REACHED'
        outcomes.append({'world': index, 'outcome': run.outcome.name,
                         'contacts': result.contacts,
                         'time': float(run.rows[-1, 0]),
                         'score': barn_score(success, float(run.rows[-1, 0]), length)})
    values = np.array(errors) if errors else np.zeros((0, 2))
    return {'errors': values, 'outcomes': outcomes}


def bag_one_step_errors(bag: str | Path, h: float) -> list[tuple[float, float]]:
    """Return (position, heading) errors of each solve's first step h in a closed_loop bag.

    A solve is a control step whose diagnostics say ``solved`` with the paper's MPC's plan
    applied (source solver or candidate); its prediction is the local_plan of the same
    stamp, starting at the state measured at ``state_time``. The true motion from then to
    h later is the simulator's ground truth (``simulator/ground_truth``; the odometry when the
    bag has none), interpolated between its ticks.

    Raises:
        ValueError: if the bag holds no pose to compare with, or no local plan.

    """
    run = read_run(bag, ground_truth_topic='/' + GROUND_TRUTH)
    samples = run.ground_truth if len(run.ground_truth) else run.odometry_poses
    if not len(samples):
        msg_text = f'{bag}: no ground truth and no odometry to compare the predictions with'
        raise ValueError(msg_text)
    if not run.predictions:
        msg_text = f'{bag}: no local_plan'
        raise ValueError(msg_text)
    plans = dict(zip(run.prediction_times.tolist(), run.predictions, strict=True))
    track = np.array(sorted(samples.tolist()))
    track[:, 3] = np.unwrap(track[:, 3])

    def at(t: float) -> np.ndarray:
        return np.array([np.interp(t, track[:, 0], track[:, k]) for k in (1, 2, 3)])

    errors = []
    for row, step in enumerate(run.steps or ()):  # None: no controller's steps, no solves
        if not step.solved or step.source not in (PlanSource.SOLVER, PlanSource.CANDIDATE):
            continue
        plan = plans.get(float(run.rows[row, 0]))
        start = step.state_time - run.start
        if plan is None or len(plan) < 2 or start + h > track[-1, 0] or start < track[0, 0]:
            continue
        predicted = relative_motion(plan[0], plan[1])
        actual = relative_motion(at(start), at(start + h))
        heading = float(np.arctan2(np.sin(predicted[2] - actual[2]),
                                   np.cos(predicted[2] - actual[2])))
        errors.append((float(np.hypot(*(predicted[:2] - actual[:2]))), abs(heading)))
    return errors


def _print_bag_errors(bags: list[str], h: float) -> None:
    """Print the one-step errors over the bags' solves (median, 95th percentile, maximum)."""
    errors = []
    for bag in bags:
        errors += bag_one_step_errors(bag, h)
    e = np.array(errors).reshape(-1, 2)
    pos, head = (np.percentile(e[:, k], [50, 95, 100]) if len(e) else [np.nan] * 3
                 for k in (0, 1))
    print('| bags | solves | position median / p95 / max (m) | '
          'heading median / p95 / max (rad) |')
    print('|---|---|---|---|')
    print(f'| {len(bags)} | {len(e)} | {pos[0]:.3f} / {pos[1]:.3f} / {pos[2]:.3f} | '
          f'{head[0]:.3f} / {head[1]:.3f} / {head[2]:.3f} |', flush=True)


def main(argv: list[str] | None = None) -> int:
    """Print the prediction errors of each variant over the given BARN worlds (or bags).

    Returns 0, or 2 with the reason on stderr for a bag that is missing or cannot be used.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bag', nargs='+', default=None, metavar='BAG',
                        help="closed_loop bags (e.g. evaluate --through-nodes' runs): their "
                             'solves against the ground truth instead of running worlds')
    parser.add_argument('--step', type=float, default=0.2, help='the MPC step h of the bags (s)')
    parser.add_argument('--worlds', default='0-9', help='BARN world indices, e.g. 0-9,50')
    parser.add_argument('--reality', default='real')
    parser.add_argument('--variants', default='zoh-2x,foh-1x',
                        help='comma-separated names of VARIANTS')
    args = parser.parse_args(argv)
    if args.bag:
        try:
            _print_bag_errors(args.bag, args.step)
        except (FileNotFoundError, ValueError) as err:
            print(f'prediction_error: {err}', file=sys.stderr)
            return 2
        return 0
    worlds = parse_worlds(args.worlds)
    print('| variant | solves | position median / p95 / max (m) | '
          'heading median / p95 / max (rad) | reached | contacts |')
    print('|---|---|---|---|---|---|')
    for name in args.variants.split(','):
        result = run_variant(worlds, VARIANTS[name], reality=args.reality)
        e = result['errors']
        pos, head = (np.percentile(e[:, k], [50, 95, 100]) if len(e) else [np.nan] * 3
                     for k in (0, 1))
        reached = sum(o['outcome'] == 'REACHED' for o in result['outcomes'])
        contacts = sum(o['contacts'] for o in result['outcomes'])
        print(f'| {name} | {len(e)} | {pos[0]:.3f} / {pos[1]:.3f} / {pos[2]:.3f} | '
              f'{head[0]:.3f} / {head[1]:.3f} / {head[2]:.3f} | {reached}/{len(worlds)} | '
              f'{contacts} |', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
