# SPDX-License-Identifier: Apache-2.0
"""The closed loop without ROS: its stop rule, its rows and the controllers it drives."""

import math

import numpy as np
import pytest

from mpc_local_planner.core.baselines.pure_pursuit import PurePursuit
from mpc_local_planner.core.config import MpcConfig, SolverSettings
from mpc_local_planner.core.errors import PlanningError
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import PathReferenceMPC
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import paper_sinusoid
from mpc_local_planner.evaluation.rollout import (
    circle_clearance,
    ControlStep,
    EVALUATION_BUDGET,
    Outcome,
    polygon_clearance,
    rollout,
    solution_step,
    StopRule,
)
from mpc_local_planner.evaluation.trajectory import (
    read_trajectory_csv,
    TRAJECTORY_COLUMNS,
    TRAJECTORY_INDEX,
    trajectory_row,
    write_trajectory_csv,
)

H = 0.2


class Constant:
    """A controller that commands the same input everywhere."""

    def __init__(self, u):
        self.u = np.asarray(u, dtype=float)
        self.calls = 0

    def step(self, x):
        self.calls += 1
        return ControlStep(u=self.u, s=0.5, value=2.0, solve_time_s=1e-3)


def test_a_heading_of_plus_pi_reaches_a_goal_heading_of_minus_pi() -> None:
    rule = StopRule(time_limit=10.0, position_tolerance=0.01, heading_tolerance=0.05)
    goal = np.array([1.0, 2.0, -math.pi])
    assert rule.reached(np.array([1.0, 2.0, math.pi]), goal)
    assert rule.reached(np.array([1.0, 2.0, math.pi + 4 * math.pi]), goal)
    assert not rule.reached(np.array([1.0, 2.0, 0.0]), goal)
    run = rollout(Constant([0.0, 0.0]), Unicycle(), np.array([1.0, 2.0, math.pi]), goal, h=H,
                  rule=rule)
    assert run.outcome is Outcome.REACHED and run.reached
    assert len(run.rows) == 1 and len(run.steps) == 1


def test_an_infinite_heading_tolerance_compares_positions_only() -> None:
    rule = StopRule(time_limit=10.0, position_tolerance=1.0)
    assert rule.reached(np.array([0.5, 0.5, 3.0]), np.array([0.0, 0.0, 0.0]))
    assert not rule.reached(np.array([1.0, 0.5, 0.0]), np.array([0.0, 0.0, 0.0]))


def test_a_controller_standing_still_away_from_the_goal_stalls() -> None:
    rule = StopRule(time_limit=100.0, position_tolerance=0.05, stall_steps=7)
    controller = Constant([0.0, 0.0])
    run = rollout(controller, Unicycle(), np.zeros(3), np.array([1.0, 0.0, 0.0]), h=H,
                  rule=rule)
    assert run.outcome is Outcome.STALLED
    assert len(run.rows) == 7 == controller.calls
    assert np.all(run.rows[:, TRAJECTORY_INDEX['x']] == 0.0)


def test_a_run_that_never_arrives_ends_at_the_time_limit() -> None:
    rule = StopRule(time_limit=3.0, position_tolerance=0.05)
    run = rollout(Constant([0.1, 0.0]), Unicycle(), np.zeros(3), np.array([5.0, 0.0, 0.0]),
                  h=H, rule=rule)
    assert run.outcome is Outcome.TIME_LIMIT
    assert len(run.rows) == 16  # t = 0, 0.2, ..., 3.0
    assert run.end_time == pytest.approx(3.0)
    assert run.rows[-1, TRAJECTORY_INDEX['x']] == pytest.approx(0.1 * 3.0)
    assert run.solve_times == pytest.approx(np.full(16, 1e-3))
    assert len(run.step_times) == 16 and run.solver_failures == 0


