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

"""Laser scans to convex obstacles in the map frame, and a memory of what was seen.

The MPC avoids convex polygons {p : A p <= b}; a scan is a fan of points. The steps:

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
   Every reader (the points, the memory's clearing, the planner's grid) asks it.
3. `scan_points`: the returns in the map frame, from the robot's pose at the scan's stamp
   and the laser's mounting pose in the robot frame.
4. Clusters: consecutive points (in beam order) farther apart than ``gap`` belong to
   different objects.
5. Convex pieces: a curved cluster that fits in ``small_size`` becomes its convex hull
   (thickened behind the surface, so a single point still has an interior); a straight one
   (within ``split_tolerance`` of its chord) or a larger one is split Douglas-Peucker style
   at its farthest point from the chord until every piece is within ``split_tolerance`` of
   its chord, and each piece becomes a thin rectangle along the chord, at least
   ``thickness`` wide, covering its points and reaching one beam spacing past its ends (the
   surface may continue up to the next beam, which missed it).
6. `ObstacleMemory`: the laser does not see behind the robot, so obstacles are remembered for
   ``ttl`` seconds; a later beam that passes through a remembered obstacle proves it gone, and
   one whose view covers it entirely replaces it by what it sees now.

The splitting, the rectangles and the memory's tests are vectorised over all pieces at once:
a BARN scan yields dozens of clusters, and a Python loop per point would cost milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import NamedTuple, Sequence

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.raycast import TrueGeometry

__all__ = [
    'BODY_MARGIN',
    'Beams',
    'MAX_BEAMS',
    'MAX_SCAN_FUTURE_S',
    'ObstacleMemory',
    'Scan',
    'ScanError',
    'ScanObstacleConfig',
    'check_beam_count',
    'check_scan_stamp',
    'classify_beams',
    'compose_pose',
    'cluster_bounds',
    'scan_points',
    'scan_to_obstacles',
    'validate_scan',
]

#: More beams than this is refused: no planar laser has them, and a corrupt message might.
MAX_BEAMS = 10_000
#: Seconds a scan's stamp may be ahead of the receiving node's clock (clock skew between
#: the laser's computer and this one); a scan further in the future is refused.
MAX_SCAN_FUTURE_S = 0.2
# Beams of slack when asking whether the current scan sees a remembered vertex.
_VIEW_SLACK = 2
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


@dataclass(frozen=True)
class ScanObstacleConfig:
    """How scans become obstacles.

    Attributes:
        gap: Consecutive points farther apart than this (metres) start a new cluster; below
            the robot's diameter, so that no passage is closed by joining two objects.
        split_tolerance: A piece is split until its points are within this of its chord
            (metres); it also bounds how far a rectangle's face may be from the surface.
        thickness: Smallest width of a piece (metres): every obstacle has an interior.
        small_size: Curved clusters whose bounding box diagonal is at most this become their
            hull (straight ones become a rectangle along their chord).

    """

    gap: float = 0.3
    split_tolerance: float = 0.08
    thickness: float = 0.04
    small_size: float = 0.3

    def __post_init__(self) -> None:
        for name in ('gap', 'split_tolerance', 'thickness', 'small_size'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                msg = f'{name} must be a finite number > 0, got {value!r}'
                raise ValueError(msg)


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


def _expand(first: np.ndarray, last: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the point indices of every range [first, last], their owner and range offsets."""
    count = last - first + 1
    offsets = np.cumsum(count) - count
    owner = np.repeat(np.arange(len(first)), count)
    index = np.repeat(first, count) + np.arange(int(count.sum())) - offsets[owner]
    return index, owner, offsets


