# SPDX-License-Identifier: Apache-2.0
"""The robot's pose in the plan's frame (map) from odometry (odom) and a localizer.

Odometry drifts: a plan in ``map`` followed with the odometry pose is followed displaced by
the drift. A localizer (AMCL's ``amcl_pose``) says where the robot is in ``map``, but late
and seldom; odometry is smooth and frequent. Composed, the correction ``map <- odom`` =
localizer_pose(t) * inverse(odom_pose(t)), computed at the localizer's stamp t with the
odometry interpolated in the history, is applied to every later odometry pose (and to the
odometry at a scan's stamp, so that the scan lands where the robot was in ``map``). This is
what tf2 does with AMCL's map -> odom transform; here without tf2, which PyPI does not have.

Without a localizer the correction is the identity: the odometry is the pose in the plan's
frame, as in the simulator. With one, there is no pose until its first message, and none
after a message the history cannot place (older than every odometry pose kept): the
controller stops and says why (`LocalizedPose.problem`).

A localizer can also fall silent: AMCL publishes only after the robot has moved
(``update_min_d`` 0.25 m, ``update_min_a`` 0.2 rad), so silence at rest is normal and a
timeout in seconds would stop a robot that waits. What is measured instead is how far the
odometry has moved from where it was at the last localizer pose's stamp (``max_travel``
metres, ``max_rotation`` radians; `LocalizedPose.staleness`): beyond a few times AMCL's update
thresholds the correction is stale, the localizer lost or dead, and the drift since then
uncorrected. The distance is the net displacement, as AMCL's thresholds measure it, not the
path length: noise on the odometry's pose at rest then adds nothing, where summed sample by
sample it would grow without bound. The largest displacement since the stamp is kept, so a
robot that moved away and came back stays stale. The count starts at the localizer's stamp,
not its arrival, so a late pose counts the motion made while it was on its way.
"""

from __future__ import annotations

import math

import numpy as np

from mpc_local_planner.core.paths import wrap_angle
from mpc_local_planner.perception.pose_history import PoseHistory
from mpc_local_planner.perception.scans import compose_pose

__all__ = ['compose', 'invert', 'LocalizationError', 'LocalizedPose']


