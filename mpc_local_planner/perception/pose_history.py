# SPDX-License-Identifier: Apache-2.0
"""The robot's recent poses, so that a scan is placed where the robot was when it was taken.

A laser scan and the odometry arrive on different topics and at different times; placing a
scan with the latest pose instead of the pose at its stamp smears obstacles by the distance
(and turn) travelled in between. The history keeps the last few seconds of odometry and
interpolates between the two poses around a stamp.

A scan is often newer than the latest odometry (the two come from different drivers, and
odometry may arrive in bursts). Placed with that older pose, an obstacle ahead of a robot
driving at v lands v * gap closer than it is: at 1 m/s and 80 ms, 8 cm, enough for a phantom
obstacle and a stop. So a stamp newer than the newest pose is answered with the newest pose
moved along the unicycle arc of its twist (`unicycle_arc`, exact for a constant twist) for
the gap, if the gap is at most MAX_EXTRAPOLATION_S; beyond that the answer is None, "not
yet": the caller waits for odometry that covers the stamp, never uses the stale pose.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from mpc_local_planner.core.models import unicycle_arc
from mpc_local_planner.core.paths import wrap_angle

__all__ = ['MAX_EXTRAPOLATION_S', 'PoseHistory']

# How far (s) past the newest odometry a pose is extrapolated along its twist. About two
# odometry periods at 20-50 Hz (50 and 20 ms): one late or lost sample is bridged, while the
# error of a constant twist over the gap stays small (a 1 m/s^2 change of speed moves the
# robot 0.5 * 1 * 0.1^2 = 5 mm off in 0.1 s). A longer gap is odometry that is late, not
# merely between samples: the pose is not guessed then, the caller waits for it.
MAX_EXTRAPOLATION_S = 0.1
# Seconds of rounding forgiven at the bound (stamps are nanoseconds; sums of floats are not).
_STAMP_ROUNDING = 1e-9


class PoseHistory:
    """The last ``span`` seconds of (time, pose x, y, theta, twist v, omega), oldest first.

    Args:
        span: how many seconds of poses to keep (a scan older than that uses the oldest).
        max_extrapolation: how far (s) past the newest pose `at` extrapolates along its
            twist (MAX_EXTRAPOLATION_S); farther is None, "not yet".

    """

    def __init__(self, span: float = 2.0,
                 max_extrapolation: float = MAX_EXTRAPOLATION_S) -> None:
        self.span = float(span)
        self.max_extrapolation = float(max_extrapolation)
        self._times: list[float] = []
        self._poses: list[np.ndarray] = []
        self._twists: list[np.ndarray | None] = []

    def __len__(self) -> int:
        return len(self._times)

    def clear(self) -> None:
        """Forget every pose."""
        self._times.clear()
        self._poses.clear()
        self._twists.clear()

    def add(self, time: float, pose: np.ndarray,
            twist: np.ndarray | tuple[float, float] | None = None) -> None:
        """Keep pose at time, and the twist (v, omega) measured with it.

        Out-of-order times are sorted in; a clock jump back clears. A twist that is None or
        not finite is unknown: nothing is extrapolated from that pose (stamps after it are
        "not yet" until a newer pose comes).
        """
        if self._times and time < self._times[-1] - self.span:
            self.clear()  # the clock jumped back: the old poses are of another time
        known = None
        if twist is not None:
            known = np.array(twist[:2], dtype=float)
            if not np.all(np.isfinite(known)):
                known = None
        index = bisect.bisect_right(self._times, time)
        self._times.insert(index, float(time))
        self._poses.insert(index, np.array(pose[:3], dtype=float))
        self._twists.insert(index, known)
        oldest_kept = bisect.bisect_left(self._times, self._times[-1] - self.span)
        del self._times[:oldest_kept], self._poses[:oldest_kept], self._twists[:oldest_kept]

    @property
    def oldest(self) -> float:
        """The time of the oldest pose kept (inf when empty)."""
        return self._times[0] if self._times else math.inf

    @property
    def newest(self) -> float:
        """The time of the newest pose kept (-inf when empty)."""
        return self._times[-1] if self._times else -math.inf

    def newest_pose(self) -> np.ndarray | None:
        """Return the newest pose kept, as measured (None when empty)."""
        return self._poses[-1].copy() if self._poses else None

    def gap(self, time: float) -> float:
        """Return how far (seconds) time is from the nearest pose kept (inf when empty)."""
        if not self._times:
            return math.inf
        index = bisect.bisect_left(self._times, time)
        neighbours = self._times[max(index - 1, 0):index + 1]
        return min(abs(t - time) for t in neighbours)

    def at(self, time: float) -> np.ndarray | None:
        """Return the pose at time; None if empty or if time is not covered yet.

        Between two poses the position is interpolated linearly and the heading along the
        shorter turn; before the oldest pose kept the oldest is returned. After the newest,
        within max_extrapolation of it, the newest pose moved along the arc of its twist
        (unicycle_arc); farther, or with its twist unknown, None: the odometry for that
        time has not come yet, and the newest pose is not where the robot was then.
        """
        if not self._times:
            return None
        if time <= self._times[0]:
            return self._poses[0].copy()
        if time >= self._times[-1]:
            ahead = time - self._times[-1]
            if ahead == 0.0:
                return self._poses[-1].copy()
            twist = self._twists[-1]
            if twist is None or ahead > self.max_extrapolation + _STAMP_ROUNDING:
                return None
            return unicycle_arc(self._poses[-1], float(twist[0]), float(twist[1]), ahead)
        index = bisect.bisect_left(self._times, time)
        t0, t1 = self._times[index - 1], self._times[index]
        p0, p1 = self._poses[index - 1], self._poses[index]
        f = (time - t0) / (t1 - t0) if t1 > t0 else 1.0
        pose = p0 + f * (p1 - p0)
        pose[2] = p0[2] + f * float(wrap_angle(p1[2] - p0[2]))
        return pose
