# SPDX-License-Identifier: Apache-2.0
"""Laser scans to convex obstacles in the map frame, and a memory of what was seen.

The MPC avoids convex polygons {p : A p <= b}; a scan is a fan of points. The steps, after
perception/scans.py has validated the scan, classified its beams (REP 117) and placed its
returns in the map frame:

1. Clusters: consecutive points (in beam order) farther apart than ``gap`` belong to
   different objects.
2. Convex pieces: a curved cluster that fits in ``small_size`` becomes its convex hull
   (thickened behind the surface, so a single point still has an interior); a straight one
   (within ``split_tolerance`` of its chord) or a larger one is split Douglas-Peucker style
   at its farthest point from the chord until every piece is within ``split_tolerance`` of
   its chord, and each piece becomes a thin rectangle along the chord, at least
   ``thickness`` wide, covering its points and reaching one beam spacing past its ends (the
   surface may continue up to the next beam, which missed it).
3. `ObstacleMemory`: the laser does not see behind the robot, so obstacles are remembered for
   ``ttl`` seconds; a later beam that passes through a remembered obstacle proves it gone, and
   one whose view covers it entirely replaces it by what it sees now.

The splitting, the rectangles and the memory's tests are vectorised over all pieces at once:
a BARN scan yields dozens of clusters, and a Python loop per point would cost milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import NamedTuple, Sequence, TYPE_CHECKING

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.perception.scans import (
    Beams,
    classify_beams,
    cluster_bounds,
    CLUSTER_GAP,
    compose_pose,
    Scan,
    scan_points,
    ScanError,
    validate_scan,
)

if TYPE_CHECKING:
    from mpc_local_planner.perception.tracking import ScanTracker, Track, TrackLabels

__all__ = [
    'ObstacleMemory',
    'ScanObstacleConfig',
    'cluster_bounds',
    'scan_to_obstacles',
]

# Beams of slack when asking whether the current scan sees a remembered vertex.
_VIEW_SLACK = 2


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

    gap: float = CLUSTER_GAP
    split_tolerance: float = 0.08
    thickness: float = 0.04
    small_size: float = 0.3

    def __post_init__(self) -> None:
        for name in ('gap', 'split_tolerance', 'thickness', 'small_size'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                msg = f'{name} must be a finite number > 0, got {value!r}'
                raise ValueError(msg)



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
    readings = classify_beams(scan, body=body, laser_pose=laser_pose)
    points, _ = scan_points(scan, robot_pose, laser_pose=laser_pose, readings=readings)
    return _pieces(scan, points, compose_pose(robot_pose, laser_pose)[:2],
                   config or ScanObstacleConfig())[0]


def _pieces(scan: Scan, points: np.ndarray, origin: np.ndarray,
            config: ScanObstacleConfig) -> tuple[list[ConvexPolygon], np.ndarray, np.ndarray]:
    """Return a valid scan's obstacles, their anchor returns and their first returns.

    points are the scan's returns in the map frame (`scan_points`), origin the laser's
    position. Per obstacle: three returns it was built from, and the index of its first
    return in points (for the memory's track labels). The three returns (first, middle,
    last) lie on surfaces the laser saw; the memory asks whether a later scan sees them again.
    """
    if not len(points):
        return [], np.zeros((0, 3, 2)), np.zeros(0, dtype=np.int64)
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
    return obstacles, anchors, starts


class _Entry(NamedTuple):
    """A remembered obstacle: when seen, three returns it was built from, and its track.

    track: the id of the track its returns belonged to (perception/tracking.py), -1 for none.
    """

    polygon: ConvexPolygon
    seen: float
    anchors: np.ndarray
    track: int = -1


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
    - anything else (behind the robot, occluded, out of range) is kept;
    - built from returns of a track that now moves (`update`'s ``tracks``,
      perception/tracking.py): forgotten, those of this scan included at the next one.
      What moves is where the newest scan sees it, not where it was: a walker leaves no
      trail of remembered pieces behind it, not even of the scans before it was told moving.

    Args:
        ttl: Time to live of an obstacle, seconds (the ``obstacle_memory`` parameter).
        clear_margin: A beam clears only up to this short of its return (metres), so that the
            surface it hit (and the thin pieces built on it) is not cleared by it.
        config: How scans become obstacles.
        tracker: Follows the scans' small clusters and tells moving ones
            (perception/tracking.py `ScanTracker`); what a moving track built is forgotten
            at the next scan. None: the world is taken as static (every piece is kept).

    Raises:
        ValueError: If ttl or clear_margin is not finite and > 0 (>= 0 for the margin).

    """

    def __init__(self, ttl: float, *, clear_margin: float = 0.15,
                 config: ScanObstacleConfig | None = None,
                 tracker: ScanTracker | None = None) -> None:
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
        # the ids of the tracks told moving at the last scan
        self._moving: frozenset[int] = frozenset()
        self._stamp = -math.inf
        self._last_usable = False
        self.tracker = tracker

    def __len__(self) -> int:
        return len(self._entries)

    @property
    def stamp(self) -> float:
        """The stamp of the newest scan taken (-inf before the first, or after clear())."""
        return self._stamp

    @property
    def last_scan_usable(self) -> bool:
        """The last scan taken had a beam that is not ignored (`classify_beams`' usable).

        The node's scan freshness asks this of every scan; the memory classified its beams
        already, so they are not classified twice.
        """
        return self._last_usable

    @property
    def tracks(self) -> list[Track] | None:
        """The tracker's live tracks (None: the memory does not track)."""
        return self.tracker.tracker.tracks if self.tracker is not None else None

    @property
    def moving_tracks(self) -> list[Track]:
        """The tracks told moving at the last scan (none: the memory does not track)."""
        if self.tracker is None:
            return []
        return [t for t in self.tracker.tracker.tracks if t.id in self._moving]

    @property
    def suspect_tracks(self) -> list[Track]:
        """The tracks not told moving at the last scan that may be (`Track.suspect`).

        Their pieces stay in the memory: until the tracker knows, a user plans for both.
        """
        if self.tracker is None:
            return []
        return [t for t in self.tracker.tracker.tracks
                if t.suspect and t.id not in self._moving]

    def clear(self) -> None:
        """Forget everything (e.g. when the map frame jumps)."""
        self._entries = []
        self._moving = frozenset()
        self._stamp = -math.inf
        self._last_usable = False
        if self.tracker is not None:
            self.tracker.clear()

    def update(self, scan: Scan, robot_pose: Sequence[float], *,
               laser_pose: Sequence[float] = (0.0, 0.0, 0.0),
               body: Footprint | None = None,
               tracks: TrackLabels | None = None) -> list[ConvexPolygon]:
        """Add a scan's obstacles, forget what it proves gone or sees anew, and expire.

        Args:
            scan: The scan (validated here).
            robot_pose: (x, y, yaw) of the robot in the map frame at the scan's stamp.
            laser_pose: (x, y, yaw) of the laser in the robot frame.
            body: The robot's footprint: returns inside it are the robot, neither obstacles
                nor a view of one (see `classify_beams`); None: every return counts.
            tracks: The scan's returns labelled with their tracks (`scan_points`' order, with
                the same body and laser pose) and the ids of the moving tracks
                (`ScanTracker.labels`): what was built from a moving track is forgotten.
                None: the memory's own tracker labels them, if it has one (else nothing
                moves).

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
        self._last_usable = bool(readings.usable.any())
        points, _ = scan_points(scan, robot_pose, laser_pose=laser_pose, readings=readings)
        laser = compose_pose(robot_pose, laser_pose)
        if tracks is None and self.tracker is not None:
            self.tracker.update(scan, robot_pose, laser_pose=laser_pose, body=body,
                                readings=readings, points=points)
            tracks = self.tracker.labels
        current, anchors, starts = _pieces(scan, points, laser[:2], self.config)
        owners = np.full(len(current), -1, dtype=np.int64)
        moving: frozenset[int] = frozenset()
        if tracks is not None:
            labels = np.asarray(tracks.per_return)
            if labels.shape != (len(points),):
                msg = f'tracks label {labels.shape} returns, the scan has {len(points)}'
                raise ScanError(msg)
            owners = labels[starts] if len(current) else owners
            moving = tracks.moving
        self._moving = moving
        kept = [e for e in self._entries
                if e.track not in moving and scan.stamp - e.seen <= self.ttl]
        if kept:
            drop = self._superseded(kept, scan, readings, laser)
            kept = [e for e, gone in zip(kept, drop, strict=True) if not gone]
        self._entries = kept + [_Entry(p, float(scan.stamp), a, int(o))
                                for p, a, o in zip(current, anchors, owners, strict=True)]
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
                  radius: float = math.inf, *, static: bool = False) -> list[ConvexPolygon]:
        """Return the remembered obstacles that come within radius of centre.

        Args:
            centre: (x, y) of the robot; None returns everything.
            radius: Distance of interest (the MPC's reach), metres.
            static: Leave out the pieces the last scan built of a moving track (those of
                the scans before are forgotten already): what moves is handed over as its
                track instead (`moving_tracks`).

        Returns:
            The polygons, most recently seen last.

        """
        entries = ([e for e in self._entries if e.track not in self._moving] if static
                   else self._entries)
        if centre is None or not math.isfinite(radius):
            return [e.polygon for e in entries]
        c = np.asarray(centre, dtype=float)[:2]
        return [e.polygon for e in entries
                if float(e.polygon.distance(c)[0]) <= radius]