def test_the_run_stops_at_the_goal_with_the_rows_of_every_step() -> None:
    rule = StopRule(time_limit=30.0, position_tolerance=0.05)
    run = rollout(Constant([0.25, 0.0]), Unicycle(), np.zeros(3), np.array([1.0, 0.0, 0.0]),
                  h=H, rule=rule)
    assert run.outcome is Outcome.REACHED
    poses = run.rows[:, [TRAJECTORY_INDEX[k] for k in ('x', 'y', 'theta')]]
    assert rule.reached(poses[-1], np.array([1.0, 0.0, 0.0]))  # the first row within 5 cm
    assert not rule.reached(poses[-2], np.array([1.0, 0.0, 0.0]))
    assert run.rows[:, TRAJECTORY_INDEX['t']] == pytest.approx(H * np.arange(len(run.rows)))
    assert np.all(run.rows[:, TRAJECTORY_INDEX['V_N']] == 2.0)
    assert np.all(run.rows[:, TRAJECTORY_INDEX['solve_ms']] == pytest.approx(1.0))


def test_contact_ends_the_run_before_the_goal_counts() -> None:
    box = ConvexPolygon.from_box(0.5, -0.5, 1.5, 0.5)
    rule = StopRule(time_limit=30.0, position_tolerance=0.05)
    run = rollout(Constant([0.25, 0.0]), Unicycle(), np.zeros(3), np.array([2.0, 0.0, 0.0]),
                  h=H, rule=rule, clearance=polygon_clearance([box], 0.2))
    assert run.outcome is Outcome.COLLISION
    assert run.rows[-1, TRAJECTORY_INDEX['x']] == pytest.approx(0.3)
    circles = circle_clearance(np.array([[1.0, 0.0]]), 0.1, 0.2)
    assert circles(np.array([[0.0, 0.0], [0.7, 0.0]])) == pytest.approx([0.7, 0.0])


def test_a_controller_without_an_answer_stops_the_run() -> None:
    class Lost:
        def step(self, x):
            msg = 'no way to the goal'
            raise PlanningError(msg)

    rule = StopRule(time_limit=30.0, position_tolerance=0.05)
    run = rollout(Lost(), Unicycle(), np.zeros(3), np.array([2.0, 0.0, 0.0]), h=H, rule=rule)
    assert run.outcome is Outcome.STOPPED and 'no way' in run.note
    assert len(run.rows) == 1 and not run.steps
    assert run.rows[0, TRAJECTORY_INDEX['v']] == 0.0
    run = rollout(Constant([math.nan, 0.0]), Unicycle(), np.zeros(3), np.array([2.0, 0.0, 0.0]),
                  h=H, rule=rule)
    assert run.outcome is Outcome.STOPPED and 'non-finite' in run.note


def test_the_row_builder_puts_each_value_in_its_named_column(tmp_path) -> None:
    row = trajectory_row(1.5, [1.0, 2.0, 0.3, 99.0], [0.2, -0.1], s=0.4, value=7.0,
                         solve_ms=3.5)
    assert row.shape == (len(TRAJECTORY_COLUMNS),)
    expected = {'t': 1.5, 'x': 1.0, 'y': 2.0, 'theta': 0.3, 'v': 0.2, 'omega': -0.1, 's': 0.4,
                'V_N': 7.0, 'solve_ms': 3.5}
    for name, value in expected.items():
        assert row[TRAJECTORY_INDEX[name]] == value
    still = trajectory_row(0.0, np.zeros(3))
    assert still[TRAJECTORY_INDEX['v']] == 0.0 and still[TRAJECTORY_INDEX['omega']] == 0.0
    assert np.isnan(still[[TRAJECTORY_INDEX[k] for k in ('s', 'V_N', 'solve_ms')]]).all()
    write_trajectory_csv(tmp_path / 'trajectory.csv', np.stack([row, still]))
    back = read_trajectory_csv(tmp_path / 'trajectory.csv')
    assert back[0] == pytest.approx(row)


