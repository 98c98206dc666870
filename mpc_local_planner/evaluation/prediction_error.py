# Copyright 2026 mpc_local_planner developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Do the MPC's predictions match what a lagging base does? One step ahead, on BARN runs.

Runs the paper's MPC on BARN worlds (laser sensing, the suites' set-up) with a `real` base
(core/reality.py: latency, first-order lag, acceleration limits) and compares, at every
solve, the motion the plan predicts over its first step h with the motion the base made
in the h that followed: the relative pose x_0^{-1} x_1 of the prediction against
p(t)^{-1} p(t + h) of the TRUE pose. Relative motions, so that odometry's drift and noise
(what x_0 is measured from) do not count: only the actuation's departure from the model.

    PYTHONPATH=. python3 -m mpc_local_planner.evaluation.prediction_error --worlds 0-9

prints, per variant (zero hold at REALITY_ACCEL_FACTOR 2 as the Jackal ran before, the
first-order hold at the base's own limits), the median, 95th percentile and maximum of the
position and heading errors (docs/real_robot.md, "Predictions against the base").
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import json
from typing import Any
from unittest import mock

import numpy as np

from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.reality import Base
from mpc_local_planner.evaluation import navigation
from mpc_local_planner.evaluation import sensing_suites as suites
from mpc_local_planner.evaluation.suite_runs import barn_score, DEFAULT_BARN_DIR, parse_worlds
from mpc_local_planner.perception.localization import compose, invert

__all__ = ['VARIANTS', 'relative_motion', 'run_variant']

# name: (REALITY_INPUT_HOLD, REALITY_ACCEL_FACTOR): the zero hold at twice the base's limits
# (the Jackal before), the first-order hold at them; and the other two for comparison
VARIANTS = {
    'zoh-2x': ('zero', 2.0),
    'foh-1x': ('first_order', 1.0),
    'zoh-1x': ('zero', 1.0),
    'foh-2x': ('first_order', 2.0),
}


def relative_motion(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return pose b in the frame of pose a: (dx, dy, dtheta), dtheta wrapped."""
    return compose(invert(np.asarray(a[:3], dtype=float)), np.asarray(b[:3], dtype=float))


def run_variant(worlds: list[int], hold: str, factor: float, *, reality: str = 'real',
                v_max: float = 2.0, omega_max: float = 4.0) -> dict[str, Any]:
    """Run BARN worlds with one variant; return the errors and the runs' outcomes."""
    suites._MPC_CACHE.clear()
    poses: list[tuple[float, np.ndarray]] = []
    predictions: list[tuple[float, np.ndarray]] = []
    original_advance = Base.advance
    original_command = navigation.MpcLocal.command

    def advance(self: Base, until: float) -> None:
        original_advance(self, until)
        poses.append((self.time, self.pose.copy()))

    def command(self: Any, x: np.ndarray, t: float, velocity: np.ndarray | None = None
                ) -> Any:
        step = original_command(self, x, t, velocity)
        # the solves that applied a plan (a stop's prediction stands while the base brakes)
        if (step.prediction is not None and step.detail.fresh
                and step.detail.reason in (Reason.TRACKING, Reason.CANDIDATE)):
            x_pred = np.asarray(step.prediction)
            predictions.append((t, relative_motion(x_pred[0], x_pred[1])))
        return step

    robot = replace(suites.ROBOTS['jackal'], v_max=v_max, omega_max=omega_max)
    outcomes = []
    with mock.patch.object(suites, 'REALITY_INPUT_HOLD', hold), \
            mock.patch.object(suites, 'REALITY_ACCEL_FACTOR', factor), \
            mock.patch.object(Base, 'advance', advance), \
            mock.patch.object(navigation.MpcLocal, 'command', command):
        errors = []
        for index in worlds:
            poses.clear()
            predictions.clear()
            path = DEFAULT_BARN_DIR / f'world_{index:03d}.json'
            world = suites.barn_sensing_world(path, robot)
            result = suites.run_navigation(world, 'proposed', robot, sensing=True, seed=0,
                                           budget='iterations', reality=reality,
                                           localized=False)
            times = np.array([t for t, _ in poses])
            truth = np.array([p for _, p in poses])
            h = MpcConfig().step  # the suites' MPC's step
            for t, predicted in predictions:
                i, j = np.searchsorted(times, [t - 1e-6, t + h - 1e-6])
                if j >= len(times) or abs(times[i] - t) > 1e-6 or abs(times[j] - t - h) > 1e-6:
                    continue
                actual = relative_motion(truth[i], truth[j])
                errors.append((float(np.hypot(*(predicted[:2] - actual[:2]))),
                               abs(float(predicted[2] - actual[2]))))
            run = result.run
            length = float(json.loads(path.read_text(encoding='utf-8'))['barn_path_length'])
            success = run.outcome.name == 'REACHED'
            outcomes.append({'world': index, 'outcome': run.outcome.name,
                             'contacts': result.contacts,
                             'time': float(run.rows[-1, 0]),
                             'score': barn_score(success, float(run.rows[-1, 0]), length)})
    values = np.array(errors) if errors else np.zeros((0, 2))
    return {'errors': values, 'outcomes': outcomes}


def main(argv: list[str] | None = None) -> None:
    """Print the prediction errors of each variant over the given BARN worlds."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--worlds', default='0-9', help='BARN world indices, e.g. 0-9,50')
    parser.add_argument('--reality', default='real')
    parser.add_argument('--variants', default='zoh-2x,foh-1x',
                        help='comma-separated names of VARIANTS')
    args = parser.parse_args(argv)
    worlds = parse_worlds(args.worlds)
    print('| variant | solves | position median / p95 / max (m) | '
          'heading median / p95 / max (rad) | reached | contacts |')
    print('|---|---|---|---|---|---|')
    for name in args.variants.split(','):
        hold, factor = VARIANTS[name]
        result = run_variant(worlds, hold, factor, reality=args.reality)
        e = result['errors']
        pos, head = (np.percentile(e[:, k], [50, 95, 100]) if len(e) else [np.nan] * 3
                     for k in (0, 1))
        reached = sum(o['outcome'] == 'REACHED' for o in result['outcomes'])
        contacts = sum(o['contacts'] for o in result['outcomes'])
        print(f'| {name} | {len(e)} | {pos[0]:.3f} / {pos[1]:.3f} / {pos[2]:.3f} | '
              f'{head[0]:.3f} / {head[1]:.3f} / {head[2]:.3f} | {reached}/{len(worlds)} | '
              f'{contacts} |', flush=True)


if __name__ == '__main__':
    main()
