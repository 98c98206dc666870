# SPDX-License-Identifier: Apache-2.0
"""One-step prediction errors, from a run's rows (the truth) and its steps (the plans)."""

from types import SimpleNamespace

import numpy as np
import pytest

from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.evaluation.prediction_error import one_step_errors, relative_motion
from mpc_local_planner.evaluation.rollout import ControlStep, Outcome, Rollout

H, PERIOD = 0.2, 0.05


def _run(predicted_speed: float, *, fresh: bool = True,
         reason: Reason = Reason.TRACKING) -> Rollout:
    """A base driving straight on at 1 m/s, truth every 0.05 s; each step predicts a speed."""
    times = np.arange(0.0, 1.0 + 1e-9, PERIOD)
    rows = np.zeros((len(times), 9))
    rows[:, 0], rows[:, 1] = times, times  # x = t: 1 m/s along x
    steps = []
    for t in times:
        prediction = np.array([[t, 0.0, 0.0], [t + predicted_speed * H, 0.0, 0.0]])
        steps.append(ControlStep(u=np.array([1.0, 0.0]), prediction=prediction,
                                 detail=SimpleNamespace(fresh=fresh, reason=reason)))
    return Rollout(outcome=Outcome.REACHED, rows=rows, steps=tuple(steps),
                   step_times=np.zeros(len(steps)), h=PERIOD, note='')


def test_a_prediction_the_base_makes_true_has_no_error_and_the_runs_end_is_left_out() -> None:
    errors = one_step_errors(_run(1.0), H)
    # every instant with a row 0.2 s later: 0.0 ... 0.8 s, 17 of the 21
    assert len(errors) == 17
    np.testing.assert_allclose(errors, 0.0, atol=1e-12)


def test_the_error_is_the_relative_motion_missed() -> None:
    errors = np.array(one_step_errors(_run(1.5), H))  # predicts 0.3 m where it made 0.2
    np.testing.assert_allclose(errors[:, 0], 0.1, atol=1e-12)
    np.testing.assert_allclose(errors[:, 1], 0.0, atol=1e-12)


@pytest.mark.parametrize('fresh, reason', [(False, Reason.TRACKING), (True, Reason.STOP)])
def test_only_fresh_applied_plans_count(fresh: bool, reason: Reason) -> None:
    assert one_step_errors(_run(1.5, fresh=fresh, reason=reason), H) == []


def test_relative_motion_is_the_pose_in_the_first_ones_frame() -> None:
    moved = relative_motion(np.array([1.0, 1.0, np.pi / 2]), np.array([1.0, 2.0, np.pi]))
    np.testing.assert_allclose(moved, [1.0, 0.0, np.pi / 2], atol=1e-12)


def test_a_bag_that_is_not_there_is_a_clear_error_not_a_traceback(tmp_path, capsys) -> None:
    from mpc_local_planner.evaluation.prediction_error import main

    assert main(['--bag', str(tmp_path / 'absent')]) == 2
    assert 'prediction_error:' in capsys.readouterr().err
