# SPDX-License-Identifier: Apache-2.0
"""InputFreshness: the controller server's check of the inputs' ages."""

from __future__ import annotations

import math

from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.input_freshness import InputFreshness

CHECK = InputFreshness(odom_timeout=0.5, scan_timeout=0.3)


def test_recent_inputs_pass_and_old_or_future_odometry_is_stale() -> None:
    assert CHECK.check(10.0, pose_time=9.6) is None
    assert CHECK.check(10.0, pose_time=None) is None  # no stamp: no age to judge
    assert CHECK.check(10.0, pose_time=9.4) is Reason.STALE_ODOM
    assert CHECK.check(10.0, pose_time=10.6) is Reason.STALE_ODOM  # the clock jumped back
    assert CHECK.check(10.0, pose_time=math.nan) is Reason.STALE_ODOM


def test_a_scan_counts_only_where_the_laser_is_a_source() -> None:
    assert CHECK.check(10.0, pose_time=10.0, scan_time=None) is None
    assert CHECK.check(10.0, pose_time=10.0, scan_required=True) is Reason.NO_SCAN
    assert CHECK.check(10.0, pose_time=10.0, scan_required=True,
                       scan_time=9.6) is Reason.STALE_SCAN
    assert CHECK.check(10.0, pose_time=10.0, scan_required=True, scan_time=9.8) is None


def test_stale_odometry_comes_before_the_scan_and_the_map() -> None:
    assert CHECK.check(10.0, pose_time=1.0, scan_required=True,
                       map_missing=True) is Reason.STALE_ODOM
    assert CHECK.check(10.0, pose_time=10.0, scan_required=True,
                       map_missing=True) is Reason.NO_SCAN
    assert CHECK.check(10.0, pose_time=10.0, map_missing=True) is Reason.NO_MAP


def test_the_timeouts_are_the_controller_settings() -> None:
    settings = ControllerSettings(odom_timeout=0.25, scan_timeout=0.75)
    assert InputFreshness.of(settings) == InputFreshness(0.25, 0.75)
