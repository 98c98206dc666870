# SPDX-License-Identifier: Apache-2.0
"""The rule that decides what a control step applies: each branch, with plain values."""

from __future__ import annotations

import math

import pytest

from mpc_local_planner.core.mpc import decide, Decision, PlanSource


def choose(*, verified: bool = True, value: float = 1.0, candidate_ok: bool = True,
           candidate_value: float = 2.0, previous: bool = True,
           clear: bool = True, timed_out: bool = False) -> Decision:
    return decide(solver_verified=verified, solver_value=value, candidate_ok=candidate_ok,
                  candidate_value=candidate_value, has_previous_plan=previous,
                  candidate_collision_free=clear, timed_out=timed_out)


def test_a_verified_solution_cheaper_than_the_candidate_is_applied() -> None:
    decision = choose(value=1.0, candidate_value=2.0)
    assert decision is Decision.SOLVER
    assert decision.source is PlanSource.SOLVER
    assert not decision.is_failure


def test_a_verified_solution_as_cheap_as_the_candidate_within_tolerance_is_applied() -> None:
    assert choose(value=100.0 + 1e-5, candidate_value=100.0) is Decision.SOLVER


def test_a_verified_solution_is_applied_when_the_candidate_fails_verification() -> None:
    # the candidate's value means nothing then, even if it looks cheaper
    assert choose(value=5.0, candidate_ok=False, candidate_value=0.0) is Decision.SOLVER
    assert choose(value=5.0, candidate_ok=False, candidate_value=math.inf,
                  previous=False, clear=False) is Decision.SOLVER


def test_a_cheaper_verified_candidate_beats_a_verified_solution_without_a_failure() -> None:
    decision = choose(value=3.0, candidate_value=2.0)
    assert decision is Decision.CANDIDATE_CHEAPER
    assert decision.source is PlanSource.CANDIDATE
    assert not decision.is_failure


def test_the_verified_candidate_is_applied_when_the_solver_fails() -> None:
    decision = choose(verified=False, value=math.inf, candidate_value=2.0)
    assert decision is Decision.CANDIDATE_SOLVER_FAILED
    assert decision.source is PlanSource.CANDIDATE
    assert decision.is_failure


def test_the_verified_candidate_is_applied_when_the_time_ran_out_before_a_solution() -> None:
    decision = choose(verified=False, value=math.inf, candidate_value=2.0, timed_out=True)
    assert decision is Decision.CANDIDATE_TIMEOUT
    assert decision.source is PlanSource.CANDIDATE
    assert decision.is_failure
    assert 'shifted candidate' in decision.value and 'budget' in decision.value


def test_running_out_of_time_changes_nothing_once_a_verified_solution_is_there() -> None:
    assert choose(value=1.0, candidate_value=2.0, timed_out=True) is Decision.SOLVER
    assert choose(value=3.0, candidate_value=2.0, timed_out=True) is Decision.CANDIDATE_CHEAPER
    assert choose(value=5.0, candidate_ok=False, timed_out=True) is Decision.SOLVER


def test_an_unverified_candidate_is_judged_alike_whether_or_not_the_time_ran_out() -> None:
    unverified = {'verified': False, 'value': math.inf, 'candidate_ok': False, 'timed_out': True}
    assert choose(**unverified) is Decision.CANDIDATE_OFF_PREDICTION
    assert choose(**unverified, previous=False) is Decision.STOP
    assert choose(**unverified, clear=False) is Decision.STOP


def test_the_clear_candidate_off_the_prediction_is_applied_after_a_previous_plan() -> None:
    decision = choose(verified=False, value=math.inf, candidate_ok=False, previous=True,
                      clear=True)
    assert decision is Decision.CANDIDATE_OFF_PREDICTION
    assert decision.source is PlanSource.CANDIDATE
    assert decision.is_failure


@pytest.mark.parametrize(('previous', 'clear'), [(True, False), (False, True), (False, False)])
def test_the_robot_stops_when_nothing_is_verified_and_the_candidate_is_not_usable(
        previous: bool, clear: bool) -> None:
    decision = choose(verified=False, value=math.inf, candidate_ok=False, previous=previous,
                      clear=clear)
    assert decision is Decision.STOP
    assert decision.source is PlanSource.STOP
    assert decision.is_failure


def test_every_decision_but_the_solver_says_why_in_the_status() -> None:
    assert Decision.SOLVER.value == ''
    assert all(d.value for d in Decision if d is not Decision.SOLVER)


def test_plan_sources_read_as_their_names_in_logs_and_comparisons() -> None:
    assert PlanSource.STOP == 'stop'
    assert f'{PlanSource.CANDIDATE}' == 'candidate'
    assert str(PlanSource.SOLVER) == 'solver'


def test_before_a_plan_of_the_solvers_a_costlier_verified_solution_beats_standing_still() -> None:
    # after a reset (a new path, a stop) the candidate stands the robot still: the proof's
    # decrease starts with the first solver plan, so a costlier verified one is applied, and
    # from then on the candidate's value bounds the next
    unbound = decide(solver_verified=True, solver_value=1005.0, candidate_ok=True,
                     candidate_value=1000.0, has_previous_plan=True,
                     candidate_collision_free=True, candidate_binds=False)
    assert unbound is Decision.SOLVER
    assert choose(value=1005.0, candidate_value=1000.0) is Decision.CANDIDATE_CHEAPER
    assert decide(solver_verified=False, solver_value=math.inf, candidate_ok=True,
                  candidate_value=1000.0, has_previous_plan=True,
                  candidate_collision_free=True,
                  candidate_binds=False) is Decision.CANDIDATE_SOLVER_FAILED