def test_the_package_controllers_plug_in_through_their_interfaces() -> None:
    class FakeMpc:
        def solve(self, x):
            from types import SimpleNamespace
            return SimpleNamespace(u0=np.array([0.1, 0.0]), s=0.2, value=3.0,
                                   solve_time_s=0.004, success=False, lyapunov_ok=True,
                                   x_pred=np.zeros((3, 3)))

    step = solution_step(FakeMpc().solve(np.zeros(3)))
    assert step.value == 3.0 and not step.success and step.prediction.shape == (3, 3)
    rule = StopRule(time_limit=30.0, position_tolerance=0.05)
    mpc = rollout(FakeMpc(), Unicycle(), np.zeros(3), np.array([2.0, 0.0, 0.0]), h=H,
                  rule=StopRule(time_limit=0.4, position_tolerance=0.05))
    assert [step.value for step in mpc.steps] == [3.0, 3.0, 3.0] and mpc.solver_failures == 3
    # a local controller: its compute(pose, twist, t), its progress as s
    follower = PurePursuit(np.array([[0.0, 0.0], [2.0, 0.0]]))
    run = rollout(follower, Unicycle(), np.zeros(3), np.array([2.0, 0.0, 0.0]), h=H, rule=rule)
    assert run.outcome is Outcome.REACHED
    assert np.all(np.diff(run.rows[:, TRAJECTORY_INDEX['s']]) >= 0)
    assert run.rows[-2, TRAJECTORY_INDEX['s']] > 0.9
    constant = Constant([0.0, 0.0])
    rollout(constant, Unicycle(), np.zeros(3), np.ones(3), h=H, rule=rule)
    assert constant.calls > 0
    with pytest.raises(TypeError, match='no step'):
        rollout(object(), Unicycle(), np.zeros(3), np.ones(3), h=H, rule=rule)


def test_the_same_rollout_twice_is_the_same_with_the_iteration_budget() -> None:
    """What the evaluation relies on: its MPC budget reads no clock, so load changes nothing.

    The allowance is tight enough to cut some steps (so the budget shapes the run), and the
    second run's MPC has a clock that fails if read.
    """
    assert EVALUATION_BUDGET == 'iterations'
    path, model = paper_sinusoid(), Unicycle()
    box = ConvexPolygon.from_box(1.0, -1.0, 1.5, 1.0)
    config = MpcConfig(solving=SolverSettings(compile=False, budget=EVALUATION_BUDGET,
                                              max_solve_iterations=12))

    def unreadable() -> float:
        msg = 'the clock was read'
        raise AssertionError(msg)

    def run(clock=None):
        mpc = PathReferenceMPC(model, config, obstacles=[box], path=path)
        if clock is not None:
            mpc.clock = clock
        return rollout(mpc, model, path.start, path.goal, h=H,
                       rule=StopRule(time_limit=4.0, position_tolerance=0.05))

    first, second = run(), run(unreadable)
    assert any(step.detail.timed_out for step in first.steps)  # the budget did cut
    assert first.outcome is second.outcome
    applied = [TRAJECTORY_INDEX[name] for name in TRAJECTORY_COLUMNS if name != 'solve_ms']
    np.testing.assert_array_equal(first.rows[:, applied], second.rows[:, applied])
    assert ([(s.detail.status, s.detail.iterations, s.detail.tries) for s in first.steps]
            == [(s.detail.status, s.detail.iterations, s.detail.tries) for s in second.steps])


def test_on_a_real_base_the_controller_sees_odometry_and_the_rows_hold_the_truth():
    from mpc_local_planner.sim.base import Base
    from mpc_local_planner.sim.reality import Reality

    seen = []

    class Forward:
        def step(self, x):
            seen.append(np.array(x, dtype=float))
            return ControlStep(u=np.array([0.2, 0.0]))

    base = Base(Unicycle(), Reality(odom_drift=(0.1, 0.0), latency=0.1), [0.0, 0.0, 0.0])
    run = rollout(Forward(), base, np.zeros(3), np.array([9.0, 0.0, 0.0]), h=0.05,
                  rule=StopRule(time_limit=2.0, position_tolerance=0.01))
    assert run.rows[-1, 0] == pytest.approx(2.0)
    # latency: the first 0.1 s without motion; then 0.2 m/s; odometry says 10 % more
    assert run.rows[-1, 1] == pytest.approx(0.2 * 1.9, abs=1e-6)
    assert seen[-1][0] == pytest.approx(1.1 * 0.2 * 1.9, abs=1e-6)


