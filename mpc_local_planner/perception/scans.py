# SPDX-License-Identifier: Apache-2.0
"""Laser scans as REP 117 reads them: what a scan must hold, what each beam means.

1. `validate_scan`: refuse a scan that cannot be interpreted (angles, increment, beam count,
   limits, intensities) with a `ScanError` naming the problem. Its readings are never a
   reason: a real driver publishes NaN and -inf all the time, and a controller that drops the
   whole scan for one of them never moves.
2. `classify_beams`: the one place where a reading's meaning is decided, beam by beam, as
   REP 117 says: a reading in [range_min, range_max] is a return; +inf is no return (free up
   to range_max); -inf is "too close", taken conservatively as a return at range_min that
   proves nothing free; NaN (an erroneous reading) and finite readings outside the limits are
   ignored. Given the robot's footprint (``body``), a return inside it (a -inf one at
   range_min included) is the robot itself and is ignored too, as a laser self-filter does.
   Every reader (the points, the obstacle memory's clearing, the planner's grid) asks it.
3. `scan_points`: the returns in the map frame, from the robot's pose at the scan's stamp
   and the laser's mounting pose in the robot frame (`compose_pose`).

`check_beam_count` and `check_scan_stamp` are the checks a node makes of a message before it
becomes a `Scan`. NumPy only.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import numpy as np

from mpc_local_planner.core.footprint import Footprint

__all__ = [
    'CLUSTER_GAP',
    'cluster_bounds',
    'BODY_MARGIN',
    'Beams',
    'MAX_BEAMS',
    'MAX_SCAN_FUTURE_S',
    'Scan',
    'ScanError',
    'check_beam_count',
    'check_scan_stamp',
    'classify_beams',
    'compose_pose',
    'scan_points',
    'validate_scan',
]

# Consecutive returns farther apart than this (m) belong to different objects: below the
# robot's diameter, so that no passage is closed by joining two objects (the memory's and the
# tracker's clusters).
CLUSTER_GAP = 0.3

#: More beams than this is refused: no planar laser has them, and a corrupt message might.
MAX_BEAMS = 10_000
#: Seconds a scan's stamp may be ahead of the receiving node's clock (clock skew between
#: the laser's computer and this one); a scan further in the future is refused.
MAX_SCAN_FUTURE_S = 0.2
#: A return at most this far outside the robot's footprint (metres) is still the robot itself
#: (see `classify_beams`).
BODY_MARGIN = 1e-3


class ScanError(ValueError):
    """A laser scan (or the pose it is taken from) is malformed."""


class Scan(NamedTuple):
    """A planar laser scan, as sensor_msgs/LaserScan carries it (without the header).

    Attributes:
        angle_min: Angle of the first beam in the laser frame, radians.
        angle_increment: Angle between consecutive beams (negative for a clockwise scan).
        range_min: Closest valid reading, metres.
        range_max: Farthest valid reading, metres.
        ranges: (beams,) readings, as REP 117 gives them (see `classify_beams`).
        intensities: (beams,) or empty.
        stamp: Time of the scan, seconds.
        angle_max: Angle of the last beam as the message states it, or None when the scan
            was made here (the simulated laser) and cannot disagree with its beam count.

    """

    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: np.ndarray
    intensities: np.ndarray | None = None
    stamp: float = 0.0
    angle_max: float | None = None


def validate_scan(scan: Scan, *, max_beams: int = MAX_BEAMS) -> None:
    """Refuse a scan that cannot be interpreted, naming the problem.

    Only the scan's frame of reference is checked: where its beams point and what its
    limits are. Its readings are judged beam by beam (`classify_beams`), never here: a NaN,
    -inf or out-of-range reading makes that beam ignored (or, for -inf, a return at
    range_min), not the scan invalid.

    Args:
        scan: The scan.
        max_beams: Largest number of beams accepted.

    Raises:
        ScanError: If an angle or limit is not finite, the increment is 0, range_min < 0 or
            range_max <= range_min, the ranges are not a 1-D array of numbers, the
            intensities' length differs from the ranges', there are more than max_beams
            beams, the beams cover more than a full turn, the stamp is not finite, or the
            beam count disagrees with the angles (see check_beam_count).

    """
    names = ('angle_min', 'angle_increment', 'range_min', 'range_max', 'stamp')
    if scan.angle_max is not None:
        names += ('angle_max',)
    for name in names:
        value = getattr(scan, name)
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
            msg = f'scan {name} must be a number, got {value!r}'
            raise ScanError(msg)
        if not math.isfinite(value):
            msg = f'scan {name} must be finite, got {value!r}'
            raise ScanError(msg)
    if scan.angle_increment == 0.0:
        msg = 'scan angle_increment must not be 0'
        raise ScanError(msg)
    if not (0.0 <= scan.range_min < scan.range_max):
        msg = f'scan needs 0 <= range_min < range_max, got {scan.range_min}, {scan.range_max}'
        raise ScanError(msg)
    ranges = np.asarray(scan.ranges)
    if ranges.ndim != 1:
        msg = f'scan ranges must be one-dimensional, got shape {ranges.shape}'
        raise ScanError(msg)
    if len(ranges) > max_beams:
        msg = f'scan has {len(ranges)} beams, more than the {max_beams} accepted'
        raise ScanError(msg)
    if not np.issubdtype(ranges.dtype, np.number):
        msg = f'scan ranges must be numbers, got dtype {ranges.dtype}'
        raise ScanError(msg)
    if scan.intensities is not None and len(scan.intensities) not in (0, len(ranges)):
        msg = (f'scan has {len(ranges)} ranges but {len(scan.intensities)} intensities '
               '(expected the same number, or none)')
        raise ScanError(msg)
    if abs(scan.angle_increment) * max(len(ranges) - 1, 0) > 2.0 * math.pi + 1e-6:
        msg = (f'scan covers more than a full turn ({len(ranges)} beams of '
               f'{scan.angle_increment} rad)')
        raise ScanError(msg)
    if scan.angle_max is not None:
        check_beam_count(scan.angle_min, scan.angle_max, scan.angle_increment, len(ranges))


class Beams(NamedTuple):
    """What each beam of a scan says (REP 117), as `classify_beams` reads it.

    Attributes:
        hit: (beams,) True where the beam returned from a surface at ``seen``: a reading in
            [range_min, range_max], or -inf ("too close"), placed at range_min; never a
            return inside the robot's body, when it is given.
        seen: (beams,) how far the beam observed the world, metres: its return, range_max for
            +inf (no return within range), NaN for an ignored beam (a NaN reading, a finite
            one outside [range_min, range_max], or a return inside the robot's body), which
            observed nothing.
        free: (beams,) how far the beam proves free space, metres: up to its return (a
            reading in range) or range_max (+inf); 0 for -inf and ignored beams, which
            clear nothing.

    """

    hit: np.ndarray
    seen: np.ndarray
    free: np.ndarray

    @property
    def usable(self) -> np.ndarray:
        """(beams,) True where the beam carries information (it is not ignored)."""
        return ~np.isnan(self.seen)


def classify_beams(scan: Scan, *, body: Footprint | None = None,
                   laser_pose: Sequence[float] = (0.0, 0.0, 0.0)) -> Beams:
    """Say, beam by beam, what a scan's readings mean: the one rule every reader applies.

    REP 117: a reading in [range_min, range_max] is a return; +inf is no return within
    range_max (the beam's whole length is free); -inf is an object too close to measure,
    taken conservatively as a return at range_min that proves nothing free; NaN is an
    erroneous reading and a finite reading outside the limits an invalid one: both are
    ignored (no return, no free space). Every reading is judged on its own.

    The robot's own body: a return inside its footprint (within BODY_MARGIN of it) is the
    robot itself (its chassis, a mount, a cable in view) or a spurious reading, never an
    obstacle it could avoid: kept, it would sit inside the robot, where no input keeps the
    MPC's constraints and the planner's start feasible, and the robot would stop for good.
    Such a beam is ignored like a NaN one (laser_filters' footprint filter writes NaN there
    too): no return, and nothing free, since the body hides what lies beyond. This is what
    makes -inf usable on a real robot: its range_min point is inside the body for a laser
    mounted within it (5 cm from a laser at the centre of a 0.2 m robot), and only outside
    it (a laser at the front edge) is it an obstacle, as REP 117 means it. The margin of a
    millimetre takes in the returns of a part flush with the footprint's outline (the laser's
    own housing at an edge), which rounding in the beam's geometry puts either side of it;
    an obstacle that close already touches the robot, and its farther points still count.

    Args:
        scan: A scan that passed `validate_scan` (its limits are finite and ordered).
        body: The robot's footprint (the robot frame), which must be its body, not grown by
            a clearance; None: no return is taken for the robot (nothing is dropped).
        laser_pose: (x, y, yaw) of the laser in the robot frame (used with body only).

    Returns:
        The beams' returns, reach and free space.

    Raises:
        ScanError: If body is given and laser_pose is not three finite numbers.

    """
    ranges = np.asarray(scan.ranges, dtype=float)
    in_range = (ranges >= scan.range_min) & (ranges <= scan.range_max)
    no_return = ranges == math.inf
    too_close = ranges == -math.inf
    hit = in_range | too_close
    seen = np.where(in_range, ranges, np.nan)
    seen[no_return] = scan.range_max
    seen[too_close] = scan.range_min
    free = np.where(in_range, ranges, 0.0)
    free[no_return] = scan.range_max
    if body is not None:
        beams = np.flatnonzero(hit)
        mount = compose_pose((0.0, 0.0, 0.0), laser_pose)  # the laser in the robot frame
        own = beams[body.contains(_beam_points(scan, beams, seen[beams], mount),
                                  margin=BODY_MARGIN)]
        hit[own] = False
        seen[own] = np.nan
        free[own] = 0.0
    return Beams(hit=hit, seen=seen, free=free)


def _beam_points(scan: Scan, beams: np.ndarray, ranges: np.ndarray,
                 laser: Sequence[float]) -> np.ndarray:
    """Return the points at ranges along the given beams of a laser at (x, y, yaw), (N, 2)."""
    ox, oy, oyaw = laser
    theta = oyaw + scan.angle_min + beams * scan.angle_increment
    return np.column_stack([ox + ranges * np.cos(theta), oy + ranges * np.sin(theta)])


def check_beam_count(angle_min: float, angle_max: float, angle_increment: float,
                     beams: int) -> None:
    """Refuse a beam count that the angles do not imply, within one increment.

    The beams are at angle_min + i angle_increment, i = 0 .. beams - 1, so the last one must
    be at angle_max. A count that is off (250 or 60 ranges where the angles imply 181), or
    an increment whose sign does not lead from angle_min to angle_max, means the ranges
    cannot be put at their angles: every obstacle would be placed wrong.

    Raises:
        ScanError: If the last beam's angle is more than one increment from angle_max.

    """
    last = angle_min + (beams - 1) * angle_increment
    if abs(last - angle_max) <= abs(angle_increment) * (1.0 + 1e-6):
        return
    span = (angle_max - angle_min) / angle_increment
    if not math.isfinite(span):  # angles so far apart that the count overflows
        implied = 'more beams than can be counted'
    elif span > -0.5:
        implied = f'{round(span) + 1}'
    else:
        implied = "none (the increment's sign leads away from angle_max)"
    msg = (f'scan has {beams} ranges but angle_min {angle_min:.6g}, angle_max '
           f'{angle_max:.6g} and angle_increment {angle_increment:.6g} imply {implied}')
    raise ScanError(msg)


def check_scan_stamp(stamp: float, now: float, *,
                     tolerance: float = MAX_SCAN_FUTURE_S) -> None:
    """Refuse a scan stamped in the future by more than tolerance seconds.

    Placed with the latest pose, such a scan would put what the laser saw where the robot
    was not; and stamped ahead it would keep the laser fresh after it stopped.

    Raises:
        ScanError: If stamp - now > tolerance.

    """
    if stamp - now > tolerance:
        msg = (f'scan stamped {stamp - now:.3f} s in the future (stamp {stamp:.3f} s, now '
               f'{now:.3f} s; at most {tolerance:g} s is accepted): are the clocks in sync?')
        raise ScanError(msg)


def cluster_bounds(points: np.ndarray, gap: float) -> tuple[np.ndarray, np.ndarray]:
    """Split points (in beam order) where consecutive ones are farther apart than gap.

    Args:
        points: (N, 2) points in beam order.
        gap: Largest distance between neighbours of one cluster, metres.

    Returns:
        (first, last): index of each cluster's first and last point (inclusive).

    """
    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    step = np.hypot(*np.diff(points, axis=0).T) if n > 1 else np.zeros(0)
    breaks = np.flatnonzero(step > gap)
    return np.concatenate([[0], breaks + 1]), np.concatenate([breaks, [n - 1]])


def compose_pose(robot_pose: Sequence[float],
                 laser_pose: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Return the laser's pose in the map frame from the robot's and the mounting pose.

    Args:
        robot_pose: (x, y, yaw) of the robot in the map frame (at the scan's stamp).
        laser_pose: (x, y, yaw) of the laser in the robot frame.

    Returns:
        (3,) x, y, yaw.

    Raises:
        ScanError: If either pose is not three finite numbers.

    """
    poses = []
    for name, pose in (('robot pose', robot_pose), ('laser pose', laser_pose)):
        values = np.asarray(pose, dtype=float).ravel()
        if values.shape[0] < 3 or not np.all(np.isfinite(values[:3])):
            msg = f'{name} must be three finite numbers (x, y, yaw), got {tuple(pose)}'
            raise ScanError(msg)
        poses.append(values[:3])
    (x, y, yaw), (lx, ly, lyaw) = poses
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([x + c * lx - s * ly, y + s * lx + c * ly, yaw + lyaw])


def scan_points(scan: Scan, robot_pose: Sequence[float], *,
                laser_pose: Sequence[float] = (0.0, 0.0, 0.0),
                body: Footprint | None = None,
                readings: Beams | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Return the valid returns of a scan in the map frame, in beam order.

    Args:
        scan: A valid scan (see `validate_scan`).
        robot_pose: (x, y, yaw) of the robot in the map frame at the scan's stamp.
        laser_pose: (x, y, yaw) of the laser in the robot frame.
        body: The robot's footprint: returns inside it are the robot (see `classify_beams`);
            None: every return counts.
        readings: The scan's beams as `classify_beams(scan, body=body, laser_pose=...)`
            reads them, when the caller has them already (the memory and the planner's grid
            use them for clearing too); None: read here.

    Returns:
        (points (N, 2), beam indices (N,)): the returns of `classify_beams` (readings in
        [range_min, range_max], and -inf at range_min, outside the body).

    Raises:
        ScanError: If a pose is not finite.

    """
    laser = compose_pose(robot_pose, laser_pose)
    if readings is None:
        readings = classify_beams(scan, body=body, laser_pose=laser_pose)
    beams = np.flatnonzero(readings.hit)
    return _beam_points(scan, beams, readings.seen[beams], laser), beams