def _chord_deviation(points: np.ndarray, first: np.ndarray, last: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return, for ranges of points, each point's distance from its range's chord.

    Returns:
        (point indices, their range, their distance from the chord, the largest per range).

    """
    index, owner, offsets = _expand(first, last)
    a, b = points[first], points[last]
    chord = b - a
    length = np.hypot(chord[:, 0], chord[:, 1])
    rel = points[index] - a[owner]
    cross = np.abs(chord[owner, 0] * rel[:, 1] - chord[owner, 1] * rel[:, 0])
    dev = np.where(length[owner] > 1e-12, cross / np.maximum(length[owner], 1e-12),
                   np.hypot(rel[:, 0], rel[:, 1]))
    return index, owner, dev, np.maximum.reduceat(dev, offsets)


def _split(points: np.ndarray, first: np.ndarray, last: np.ndarray,
           tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Split ranges Douglas-Peucker style until each is within tolerance of its chord.

    All ranges are split at once per round (at their farthest point), so the number of
    NumPy calls grows with the depth of the recursion, not with the number of pieces.
    """
    done_first, done_last = [first[:0]], [last[:0]]
    while len(first):
        index, owner, dev, worst = _chord_deviation(points, first, last)
        split = (worst > tolerance) & (last - first >= 2)
        done_first.append(first[~split])
        done_last.append(last[~split])
        if not np.any(split):
            break
        at_worst = np.flatnonzero((dev == worst[owner]) & split[owner])
        pieces, where = np.unique(owner[at_worst], return_index=True)
        cut = index[at_worst[where]]
        cut = np.clip(cut, first[pieces] + 1, last[pieces] - 1)
        first = np.concatenate([first[pieces], cut])
        last = np.concatenate([cut, last[pieces]])
    return np.concatenate(done_first), np.concatenate(done_last)


def _rectangles(points: np.ndarray, first: np.ndarray, last: np.ndarray,
                reach: np.ndarray, thickness: float) -> list[ConvexPolygon]:
    """Build, per range of points, the thin rectangle along its chord that covers them.

    The rectangle spans the points' projections on the chord, extended by reach at both ends,
    and their distances across it, widened to at least thickness.
    """
    if not len(first):
        return []
    index, owner, offsets = _expand(first, last)
    a = points[first]
    chord = points[last] - a
    length = np.hypot(chord[:, 0], chord[:, 1])
    u = chord / np.maximum(length, 1e-12)[:, None]
    u[length <= 1e-12] = (1.0, 0.0)
    n = np.column_stack([-u[:, 1], u[:, 0]])
    rel = points[index] - a[owner]
    along = np.einsum('ij,ij->i', rel, u[owner])
    across = np.einsum('ij,ij->i', rel, n[owner])
    lo = np.minimum.reduceat(along, offsets) - reach
    hi = np.maximum.reduceat(along, offsets) + reach
    half = 0.5 * thickness
    below = np.minimum(np.minimum.reduceat(across, offsets), -half)
    above = np.maximum(np.maximum.reduceat(across, offsets), half)
    corners = np.stack([
        a + lo[:, None] * u + below[:, None] * n,
        a + hi[:, None] * u + below[:, None] * n,
        a + hi[:, None] * u + above[:, None] * n,
        a + lo[:, None] * u + above[:, None] * n,
    ], axis=1)  # counter-clockwise: n is u turned left
    normals = np.stack([-n, u, n, -u], axis=1)
    offsets_b = np.einsum('kfj,kfj->kf', normals, corners)
    return [ConvexPolygon(A=normals[k], b=offsets_b[k], vertices=corners[k])
            for k in range(len(first))]


def _polygon_ccw(vertices: np.ndarray) -> ConvexPolygon:
    """Build a ConvexPolygon from strictly convex counter-clockwise vertices, without a hull.

    `ConvexPolygon.from_vertices` recomputes the hull in Python; the vertices here come from
    Qhull already in order, and the scan budget is a couple of milliseconds.
    """
    edges = np.roll(vertices, -1, axis=0) - vertices
    normals = np.column_stack([edges[:, 1], -edges[:, 0]])
    normals /= np.hypot(normals[:, 0], normals[:, 1])[:, None]
    return ConvexPolygon(A=normals, b=np.einsum('ij,ij->i', normals, vertices),
                         vertices=vertices)


def _hull(points: np.ndarray, origin: np.ndarray, thickness: float) -> ConvexPolygon:
    """Return the hull of points and their copies pushed thickness away from origin.

    The surface seen by the laser is the front of the object; pushing a copy back along each
    ray gives the piece an interior without moving its front towards the robot. A single
    point (or points on one ray) becomes a square of side thickness just behind it.
    """
    ray = points - origin
    ray /= np.maximum(np.hypot(ray[:, 0], ray[:, 1]), 1e-12)[:, None]
    cloud = np.vstack([points, points + thickness * ray])
    if len(points) >= 2:
        try:
            hull = ConvexHull(cloud)
        except QhullError:
            pass
        else:
            return _polygon_ccw(cloud[hull.vertices])
    centre = points.mean(axis=0) + 0.5 * thickness * ray[0]
    h = 0.5 * thickness
    square = centre + np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
    return _polygon_ccw(square)


def scan_to_obstacles(scan: Scan, robot_pose: Sequence[float], *,
                      laser_pose: Sequence[float] = (0.0, 0.0, 0.0),
                      body: Footprint | None = None,
                      config: ScanObstacleConfig | None = None,
                      validate: bool = True) -> list[ConvexPolygon]:
    """Turn one scan into convex obstacles in the map frame.

    Args:
        scan: The scan.
        robot_pose: (x, y, yaw) of the robot in the map frame at the scan's stamp.
        laser_pose: (x, y, yaw) of the laser in the robot frame.
        body: The robot's footprint: returns inside it are the robot, not obstacles (see
            `classify_beams`); None: every return counts.
        config: Clustering and splitting options (defaults if None).
        validate: Check the scan first (skip only for scans known to be valid).

    Returns:
        Convex polygons covering every valid return: hulls of small clusters, then thin
        rectangles along the straight pieces of larger ones.

    Raises:
        ScanError: If the scan or a pose is malformed.

    """
    if validate:
        validate_scan(scan)
    return _pieces(scan, robot_pose, laser_pose,
                   classify_beams(scan, body=body, laser_pose=laser_pose),
                   config or ScanObstacleConfig())[0]


def _pieces(scan: Scan, robot_pose: Sequence[float], laser_pose: Sequence[float],
            readings: Beams,
            config: ScanObstacleConfig) -> tuple[list[ConvexPolygon], np.ndarray]:
    """Return the obstacles of a valid scan and, per obstacle, three returns it was built from.

    The returns (first, middle, last) lie on surfaces the laser saw; the memory asks whether
    a later scan sees them again.
    """
    points, _ = scan_points(scan, robot_pose, laser_pose=laser_pose, readings=readings)
    if not len(points):
        return [], np.zeros((0, 3, 2))
    origin = compose_pose(robot_pose, laser_pose)[:2]
    first, last = cluster_bounds(points, config.gap)
    index, owner, offsets = _expand(first, last)
    span = (np.maximum.reduceat(points[index], offsets) -
            np.minimum.reduceat(points[index], offsets))
    small = np.hypot(span[:, 0], span[:, 1]) <= config.small_size
    # A small but straight cluster (a face, maybe seen at a grazing angle) is a thin
    # rectangle along its chord like a long one: its hull pushed back along the rays would be
    # a sliver with needle corners, which grow into long spikes when inflated.
    small &= _chord_deviation(points, first, last)[3] > config.split_tolerance
    obstacles = [_hull(points[first[k]:last[k] + 1], origin, config.thickness)
                 for k in np.flatnonzero(small)]
    piece_first, piece_last = _split(points, first[~small], last[~small],
                                     config.split_tolerance)
    # One beam spacing past each end (the surface may go on up to the next beam, which
    # missed it), at the farther end's range; never more than half the clustering gap.
    ranges = np.hypot(*(points - origin).T)
    spacing = abs(scan.angle_increment) * np.maximum(ranges[piece_first], ranges[piece_last])
    reach = np.minimum(spacing, 0.5 * config.gap)
    obstacles += _rectangles(points, piece_first, piece_last, reach, config.thickness)
    starts = np.concatenate([first[small], piece_first])
    ends = np.concatenate([last[small], piece_last])
    anchors = np.stack([points[starts], points[(starts + ends) // 2], points[ends]], axis=1)
    return obstacles, anchors


class _Entry(NamedTuple):
    """A remembered obstacle, when it was seen, and three returns it was built from."""

    polygon: ConvexPolygon
    seen: float
    anchors: np.ndarray


class ObstacleMemory:
    """Remember obstacles seen by the laser, forget them after ttl or when proven gone.

    Each `update` adds the current scan's obstacles and then reviews what was remembered:

    - older than ``ttl`` seconds: forgotten;
    - crossed by a current beam short of its return (minus ``clear_margin``): the beam proves
      free space along its ray, so the obstacle is gone (or moved) and is forgotten;
    - seen again (the returns it was built from, its first, middle and last, are all inside
      the field of view, within range and not behind the surface the beams now return
      from): the current scan sees that surface, so what it sees now replaces the old piece
      (otherwise each scan would add a copy);
    - anything else (behind the robot, occluded, out of range) is kept.

    Args:
        ttl: Time to live of an obstacle, seconds (the ``obstacle_memory`` parameter).
        clear_margin: A beam clears only up to this short of its return (metres), so that the
            surface it hit (and the thin pieces built on it) is not cleared by it.
        config: How scans become obstacles.

    Raises:
        ValueError: If ttl or clear_margin is not finite and > 0 (>= 0 for the margin).

    """

    def __init__(self, ttl: float, *, clear_margin: float = 0.15,
                 config: ScanObstacleConfig | None = None) -> None:
        if not (math.isfinite(ttl) and ttl > 0.0):
            msg = f'obstacle memory ttl must be > 0 seconds, got {ttl!r}'
            raise ValueError(msg)
        if not (math.isfinite(clear_margin) and clear_margin >= 0.0):
            msg = f'clear_margin must be >= 0, got {clear_margin!r}'
            raise ValueError(msg)
        self.ttl = float(ttl)
        self.clear_margin = float(clear_margin)
        self.config = config or ScanObstacleConfig()
        self._entries: list[_Entry] = []
        self._stamp = -math.inf

    def __len__(self) -> int:
        return len(self._entries)

    def clear(self) -> None:
        """Forget everything (e.g. when the map frame jumps)."""
        self._entries = []
        self._stamp = -math.inf

    def update(self, scan: Scan, robot_pose: Sequence[float], *,
               laser_pose: Sequence[float] = (0.0, 0.0, 0.0),
               body: Footprint | None = None) -> list[ConvexPolygon]:
        """Add a scan's obstacles, forget what it proves gone or sees anew, and expire.

        Args:
            scan: The scan (validated here).
            robot_pose: (x, y, yaw) of the robot in the map frame at the scan's stamp.
            laser_pose: (x, y, yaw) of the laser in the robot frame.
            body: The robot's footprint: returns inside it are the robot, neither obstacles
                nor a view of one (see `classify_beams`); None: every return counts.

        Returns:
            The obstacles built from this scan alone.

        Raises:
            ScanError: If the scan or a pose is malformed, or the scan is older than the last.

        """
        validate_scan(scan)
        if scan.stamp < self._stamp:
            msg = f'scan stamp {scan.stamp} is older than the last one ({self._stamp})'
            raise ScanError(msg)
        self._stamp = float(scan.stamp)
        readings = classify_beams(scan, body=body, laser_pose=laser_pose)
        current, anchors = _pieces(scan, robot_pose, laser_pose, readings, self.config)
        kept = [e for e in self._entries if scan.stamp - e.seen <= self.ttl]
        if kept:
            drop = self._superseded(kept, scan, readings,
                                    compose_pose(robot_pose, laser_pose))
            kept = [e for e, gone in zip(kept, drop, strict=True) if not gone]
        self._entries = kept + [_Entry(p, float(scan.stamp), a)
                                for p, a in zip(current, anchors, strict=True)]
        return current

    def _superseded(self, entries: list[_Entry], scan: Scan, readings: Beams,
                    laser: np.ndarray) -> np.ndarray:
        """Say, per remembered obstacle, whether the scan's beams cross it or see it again."""
        polygons = [e.polygon for e in entries]
        beams = len(readings.free)
        # Free space along each beam: up to its return, or up to range_max if none.
        free = readings.free - self.clear_margin
        geometry = TrueGeometry(polygons)
        angle0 = laser[2] + scan.angle_min
        beam, owner, t = geometry.cast_pairs(laser[:2], angle0, scan.angle_increment, beams,
                                             scan.range_max)
        crossed = np.zeros(len(polygons), dtype=bool)
        crossed[owner[t < free[beam]]] = True
        # Seen again: its returns in view and not behind the surface now returned.
        vertices = np.concatenate([e.anchors for e in entries])
        rel = vertices - laser[:2]
        dist = np.hypot(rel[:, 0], rel[:, 1])
        half_span = 0.5 * scan.angle_increment * (beams - 1)
        bearing = np.arctan2(rel[:, 1], rel[:, 0]) - (angle0 + half_span)
        bearing = (bearing + math.pi) % (2.0 * math.pi) - math.pi  # about the middle beam
        k = np.rint((bearing + half_span) / scan.angle_increment).astype(np.int64)
        # A return counts as seen if a beam within _VIEW_SLACK of its bearing sees as far
        # (the robot moved a little since, and an edge return sits next to a miss).
        in_fov = (k >= -_VIEW_SLACK) & (k < beams + _VIEW_SLACK)
        k = np.clip(k, 0, beams - 1)
        # an ignored beam observed nothing: it sees no return again (nor does it hide one)
        surface = np.where(readings.usable, readings.seen, -math.inf)
        padded = np.pad(surface, _VIEW_SLACK, mode='edge')
        reach = np.max(np.lib.stride_tricks.sliding_window_view(padded, 2 * _VIEW_SLACK + 1),
                       axis=1)[k]
        visible = in_fov & (dist <= scan.range_max) & (dist <= reach + self.clear_margin)
        owner_v = np.repeat(np.arange(len(polygons)), [len(e.anchors) for e in entries])
        hidden = np.bincount(owner_v, weights=~visible, minlength=len(polygons))
        return crossed | (hidden == 0)

    def obstacles(self, centre: Sequence[float] | None = None,
                  radius: float = math.inf) -> list[ConvexPolygon]:
        """Return the remembered obstacles that come within radius of centre.

        Args:
            centre: (x, y) of the robot; None returns everything.
            radius: Distance of interest (the MPC's reach), metres.

        Returns:
            The polygons, most recently seen last.

        """
        if centre is None or not math.isfinite(radius):
            return [e.polygon for e in self._entries]
        c = np.asarray(centre, dtype=float)[:2]
        return [e.polygon for e in self._entries
                if float(e.polygon.distance(c)[0]) <= radius]
