# SPDX-License-Identifier: Apache-2.0
"""ScanIntake, without ROS: the rules both nodes take scans by.

Scans wait for a pose at their stamps and are placed in order; one out-of-order and
clock-jump rule; one beam limit.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from mpc_local_planner.perception.scan_intake import (
    Discarded,
    Dropped,
    Placed,
    ScanIntake,
    ScanOrder,
)
from mpc_local_planner.perception.scans import Scan, ScanError

POSE = np.array([1.0, 2.0, 0.5])


def scan(stamp: float, **changes: Any) -> Scan:
    return Scan(-1.0, 0.01, 0.05, 10.0, np.full(201, 3.0), stamp=stamp)._replace(**changes)


def covered_until(limit: float):
    """A pose source that has a pose for every stamp up to limit, none after."""
    def pose_at(stamp: float) -> np.ndarray | None:
        return POSE if stamp <= limit else None
    return pose_at


def test_a_scan_the_pose_covers_is_placed_with_its_receipt_and_pose() -> None:
    intake = ScanIntake(capacity=3, span=2.0)
    intake.add(scan(10.0), receipt=10.02)
    events = intake.place(covered_until(10.0), now=10.02, timeout=0.5)
    assert len(events) == 1 and isinstance(events[0], Placed)
    assert events[0].scan.stamp == 10.0 and events[0].receipt == 10.02
    np.testing.assert_array_equal(events[0].pose, POSE)
    assert intake.pending == 0


def test_scans_wait_for_a_pose_and_are_placed_in_arrival_order() -> None:
    intake = ScanIntake(capacity=3, span=2.0)
    for stamp in (10.0, 10.1, 10.2):
        intake.add(scan(stamp), receipt=stamp)
    assert intake.place(covered_until(9.9), now=10.2, timeout=0.5) == []
    assert intake.pending == 3
    events = intake.place(covered_until(10.1), now=10.25, timeout=0.5)
    assert [e.scan.stamp for e in events] == [10.0, 10.1]  # never one newer than a waiting
    assert intake.pending == 1


def test_the_oldest_waiting_scan_falls_out_beyond_the_capacity() -> None:
    intake = ScanIntake(capacity=2, span=2.0)
    for stamp in (10.0, 10.1, 10.2):
        intake.add(scan(stamp), receipt=stamp)
    events = intake.place(covered_until(11.0), now=10.2, timeout=0.5)
    assert [e.scan.stamp for e in events] == [10.1, 10.2]


def test_a_scan_without_a_pose_past_the_timeout_is_discarded_and_one_within_waits() -> None:
    intake = ScanIntake(capacity=3, span=2.0)
    intake.add(scan(10.0), receipt=10.0)
    intake.add(scan(10.4), receipt=10.4)
    events = intake.place(covered_until(9.0), now=10.5, timeout=0.3)
    assert events == [Discarded(events[0].scan)] and events[0].scan.stamp == 10.0
    assert intake.pending == 1
    # exactly the timeout old still waits
    intake2 = ScanIntake(capacity=3, span=2.0)
    intake2.add(scan(10.0), receipt=10.0)
    assert intake2.place(covered_until(9.0), now=10.25, timeout=0.25) == []


def test_a_scan_whose_pose_cannot_be_had_is_dropped_with_the_error() -> None:
    intake = ScanIntake(capacity=3, span=2.0)
    intake.add(scan(10.0), receipt=10.0)
    problem = LookupError('no transform')

    def broken(stamp: float) -> np.ndarray | None:
        raise problem

    events = intake.place(broken, now=10.0, timeout=0.5)
    assert len(events) == 1 and isinstance(events[0], Dropped)
    assert events[0].error is problem and intake.pending == 0


def test_a_malformed_scan_or_one_from_the_future_is_refused_and_not_queued() -> None:
    intake = ScanIntake(capacity=3, span=2.0)
    with pytest.raises(ScanError, match='angle_increment must not be 0'):
        intake.add(scan(10.0, angle_increment=0.0), receipt=10.0)
    with pytest.raises(ScanError, match='in the future'):
        intake.add(scan(10.5), receipt=10.0)
    assert intake.pending == 0


def test_the_beam_limit_is_one_value_for_a_count_and_for_a_scan() -> None:
    intake = ScanIntake(capacity=3, span=2.0, max_beams=100)
    intake.check_beam_count(100)
    with pytest.raises(ScanError, match='101 beams, more than the 100 accepted'):
        intake.check_beam_count(101)
    with pytest.raises(ScanError, match='more than the 100 accepted'):
        intake.add(scan(10.0, ranges=np.ones(101)), receipt=10.0)
    intake.add(scan(10.0, ranges=np.ones(100)), receipt=10.0)
    assert intake.pending == 1


def test_out_of_order_within_the_span_is_late_and_beyond_it_a_clock_jump() -> None:
    intake = ScanIntake(capacity=3, span=2.0)
    assert intake.order(5.0) is ScanOrder.IN_ORDER  # nothing taken yet
    intake.taken(10.0, 10.0)
    assert intake.order(10.0) is ScanOrder.IN_ORDER
    assert intake.order(10.5) is ScanOrder.IN_ORDER
    assert intake.order(9.0) is ScanOrder.LATE
    assert intake.order(8.0) is ScanOrder.LATE  # exactly the span
    assert intake.order(7.9) is ScanOrder.CLOCK_JUMP
    intake.taken(1.0, 1.0)  # after a jump the memory starts anew from the new stamp
    assert intake.order(1.5) is ScanOrder.IN_ORDER


def test_a_usable_scan_renews_fresh_time_no_later_than_its_arrival_a_blind_one_does_not(
        ) -> None:
    intake = ScanIntake(capacity=3, span=2.0)
    assert intake.latest_stamp is None and intake.fresh_time is None
    intake.taken(10.0, receipt=9.95)  # stamped after it arrived (clock skew)
    assert intake.latest_stamp == 10.0 and intake.fresh_time == 9.95
    intake.taken(10.1, receipt=10.2, usable=False)
    assert intake.latest_stamp == 10.1 and intake.fresh_time == 9.95


def test_clear_drops_the_waiting_scans() -> None:
    intake = ScanIntake(capacity=3, span=2.0)
    intake.add(scan(10.0), receipt=10.0)
    intake.clear()
    assert intake.pending == 0
    assert intake.place(covered_until(11.0), now=10.0, timeout=0.5) == []
