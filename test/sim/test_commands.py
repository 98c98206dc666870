# SPDX-License-Identifier: Apache-2.0
"""The command queue every plant receives its commands through (sim/commands.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.sim.base import Base
from mpc_local_planner.sim.commands import CommandQueue
from mpc_local_planner.sim.reality import Reality

MODEL = Unicycle(v_max=2.0, omega_max=4.0)


def test_commands_arrive_after_the_latency_saturated_and_in_order() -> None:
    queue = CommandQueue()
    queue.send([1.0, 0.5], 0.0, MODEL, 0.2)
    queue.send([5.0, -9.0], 0.1, MODEL, 0.2)

    assert queue.next_arrival == pytest.approx(0.2)
    assert queue.take(0.19) == []
    np.testing.assert_array_equal(queue.applied, [0.0, 0.0])  # nothing has arrived yet
    arrived = queue.take(0.5)
    assert [t for t, _ in arrived] == pytest.approx([0.2, 0.3])
    np.testing.assert_array_equal(arrived[0][1], [1.0, 0.5])
    np.testing.assert_array_equal(queue.applied, [2.0, -4.0])  # the latest, saturated
    assert queue.next_arrival is None


@pytest.mark.parametrize('u', [[math.nan, 1.0], [1.0, math.inf], [1.0], []])
def test_a_command_that_is_not_two_finite_numbers_is_a_stop(u: list) -> None:
    queue = CommandQueue()
    queue.send([1.0, 1.0], 0.0, MODEL, 0.0)
    queue.send(u, 1.0, MODEL, 0.0)
    queue.take(1.0)
    np.testing.assert_array_equal(queue.applied, [0.0, 0.0])


def test_the_kinematic_base_takes_a_command_of_one_number_as_a_stop() -> None:
    base = Base(MODEL, Reality(), [0.0, 0.0, 0.0])
    base.command([0.5], 0.0)
    base.advance(0.2)
    np.testing.assert_array_equal(base.pose, [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(base.target, [0.0, 0.0])
