# SPDX-License-Identifier: Apache-2.0
"""The lockstep clock's rules: what it waits for before simulated time may move."""

from __future__ import annotations

from mpc_local_planner.sim.lockstep import (
    awaited_matches,
    awaited_messages,
    awaited_participants,
    awaited_steps,
    StepStatus,
)

SIM = StepStatus('sim', 0, None, published={'/odom': 3}, received={'/cmd_vel': 1},
                 matched={'/odom': 2})
CONTROLLER = StepStatus('controller', 0, 50_000_000, published={'/cmd_vel': 1},
                        received={'/odom': 3, '/plan': 1}, matched={'/cmd_vel': 1})
PLANNER = StepStatus('planner', 0, None, published={'/plan': 1}, received={'/odom': 3},
                     matched={'/plan': 1})


def test_nothing_is_awaited_when_every_message_is_taken_and_no_step_is_due() -> None:
    statuses = [SIM, CONTROLLER, PLANNER]
    assert awaited_messages(statuses) == []
    assert awaited_matches(statuses) == []
    assert awaited_steps(statuses, 49_999_999) == []


def test_a_message_not_yet_taken_is_awaited_by_reader_and_topic() -> None:
    behind = StepStatus('planner', 0, None, published={'/plan': 1}, received={'/odom': 2})
    assert awaited_messages([SIM, CONTROLLER, behind]) == [
        'planner has taken 2 of 3 messages on /odom']


def test_counts_add_up_over_every_publisher_of_a_topic() -> None:
    second = StepStatus('teleop', 0, None, published={'/cmd_vel': 4})
    assert awaited_messages([SIM, CONTROLLER, second]) == [
        'sim has taken 1 of 5 messages on /cmd_vel']


def test_a_topic_no_participant_publishes_is_not_waited_for() -> None:
    reader = StepStatus('controller', 0, None, received={'/goal_pose': 0, '/odom': 3})
    assert awaited_messages([SIM, reader]) == []


def test_a_step_due_by_now_is_awaited_until_its_node_reports_the_next_one() -> None:
    assert awaited_steps([CONTROLLER], 50_000_000) == [
        'controller has not finished its step due at 0.050 s']
    done = StepStatus('controller', 50_000_000, 100_000_000)
    assert awaited_steps([done], 50_000_000) == []


def test_the_clock_starts_only_when_each_publisher_matched_every_participant_reader() -> None:
    unmatched = StepStatus('sim', 0, None, published={'/odom': 0}, matched={'/odom': 1})
    assert awaited_matches([unmatched, CONTROLLER, PLANNER]) == [
        'sim has matched 1 of the 2 participants reading /odom']
    assert awaited_participants({'controller': CONTROLLER}, ['controller', 'planner']) == [
        'planner has not reported']
