# SPDX-License-Identifier: Apache-2.0
"""Scans taken in, each placed with the robot's pose at its stamp, in order: ScanIntake.

Both nodes (the controller's obstacle memory, the planner's grid and memory) take scans this
way, so one rule decides for both:

- a scan is refused if it cannot be interpreted (`validate_scan`, at most ``max_beams``
  beams) or is stamped in the future (`check_scan_stamp`);
- a valid scan waits (the latest ``capacity``, an older one falling out) until a pose at its
  stamp can be had (`PoseHistory`: none for a stamp more than MAX_EXTRAPOLATION_S past the
  latest odometry), then is placed; waiting scans are placed in order of arrival, and one
  still without a pose once older than the caller's timeout is discarded, never placed with
  an older pose, which would displace what it saw by the motion since;
- of the scans placed, one older than the latest taken by at most ``span`` seconds arrived
  out of order (the memory holds a newer view: skip it); one older by more means the clock
  jumped back (a restarted simulation, a bag played again): the memory starts anew rather
  than refusing every scan from then on.

No rclpy: the nodes read messages, log and hand the placed scans to their memories.
"""

from __future__ import annotations

from collections import deque
from enum import Enum
from typing import Callable, NamedTuple

import numpy as np

from mpc_local_planner.perception.scans import (
    check_scan_stamp,
    MAX_BEAMS,
    Scan,
    ScanError,
    validate_scan,
)

__all__ = ['Discarded', 'Dropped', 'Placed', 'ScanIntake', 'ScanOrder']


class ScanOrder(Enum):
    """How a placed scan's stamp stands to the latest scan taken (ScanIntake.order)."""

    IN_ORDER = 'in_order'
    # older than the latest taken by at most span: skip it, the memory is newer already
    LATE = 'late'
    # older by more than span: the clock jumped back, the memory starts anew
    CLOCK_JUMP = 'clock_jump'


class Placed(NamedTuple):
    """A scan with the robot's pose at its stamp, ready for the memory (or grid)."""

    scan: Scan
    receipt: float
    pose: np.ndarray


class Dropped(NamedTuple):
    """A scan whose pose could not be had (pose_at raised): it is dropped."""

    scan: Scan
    error: Exception


class Discarded(NamedTuple):
    """A scan that waited for a pose longer than the timeout: it is discarded."""

    scan: Scan


class ScanIntake:
    """The scans waiting for a pose, and the stamp of the latest one taken.

    Args:
        capacity: scans kept waiting (the latest; an older one falls out).
        span: seconds a placed scan may be older than the latest taken and still count as
            out of order rather than as the clock jumping back (the odometry kept).
        max_beams: more beams than this is refused (before decoding, too: check_beam_count).

    """

    def __init__(self, *, capacity: int, span: float, max_beams: int = MAX_BEAMS) -> None:
        self.span = float(span)
        self.max_beams = int(max_beams)
        # (scan, receipt) in order of arrival
        self._pending: deque[tuple[Scan, float]] = deque(maxlen=capacity)
        self._latest: float | None = None
        self._fresh: float | None = None

    @property
    def pending(self) -> int:
        """How many valid scans wait for a pose at their stamps."""
        return len(self._pending)

    @property
    def latest_stamp(self) -> float | None:
        """The stamp of the latest scan taken (`taken`); None: none yet."""
        return self._latest

    @property
    def fresh_time(self) -> float | None:
        """The latest usable scan's stamp, never later than its arrival (None: none yet).

        What a scan timeout is measured from: a waiting or blind scan renews nothing.
        """
        return self._fresh

    def check_beam_count(self, count: int) -> None:
        """Refuse a beam count above max_beams (a serialised scan's, before it is decoded).

        Raises:
            ScanError: if count > max_beams.

        """
        if count > self.max_beams:
            msg = f'{count} beams, more than the {self.max_beams} accepted'
            raise ScanError(msg)

    def add(self, scan: Scan, receipt: float) -> None:
        """Queue a scan until a pose at its stamp can be had.

        Args:
            scan: the scan, stamped (seconds of the node's clock).
            receipt: when it arrived (seconds of the node's clock).

        Raises:
            ScanError: if the scan cannot be interpreted or is stamped in the future.

        """
        validate_scan(scan, max_beams=self.max_beams)
        check_scan_stamp(scan.stamp, receipt)
        self._pending.append((scan, receipt))

    def place(self, pose_at: Callable[[float], np.ndarray | None], now: float,
              timeout: float) -> list[Placed | Dropped | Discarded]:
        """Place the waiting scans whose stamps pose_at now covers, in arrival order.

        pose_at covers every stamp up to a threshold, so a scan placed is never newer than
        one left waiting: the memory sees them in order.

        Args:
            pose_at: the robot's pose at a stamp; None: not yet (the scan waits); raises:
                no pose can be had for it (the scan is dropped).
            now: the node's clock (seconds).
            timeout: a scan still without a pose once older than this is discarded.

        Returns:
            What became of each scan that left the queue, in order.

        """
        events: list[Placed | Dropped | Discarded] = []
        waiting: list[tuple[Scan, float]] = []
        while self._pending:
            scan, receipt = self._pending.popleft()
            try:
                pose = pose_at(scan.stamp)
            except Exception as err:  # the caller says why (LocalizationError mostly)
                events.append(Dropped(scan, err))
                continue
            if pose is not None:
                events.append(Placed(scan, receipt, pose))
            elif now - scan.stamp <= timeout:
                waiting.append((scan, receipt))  # until odometry covers its stamp
            else:
                events.append(Discarded(scan))
        self._pending.extend(waiting)
        return events

    def order(self, stamp: float) -> ScanOrder:
        """Say how a placed scan stamped so stands to the latest taken (the module's rule)."""
        if self._latest is None or stamp >= self._latest:
            return ScanOrder.IN_ORDER
        if self._latest - stamp <= self.span:
            return ScanOrder.LATE
        return ScanOrder.CLOCK_JUMP

    def taken(self, stamp: float, receipt: float, *, usable: bool = True) -> None:
        """Note that the memory took a scan; a usable one renews fresh_time.

        Args:
            stamp: the scan's stamp.
            receipt: when it arrived.
            usable: whether it has a usable reading (a blind scan renews nothing).

        """
        self._latest = stamp
        if usable:
            self._fresh = min(stamp, receipt)

    def clear(self) -> None:
        """Drop the waiting scans (the latest stamps stay)."""
        self._pending.clear()
