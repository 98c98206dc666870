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

"""The pure-pursuit baseline: reaches the end of simple paths within the unicycle's bounds."""

import numpy as np
import pytest

from mpc_local_planner.core.baselines.pure_pursuit import PurePursuit, PurePursuitConfig
from mpc_local_planner.core.models import Unicycle


def _follow(waypoints, start, steps=2000, h=0.1):
    model = Unicycle()
    follower = PurePursuit(np.array(waypoints, dtype=float),
                           PurePursuitConfig(v_max=model.v_max, omega_max=model.omega_max))
    x = np.array(start, dtype=float)
    inputs = []
    for _ in range(steps):
        u = follower.command(x)
        inputs.append(u)
        if not np.any(u):
            break
        x = model.step(x, u, h)
    return x, np.array(inputs), follower


def test_straight_path_is_followed_to_its_end() -> None:
    x, inputs, _ = _follow([[0, 0], [3, 0]], [0, 0, 0])
    assert np.hypot(x[0] - 3, x[1]) <= 0.03
    assert not np.any(inputs[-1])  # stopped at the end
    assert np.all(np.abs(inputs[:, 0]) <= 0.31 + 1e-12)
    assert np.all(np.abs(inputs[:, 1]) <= 1.9 + 1e-12)


def test_l_shaped_path_is_followed_to_its_end_close_to_the_corner() -> None:
    x, inputs, follower = _follow([[0, 0], [2, 0], [2, 2]], [0, 0.1, 0.5])
    assert np.hypot(x[0] - 2, x[1] - 2) <= 0.03
    assert follower.progress == pytest.approx(follower.length, abs=0.05)
    assert np.all(np.abs(inputs[:, 1]) <= 1.9 + 1e-12)


def test_robot_facing_away_turns_in_place_first() -> None:
    follower = PurePursuit(np.array([[0.0, 0.0], [2.0, 0.0]]))
    u = follower.command(np.array([0.0, 0.0, np.pi]))
    assert u[0] == 0.0 and abs(u[1]) == pytest.approx(1.9)


def test_degenerate_paths_and_settings_are_refused() -> None:
    with pytest.raises(ValueError):
        PurePursuit(np.array([[1.0, 1.0], [1.0, 1.0]]))
    with pytest.raises(ValueError):
        PurePursuitConfig(lookahead=0.0)
