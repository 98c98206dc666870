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


"""The robot's recent poses, so that a scan is placed where the robot was when it was taken.

A laser scan and the odometry arrive on different topics and at different times; placing a
scan with the latest pose instead of the pose at its stamp smears obstacles by the distance
(and turn) travelled in between. The history keeps the last few seconds of odometry and
interpolates between the two poses around a stamp.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from mpc_local_planner.core.paths import wrap_angle

__all__ = ['PoseHistory']


class PoseHistory:
    """The last ``span`` seconds of (time, pose x, y, theta), oldest first.

    Args:
        span: how many seconds of poses to keep (a scan older than that uses the oldest).

    """

    def __init__(self, span: float = 2.0) -> None:
        self.span = float(span)
        self._times: list[float] = []
        self._poses: list[np.ndarray] = []

    def __len__(self) -> int:
        return len(self._times)

    def clear(self) -> None:
        """Forget every pose."""
        self._times.clear()
        self._poses.clear()

    def add(self, time: float, pose: np.ndarray) -> None:
        """Keep pose at time (out-of-order times are sorted in; a clock jump back clears)."""
        if self._times and time < self._times[-1] - self.span:
            self.clear()  # the clock jumped back: the old poses are of another time
        index = bisect.bisect_right(self._times, time)
        self._times.insert(index, float(time))
        self._poses.insert(index, np.array(pose[:3], dtype=float))
        oldest_kept = bisect.bisect_left(self._times, self._times[-1] - self.span)
        del self._times[:oldest_kept], self._poses[:oldest_kept]

    @property
    def oldest(self) -> float:
        """The time of the oldest pose kept (inf when empty)."""
        return self._times[0] if self._times else math.inf

    def gap(self, time: float) -> float:
        """Return how far (seconds) time is from the nearest pose kept (inf when empty)."""
        if not self._times:
            return math.inf
        index = bisect.bisect_left(self._times, time)
        neighbours = self._times[max(index - 1, 0):index + 1]
        return min(abs(t - time) for t in neighbours)

    def at(self, time: float) -> np.ndarray | None:
        """Return the pose at time (None if empty).

        Between two poses the position is interpolated linearly and the heading along the
        shorter turn; before the oldest pose kept the oldest is returned, after the newest
        the newest (no extrapolation).
        """
        if not self._times:
            return None
        if time <= self._times[0]:
            return self._poses[0].copy()
        if time >= self._times[-1]:
            return self._poses[-1].copy()
        index = bisect.bisect_left(self._times, time)
        t0, t1 = self._times[index - 1], self._times[index]
        p0, p1 = self._poses[index - 1], self._poses[index]
        f = (time - t0) / (t1 - t0) if t1 > t0 else 1.0
        pose = p0 + f * (p1 - p0)
        pose[2] = p0[2] + f * float(wrap_angle(p1[2] - p0[2]))
        return pose
