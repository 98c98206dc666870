# SPDX-License-Identifier: Apache-2.0
"""ProblemThrottle: once per episode, then once per period, on the clock the test holds."""

from mpc_local_planner.ros.throttle import ERROR_THROTTLE_S, ProblemThrottle


def test_a_persisting_problem_is_logged_once_per_period_of_the_throttle_clock(
        throttle_clock) -> None:
    throttle = ProblemThrottle(ERROR_THROTTLE_S)  # the nodes' default clock
    assert throttle.report('scan')
    assert not any(throttle.report('scan') for _ in range(100))  # however many, no time
    throttle_clock.advance(ERROR_THROTTLE_S - 1e-6)
    assert not throttle.report('scan')
    throttle_clock.advance(1e-6)
    assert throttle.report('scan')
    assert throttle.report('odom')  # channels are independent


def test_a_problem_that_resolves_is_reported_anew_at_once(throttle_clock) -> None:
    throttle = ProblemThrottle(ERROR_THROTTLE_S)
    assert throttle.report('plan') and not throttle.report('plan')
    assert throttle.resolve('plan') and not throttle.resolve('plan')
    assert throttle.report('plan')  # a second episode, no time passed


def test_an_explicit_clock_wins_over_the_default() -> None:
    now = [10.0]
    throttle = ProblemThrottle(1.0, clock=lambda: now[0])
    assert throttle.report('map') and not throttle.report('map')
    now[0] += 1.0
    assert throttle.report('map')
