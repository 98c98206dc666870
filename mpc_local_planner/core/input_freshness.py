# SPDX-License-Identifier: Apache-2.0
"""`InputFreshness`: whether the controller's inputs are recent enough to act on.

The controller server's check before it asks a controller for a command (Nav2's controller
server refuses stale odometry the same way): a stale or missing input is answered with a stop
(`MpcController.refuse_inputs`), never with a command computed from out-of-date data.
"""

from __future__ import annotations

from dataclasses import dataclass

from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.controller_settings import ControllerSettings, is_stale

__all__ = ['InputFreshness']


@dataclass(frozen=True)
class InputFreshness:
    """The ages the controller server accepts (seconds of the control clock).

    Attributes:
        odom_timeout: odometry older than this, or from the future by more (the clock
            jumped back), is stale.
        scan_timeout: the same for the latest scan, when the laser is a source of obstacles.

    """

    odom_timeout: float
    scan_timeout: float

    @classmethod
    def of(cls, settings: ControllerSettings) -> InputFreshness:
        """Return the check with the timeouts of settings."""
        return cls(settings.odom_timeout, settings.scan_timeout)

    def check(self, now: float, *, pose_time: float | None, scan_required: bool = False,
              scan_time: float | None = None, map_missing: bool = False) -> Reason | None:
        """Return why the inputs at now cannot be acted on, or None when they can.

        Args:
            now: the current time.
            pose_time: when the pose was measured, or None when its age is unknown.
            scan_required: the laser is a source of obstacles: without a scan (scan_time
                None) or with a stale one the robot stops, as the obstacles it knows may be
                out of date.
            scan_time: the stamp of the latest valid scan with a usable reading, or None.
            map_missing: the map is a source of obstacles and no valid map has come.

        """
        if pose_time is not None and is_stale(now - pose_time, self.odom_timeout):
            return Reason.STALE_ODOM
        if scan_required:
            if scan_time is None:
                return Reason.NO_SCAN
            if is_stale(now - scan_time, self.scan_timeout):
                return Reason.STALE_SCAN
        if map_missing:
            return Reason.NO_MAP
        return None