class LocalizationError(ValueError):
    """A localizer pose that gives no correction (no odometry to compose it with, too old)."""


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return the planar pose a * b (b given in a's frame), its heading in [-pi, pi].

    The rule scans are placed with (compose_pose: the laser on the robot).
    """
    pose = compose_pose(a, b)
    pose[2] = float(wrap_angle(pose[2]))
    return pose


def invert(a: np.ndarray) -> np.ndarray:
    """Return the planar pose that undoes a (composed with a, the identity)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([-c * a[0] - s * a[1], s * a[0] - c * a[1], float(wrap_angle(-a[2]))])


class LocalizedPose:
    """Odometry history plus the latest localizer correction: poses in the plan's frame.

    Args:
        span: seconds of odometry kept (a scan's, or a localizer's, stamp is looked up in it).
        localized: a localizer is expected: no pose until its first message. False: the
            odometry is the pose in the plan's frame (the correction is the identity).
        source: the localizer's name in messages (its topic).
        max_travel: metres the odometry may move from its pose at the last localizer pose's
            stamp before that correction is stale (`staleness`); 0 = no limit.
        max_rotation: the same in radians of heading; 0 = no limit.

    """

    def __init__(self, span: float, *, localized: bool = False, source: str = '',
                 max_travel: float = 0.0, max_rotation: float = 0.0) -> None:
        self.odometry = PoseHistory(span)
        self.localized = bool(localized)
        self.source = source
        self.max_travel = float(max_travel)
        self.max_rotation = float(max_rotation)
        self.correction: np.ndarray | None = None
        self.problem: str | None = None
        self.corrections = 0  # localizer poses taken
        # the largest net displacement (m) and turn (rad) of the odometry from its pose at
        # the last localizer pose's stamp (the anchor)
        self.travel = 0.0
        self.rotation = 0.0
        self._anchor: np.ndarray | None = None
        self.clear()

    def clear(self) -> None:
        """Forget the odometry and the correction (as at construction)."""
        self.odometry.clear()
        self.correction = None if self.localized else np.zeros(3)
        self.problem = f'no localizer pose yet on {self.source!r}' if self.localized else None
        self.corrections = 0
        self.travel = self.rotation = 0.0
        self._anchor = None

    def add_odometry(self, time: float, pose: np.ndarray,
                     twist: np.ndarray | tuple[float, float] | None = None) -> None:
        """Keep an odometry pose (x, y, theta in odom) at time, with its twist (v, omega).

        The twist lets a scan's stamp just past the newest odometry be placed (PoseHistory).
        A pose newer than the newest may raise the largest displacement from the anchor.
        """
        forward = time > self.odometry.newest
        self.odometry.add(time, pose, twist)
        if forward:  # a step forward (a clock jump back starts anew)
            self._moved_to(np.asarray(pose[:3], dtype=float))

    def _moved_to(self, pose: np.ndarray) -> None:
        """Raise travel and rotation to pose's displacement from the anchor, if larger."""
        if self._anchor is None:
            return
        self.travel = max(self.travel, math.hypot(pose[0] - self._anchor[0],
                                                  pose[1] - self._anchor[1]))
        self.rotation = max(self.rotation, abs(float(wrap_angle(pose[2] - self._anchor[2]))))

    def add_localizer(self, time: float, pose: np.ndarray) -> np.ndarray:
        """Take a localizer pose (x, y, theta in the plan's frame) at time; return the correction.

        The odometry at time is interpolated in the history, or extrapolated along the
        newest odometry's twist within its bound (PoseHistory.at); a time later than that
        uses the newest odometry pose, as before: a localizer's message is not held back
        (a correction from a slightly stale pair beats none).

        Raises:
            LocalizationError: if no odometry is kept yet, or time is older than all of it;
                the correction is dropped then (no pose until a usable localizer pose).

        """
        if len(self.odometry) == 0:
            problem = f'localizer pose at {time:.3f} s but no odometry yet to compose it with'
        elif time < self.odometry.oldest:
            problem = (f'localizer pose at {time:.3f} s is older than the odometry kept '
                       f'(from {self.odometry.oldest:.3f} s, {self.odometry.span:g} s)')
        else:
            odom = self.odometry.at(time)
            if odom is None:  # past the extrapolation bound: the newest, as before
                odom = self.odometry.newest_pose()
            self.correction = compose(np.asarray(pose[:3], dtype=float), invert(odom))
            self.problem = None
            self.corrections += 1
            # the motion since its stamp: from the odometry then to the newest
            self._anchor = np.asarray(odom[:3], dtype=float)
            self.travel = self.rotation = 0.0
            self._moved_to(self.odometry.newest_pose())
            return self.correction.copy()
        self.correction, self.problem = None, problem
        raise LocalizationError(problem)

    def staleness(self) -> str | None:
        """Return why the correction in force is stale (None: it is not, or no limit applies).

        Stale when the odometry has moved more than max_travel, or turned more than
        max_rotation, from its pose at the last localizer pose's stamp: the localizer should have
        spoken by then (AMCL does after 0.25 m or 0.2 rad), so it is silent or lost, and the
        drift since is not corrected. A new localizer pose ends it.
        """
        if not self.localized or self.correction is None:
            return None
        if 0.0 < self.max_travel < self.travel:
            travelled = f'{self.travel:.2f} m (localization_max_travel {self.max_travel:g})'
        elif 0.0 < self.max_rotation < self.rotation:
            travelled = (f'{self.rotation:.2f} rad (localization_max_rotation '
                         f'{self.max_rotation:g})')
        else:
            return None
        return (f'no localizer pose on {self.source!r} while the odometry moved '
                f'{travelled}: the localizer is silent or lost')

    def pose(self, odom_pose: np.ndarray) -> np.ndarray | None:
        """Return an odometry pose in the plan's frame (None while there is no correction).

        Without a localizer it is the odometry pose itself, unchanged (a copy).
        """
        if not self.localized:
            return np.array(odom_pose[:3], dtype=float)
        if self.correction is None:
            return None
        return compose(self.correction, np.asarray(odom_pose[:3], dtype=float))

    def at(self, time: float) -> np.ndarray | None:
        """Return the pose in the plan's frame at time (None: no odometry then, no correction).

        The odometry at time (PoseHistory.at: interpolated, or extrapolated within its
        bound; None past it) with the latest correction: extrapolation is of odometry only.
        """
        odom = self.odometry.at(time)
        return None if odom is None else self.pose(odom)
