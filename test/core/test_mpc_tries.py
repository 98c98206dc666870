# SPDX-License-Identifier: Apache-2.0
"""The solver strategy as a table: solver_tries(situation), a pure function, tested directly.

How the control step makes the tries (its budget, its continuation) is test_mpc_budget.py's.
"""

from __future__ import annotations

import dataclasses
import itertools

import pytest

from mpc_local_planner.core.mpc import Situation, Solver, solver_tries, Start, Try

CANDIDATE_BACKEND = Try(Start.CANDIDATE, Solver.BACKEND)
CANDIDATE_FALLBACK = Try(Start.CANDIDATE, Solver.IPOPT_FALLBACK)
GUIDED_BACKEND = Try(Start.GUIDED, Solver.BACKEND)
GUIDED_FALLBACK = Try(Start.GUIDED, Solver.IPOPT_FALLBACK)


def every_situation() -> list[Situation]:
    """Return every situation there is."""
    return [Situation(plan_moves=moves, obstacles_active=active, previous_round=previous,
                      has_fallback=fallback, continuation=continuation)
            for moves, active, previous, fallback, continuation in itertools.product(
                (False, True), (False, True), (False, True), (False, True),
                (None, *Solver))]


def test_after_a_plan_that_moves_the_backend_then_ipopt_from_the_candidate() -> None:
    for active, previous in itertools.product((False, True), (False, True)):
        situation = Situation(plan_moves=True, obstacles_active=active,
                              previous_round=previous)
        assert solver_tries(situation) == (CANDIDATE_BACKEND, CANDIDATE_FALLBACK)


def test_from_rest_among_obstacles_ipopt_cold_starts_first() -> None:
    # then IPOPT cold from the candidate, the one feasible start (BARN 212, 213 at a stand)
    cold_candidate = Try(Start.CANDIDATE, Solver.IPOPT_COLD)
    rest = Situation(plan_moves=False, obstacles_active=True)
    assert solver_tries(rest) == (Try(Start.GUIDED, Solver.IPOPT_COLD), cold_candidate,
                                  CANDIDATE_BACKEND, CANDIDATE_FALLBACK)
    # a further constraint-generation round starts from the last round's solution
    again = dataclasses.replace(rest, previous_round=True)
    assert solver_tries(again) == (Try(Start.PREVIOUS_ROUND, Solver.IPOPT_COLD), cold_candidate,
                                   CANDIDATE_BACKEND, CANDIDATE_FALLBACK)


def test_from_rest_without_obstacles_ipopt_cold_starts_from_stay_put_then_the_others() -> None:
    for previous in (False, True):
        rest = Situation(plan_moves=False, obstacles_active=False, previous_round=previous)
        assert solver_tries(rest) == (Try(Start.CANDIDATE, Solver.IPOPT_COLD), CANDIDATE_BACKEND,
                                      GUIDED_FALLBACK, GUIDED_BACKEND)


def test_a_cut_try_goes_on_first_with_its_ipopt_or_a_cut_fatrop_with_the_warm_ipopt() -> None:
    for situation in every_situation():
        tries = solver_tries(situation)
        plain = solver_tries(dataclasses.replace(situation, continuation=None))
        cut = situation.continuation
        if cut is None:
            assert Start.CONTINUATION not in {t.start for t in tries}
        elif cut is Solver.BACKEND and situation.has_fallback:
            assert tries == (Try(Start.CONTINUATION, Solver.IPOPT_FALLBACK), *plain)
        elif situation.has_fallback or cut is not Solver.IPOPT_FALLBACK:
            assert tries == (Try(Start.CONTINUATION, cut), *plain)
        else:  # the cut try cannot have been a fallback the NLP does not have
            assert tries == plain


def test_without_a_fallback_its_tries_are_left_out_and_the_order_kept() -> None:
    for situation in every_situation():
        with_fallback = solver_tries(dataclasses.replace(situation, has_fallback=True))
        without = solver_tries(dataclasses.replace(situation, has_fallback=False))
        assert not any(t.solver is Solver.IPOPT_FALLBACK for t in without)
        # a cut fatrop try goes on with fatrop itself then (tested above)
        assert (tuple(t for t in without if t.start is not Start.CONTINUATION)
                == tuple(t for t in with_fallback if t.solver is not Solver.IPOPT_FALLBACK
                         and t.start is not Start.CONTINUATION))


def test_there_is_always_a_backend_try_and_no_try_twice() -> None:
    for situation in every_situation():
        tries = solver_tries(situation)
        assert any(t.solver is Solver.BACKEND for t in tries)
        assert len(set(tries)) == len(tries)


def test_a_situation_is_a_frozen_keyword_only_record() -> None:
    situation = Situation(plan_moves=True, obstacles_active=False)
    assert (situation.previous_round, situation.has_fallback, situation.continuation) == (
        False, True, None)
    with pytest.raises(dataclasses.FrozenInstanceError):
        situation.plan_moves = False  # type: ignore[misc]
    with pytest.raises(TypeError):
        Situation(True, False)  # type: ignore[misc]


def test_the_status_label_names_the_ipopt_that_solved() -> None:
    assert Solver.BACKEND.label == ''
    assert Solver.IPOPT_FALLBACK.label == ' (IPOPT fallback)'
    assert Solver.IPOPT_COLD.label == ' (IPOPT cold start)'


def test_tries_that_failed_here_before_go_last_in_their_order() -> None:
    for situation in every_situation():
        plain = solver_tries(situation)
        for failed in ({plain[0]}, set(plain[:2]), set(plain)):
            tries = solver_tries(dataclasses.replace(situation, failed=frozenset(failed)))
            assert set(tries) == set(plain)  # nothing left out: a failure may be luck
            assert tries == (tuple(t for t in plain if t not in failed)
                             + tuple(t for t in plain if t in failed))