def test_a_stall_lasts_as_long_in_seconds_at_any_control_period():
    class Still:
        def step(self, x):
            return ControlStep(u=np.zeros(2))

    for h in (0.2, 0.05):
        rule = StopRule(time_limit=60.0, position_tolerance=0.01, stall_steps=10,
                        stall_period=0.2)
        run = rollout(Still(), Unicycle(), np.zeros(3), np.array([1.0, 0.0, 0.0]), h=h,
                      rule=rule)
        assert run.outcome is Outcome.STALLED
        assert run.end_time == pytest.approx(2.0 - h)


def _drifting_run(localizer, monkeypatch=None):
    """Drive a drifting base straight on for 10 s; return the run and what the controller saw."""
    from mpc_local_planner.sim.base import Base
    from mpc_local_planner.sim.reality import Reality

    seen = []

    class Straight:
        def step(self, x):
            seen.append(np.array(x, dtype=float))
            return ControlStep(u=np.array([1.0, 0.0]))

    reality = Reality(odom_drift=(0.05, 0.02), odom_noise=(0.01, 0.01), latency=0.05)
    base = Base(Unicycle(), reality, [0.0, 0.0, 0.0])
    run = rollout(Straight(), base, np.zeros(3), np.array([90.0, 0.0, 0.0]), h=0.05,
                  rule=StopRule(time_limit=10.0, position_tolerance=0.01),
                  localizer=localizer)
    return run, np.array(seen)


def test_with_a_localizer_the_controller_sees_the_pose_in_map_not_the_drifted_odometry():
    from mpc_local_planner.sim.localizer import Localizer

    truth_error = []
    for localizer in (None, Localizer()):
        run, seen = _drifting_run(localizer)
        error = np.hypot(*(seen[:, :2] - run.rows[:len(seen), 1:3]).T)
        truth_error.append(float(np.max(error[-20:])))
    # odometry alone is 5 % off after 3 m (and turned); corrected, within the estimate's error
    assert truth_error[0] > 0.15
    assert truth_error[1] < 0.05


def test_the_rollout_composes_odometry_and_the_localizer_through_localized_pose(monkeypatch):
    from mpc_local_planner.evaluation import rollout as rollout_module
    from mpc_local_planner.perception.localization import compose, LocalizedPose
    from mpc_local_planner.sim.localizer import Localizer

    made = []

    class Spy(LocalizedPose):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.given = []
            made.append(self)

        def pose(self, odom_pose):
            answer = super().pose(odom_pose)
            self.given.append((self.correction.copy(), np.array(odom_pose), answer))
            return answer

    monkeypatch.setattr(rollout_module, 'LocalizedPose', Spy)
    run, seen = _drifting_run(Localizer(rate=5.0))
    (located,) = made
    # a localizer pose at 0, 0.2, ..., 9.8 s (the last row, at 10 s, is recorded unapplied)
    assert located.corrections == 51
    assert len(located.given) == len(seen)
    for (correction, odom, answer), x in zip(located.given, seen, strict=True):
        np.testing.assert_allclose(answer, compose(correction, odom))
        np.testing.assert_allclose(x, answer)


def test_a_localizer_needs_a_real_base():
    from mpc_local_planner.sim.localizer import Localizer

    with pytest.raises(ValueError, match='real base'):
        rollout(lambda x: None, Unicycle(), np.zeros(3), np.ones(3), h=0.1,
                rule=StopRule(time_limit=1.0, position_tolerance=0.1), localizer=Localizer())
