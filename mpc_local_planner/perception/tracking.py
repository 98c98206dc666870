# SPDX-License-Identifier: Apache-2.0
"""Scans to tracks: small clusters followed over time, moving ones told from static ones.

The obstacle memory assumes a static world; a person walking through the scans is not. This
module follows the laser's small clusters (legs, people, carts, cylinders: anything no wider
than ``max_size``; walls and long runs are structure and never tracked) from scan to scan:

1. **Clusters.** A scan's returns in the map frame, split where neighbours are farther apart
   than the memory's clustering gap (`cluster_bounds`, as the memory clusters them); each
   cluster is measured by the centre of its returns.
2. **Association.** Each track predicts where it is at the scan's stamp; clusters and tracks
   are matched by the assignment that minimises the total distance (the Hungarian method,
   `scipy.optimize.linear_sum_assignment`), pairs farther apart than ``gate`` refused. A
   cluster nobody claims starts a track; a track not matched for ``lost_after`` seconds ends.
   Two walkers that cross merge into one cluster for a while: one track takes it, the other
   coasts on its prediction and is matched again when they part, so both keep their ids. A
   track whose cluster grew by a merge (MERGE_GROWTH) is not corrected with its centre: it
   coasts too, so a walker passing a cylinder keeps its velocity.
3. **A constant-velocity Kalman filter per track** (state x, y, vx, vy; white-noise
   acceleration; the measurement is the cluster's centre). It gives the position, the
   velocity and their covariance.
4. **Static or moving.** Speed alone does not tell them apart: the centre of a static
   cylinder's returns drifts as the robot drives by (the laser sees another part of its
   arc), and a cluster of BARN cylinders changes as they hide one another, so its centre
   jumps. What a static object never does is stand where the laser saw free space. So a
   cluster is *in free space* when at least ``free_share`` of its returns (and
   ``free_points`` of them) lie more than ``free_margin`` short of what the beams of a scan
   ``reference_age`` earlier saw in their direction (the nearest of three neighbouring
   beams, so that a beam grazing a silhouette's edge proves nothing) and more than
   ``free_margin`` from every return of that scan (`ScanTracker`). A track is
   moving once it has been matched ``confirm`` times, its clusters stood in free space
   ``evidence_needed`` times within the last ``evidence_age`` seconds, and its filtered speed
   exceeds ``moving_speed`` (by more than ``sigmas`` standard deviations, if set); it stays
   moving until its speed falls below half of that. A test drives past BARN cylinders at
   2 m/s with the `real` preset's laser and none is told moving.
5. **Suspects.** Until then a walker is unknown, and a walker that steps out from behind
   something near the robot is close by the time it is told moving. A track matched twice,
   faster than ``moving_speed``, whose clusters stood in free space once is a *suspect*
   (`Track.suspect`): the MPC predicts it as a mover while the memory keeps its pieces as
   static, so what the robot plans holds whichever it turns out to be. Driving past all
   200 BARN worlds at 2 m/s (ideal, real and harsh lasers), 65 of 23,085 scans had a
   static suspect, none with the ideal laser (docs/results.md, "Suspects").

The filter is written out (4 states, a few lines of numpy): the libraries that package one
(filterpy, pykalman) are unmaintained, and the matrices here are the textbook's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import NamedTuple, Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.moving_obstacles import MovingPolygon
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.scans import (
    Beams,
    classify_beams,
    cluster_bounds,
    CLUSTER_GAP,
    compose_pose,
    Scan,
    scan_points,
)

__all__ = [
    'COVER_FACTOR',
    'GROWTH_SIGMAS',
    'PREDICTION_SIGMAS',
    'WALKER_BERTH',
    'ScanTracker',
    'Track',
    'TrackLabels',
    'Tracker',
    'TrackerConfig',
    'moving_polygon',
]

# A cluster's returns see one side of an object: for a cylinder of radius R seen from
# outside, about half its arc, whose centre lies 2R/pi in front of the cylinder's and whose
# farthest return lies 1.19 R from it; so a disc of 1.4 times the cluster's radius about the
# returns' centre holds the cylinder (1.64 R). A walker's legs are two such clusters in one.
COVER_FACTOR = 1.4
# Standard deviations of a moving track's position that the MPC keeps out of now, and of its
# velocity by which the predicted disc grows per second over the horizon (docs/results.md,
# "Moving obstacles": 2 of the velocity's left the MPC boxed in among the dynamic suite's
# cylinders, whose speeds the filter knows to about 0.24 m/s).
PREDICTION_SIGMAS = 2.0
GROWTH_SIGMAS = 1.0
# The berth (m) the MPC keeps from a moving track beyond the disc that holds it: a walker
# first told moving close by, or one that turns, is not where its prediction says, and a plan
# that passes it by the least clearance leaves the robot no room to get out of its way.
WALKER_BERTH = 0.15


# A cluster this much larger than its track's last (times, plus metres) is the object merged
# with a neighbour (a walker passing a cylinder, two walkers crossing): the centre of the
# merged returns lies between the two, and correcting the track with it gives the walker a
# velocity it does not have (seen through the nodes: a walker beside a cylinder predicted
# walking away from the robot, into which it walked). Such a track coasts instead.
# (The track's size counts as at least MERGE_FLOOR: a cylinder first seen as a sliver grows
# as more of it comes into view.)
MERGE_GROWTH = 1.5
MERGE_SLACK = 0.1
MERGE_FLOOR = 0.2


@dataclass(frozen=True)
class TrackerConfig:
    """How clusters become tracks.

    Attributes:
        gate: A cluster farther than this from a track's prediction is not that track (m).
        max_size: Clusters wider than this (their returns' extent, m) are structure.
        moving_speed: A track faster than this (m/s, filtered) may be moving.
        sigmas: ... by more than this many standard deviations of its speed.
        confirm: Matches before a track may be called moving (3: a velocity from three
            centres; the free-space evidence, not this count, keeps static objects
            static, and a fourth match cost a walker first seen near the robot 0.2 s
            at 5 scans a second: docs/results.md, "Moving obstacles").
        lost_after: A track not matched for this long ends (s).
        acceleration: White-noise acceleration of the motion model (m/s^2, its standard
            deviation over one second).
        measurement: Standard deviation of a cluster centre's position (m).
        initial_speed: Standard deviation of a new track's velocity (m/s).
        evidence_age: A track is moving only if its clusters stood in free space
            evidence_needed times this recently (s).
        evidence_needed: ... that many times (one noisy return can make one).
        reference_age: The scan whose free space a cluster is checked against is the
            newest at least this old (s): a walker at 0.2 m/s moves 10 cm in 0.5 s.
        free_margin: A return counts as in free space this far short of what the
            reference beams saw (m): more than the laser's noise.
        free_share: The share of a cluster's returns in free space that makes it so.
        free_points: ... and at least this many of them.

    """

    gate: float = 0.8
    max_size: float = 1.2
    moving_speed: float = 0.15
    sigmas: float = 0.0
    confirm: int = 3
    lost_after: float = 1.0
    acceleration: float = 0.5
    measurement: float = 0.05
    initial_speed: float = 1.5
    evidence_age: float = 1.0
    evidence_needed: int = 2
    reference_age: float = 0.5
    free_margin: float = 0.05
    free_share: float = 0.3
    free_points: int = 3

    def __post_init__(self) -> None:
        for name in ('gate', 'max_size', 'moving_speed', 'lost_after', 'acceleration',
                     'measurement', 'initial_speed', 'evidence_age', 'reference_age',
                     'free_margin', 'free_share'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                msg = f'TrackerConfig.{name} must be finite and > 0, got {value!r}'
                raise ValueError(msg)
        if not (math.isfinite(self.sigmas) and self.sigmas >= 0.0):
            msg = f'TrackerConfig.sigmas must be finite and >= 0, got {self.sigmas!r}'
            raise ValueError(msg)
        for name in ('confirm', 'free_points', 'evidence_needed'):
            if getattr(self, name) < 1:
                msg = f'TrackerConfig.{name} must be >= 1, got {getattr(self, name)!r}'
                raise ValueError(msg)


@dataclass
class Track:
    """One object followed over time.

    Attributes:
        id: Its number, unique in the tracker's life.
        state: (4,) x, y, vx, vy at `stamp`.
        covariance: (4, 4) the state's covariance.
        stamp: When the state holds (the last scan's stamp).
        seen: When it was last matched.
        hits: How many clusters it has been matched to.
        size: The radius of its last cluster about its centre (m).
        moving: Whether it is told moving (see the module docstring).
        suspect: Not told moving yet, but matched at least twice (a velocity), faster than
            moving_speed, and seen in free space at least once: what a walker is until
            the tracker is sure, and a static object almost never (one noisy return can
            stand in free space). Users predict it as moving and keep it as static too.
        evidence: When its clusters stood in free space, the last evidence_age seconds.

    """

    id: int
    state: np.ndarray
    covariance: np.ndarray
    stamp: float
    seen: float
    hits: int = 1
    size: float = 0.0
    moving: bool = False
    suspect: bool = False
    evidence: list[float] = field(default_factory=list)

    @property
    def position(self) -> np.ndarray:
        """(2,) where it is at `stamp`."""
        return self.state[:2].copy()

    @property
    def velocity(self) -> np.ndarray:
        """(2,) its velocity, m/s."""
        return self.state[2:].copy()

    def speed_sigma(self) -> float:
        """Return the standard deviation of its speed along its velocity (m/s)."""
        v = self.state[2:]
        speed = float(np.hypot(*v))
        cov = self.covariance[2:, 2:]
        if speed < 1e-9:
            return float(math.sqrt(max(np.trace(cov) / 2.0, 0.0)))
        u = v / speed
        return float(math.sqrt(max(float(u @ cov @ u), 0.0)))

    def predicted(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Return the position at time t (constant velocity) and its 2x2 covariance."""
        dt = t - self.stamp
        transition = _transition(dt)
        return ((transition @ self.state)[:2],
                (transition @ self.covariance @ transition.T)[:2, :2])


def moving_polygon(track: Track, now: float, *, sigmas: float | None = None,
                   growth_sigmas: float | None = None, sides: int = 8) -> MovingPolygon:
    """Return a track as the MPC predicts it: a polygon where it is at now, and its motion.

    The polygon is circumscribed about the disc of COVER_FACTOR times the cluster's radius
    plus sigmas (PREDICTION_SIGMAS) standard deviations of the position at now (the larger
    axis of its covariance) plus WALKER_BERTH; it moves at the track's velocity, and the
    prediction's uncertainty grows at growth_sigmas (GROWTH_SIGMAS) standard deviations of the
    velocity per second (core/moving_obstacles.py).
    """
    sigmas = PREDICTION_SIGMAS if sigmas is None else sigmas
    growth_sigmas = GROWTH_SIGMAS if growth_sigmas is None else growth_sigmas
    centre, covariance = track.predicted(now)
    position_sigma = math.sqrt(max(float(np.max(np.linalg.eigvalsh(covariance))), 0.0))
    velocity_sigma = math.sqrt(max(float(np.max(np.linalg.eigvalsh(
        track.covariance[2:, 2:]))), 0.0))
    radius = COVER_FACTOR * track.size + sigmas * position_sigma + WALKER_BERTH
    disc = ConvexPolygon.from_circle(float(centre[0]), float(centre[1]),
                                     max(radius, MIN_RADIUS), sides=sides)
    return MovingPolygon.moving(disc, track.velocity, growth_sigmas * velocity_sigma)


# The smallest disc a track is predicted as (m): a cluster of one return has no radius.
MIN_RADIUS = 0.05


def _transition(dt: float) -> np.ndarray:
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt
    return f


def _process_noise(dt: float, acceleration: float) -> np.ndarray:
    """The white-noise-acceleration model's covariance over dt, per axis."""
    q = acceleration ** 2
    block = q * np.array([[dt ** 3 / 3.0, dt ** 2 / 2.0], [dt ** 2 / 2.0, dt]])
    noise = np.zeros((4, 4))
    for axis in range(2):
        index = [axis, axis + 2]
        noise[np.ix_(index, index)] = block
    return noise


class Tracker:
    """Follow small clusters from scan to scan; tell moving tracks from static ones.

    Args:
        config: The tracking settings.

    """

    def __init__(self, config: TrackerConfig | None = None) -> None:
        self.config = config or TrackerConfig()
        self._tracks: list[Track] = []
        self._next_id = 0
        self._stamp = -math.inf
        # per cluster of the last update: the id of the track it went to (None: too large)
        self.matches: list[int | None] = []

    @property
    def tracks(self) -> list[Track]:
        """Every live track."""
        return list(self._tracks)

    def clear(self) -> None:
        """Forget every track (e.g. when the map frame jumps); ids go on counting."""
        self._tracks = []
        self._stamp = -math.inf

    def update(self, clusters: Sequence[np.ndarray], stamp: float, *,
               in_free_space: Sequence[bool] | None = None) -> list[Track]:
        """Take one scan's clusters (map frame) at stamp; return the live tracks.

        in_free_space: per cluster, whether it stands where a scan saw free space
            (`ScanTracker` says); None: none does, and no track can be told moving.
        Afterwards `matches` holds, per cluster, the id of its track (None: too large).

        Raises:
            ValueError: for a stamp older than the last one, or a non-finite point.

        """
        if not math.isfinite(stamp) or stamp < self._stamp:
            msg = (f'tracker stamp {stamp!r} is not finite or older than the last one '
                   f'({self._stamp})')
            raise ValueError(msg)
        flags = list(in_free_space) if in_free_space is not None else [False] * len(clusters)
        if len(flags) != len(clusters):
            msg = f'{len(flags)} free-space flags for {len(clusters)} clusters'
            raise ValueError(msg)
        config = self.config
        # the clusters small enough to track: their index, centre, size and evidence
        index, centres, sizes, free = [], [], [], []
        for k, (cluster, flag) in enumerate(zip(clusters, flags, strict=True)):
            points = np.asarray(cluster, dtype=float).reshape(-1, 2)
            if not np.all(np.isfinite(points)):
                msg = 'a cluster has a non-finite point'
                raise ValueError(msg)
            if not len(points) or float(np.hypot(*np.ptp(points, axis=0))) > config.max_size:
                continue
            centre = points.mean(axis=0)
            index.append(k)
            centres.append(centre)
            sizes.append(float(np.max(np.hypot(*(points - centre).T))))
            free.append(bool(flag))
        self._stamp = float(stamp)
        for track in self._tracks:
            self._predict(track, stamp)
        owner: dict[int, Track] = {}
        matched: set[int] = set()
        if self._tracks and centres:
            predicted = np.array([t.state[:2] for t in self._tracks])
            offsets = predicted[:, None, :] - np.array(centres)[None, :, :]
            cost = np.hypot(offsets[..., 0], offsets[..., 1])
            rows, cols = linear_sum_assignment(cost)
            for row, col in zip(rows, cols, strict=True):
                if cost[row, col] <= config.gate:
                    track = self._tracks[row]
                    if sizes[col] > MERGE_GROWTH * max(track.size, MERGE_FLOOR) + MERGE_SLACK:
                        # merged with a neighbour: its centre moved by the merge, not by the
                        # object. The track coasts on its prediction, unseen (a merge that
                        # lasts lost_after ends it), and the cluster is not its: it starts
                        # a track of its own, not moving, so the memory keeps its pieces
                        continue
                    self._correct(track, centres[col], sizes[col], stamp, free[col])
                    owner[int(col)] = track
                    matched.add(int(row))
        self._tracks = [t for i, t in enumerate(self._tracks)
                        if i in matched or stamp - t.seen <= config.lost_after]
        for col, centre in enumerate(centres):
            if col not in owner:
                owner[col] = self._new_track(centre, sizes[col], stamp, free[col])
                self._tracks.append(owner[col])
        self.matches = [None] * len(clusters)
        for col, k in enumerate(index):
            self.matches[k] = owner[col].id
        return self.tracks

    def _new_track(self, centre: np.ndarray, size: float, stamp: float, free: bool) -> Track:
        covariance = np.diag([self.config.measurement ** 2] * 2
                             + [self.config.initial_speed ** 2] * 2)
        track = Track(self._next_id, np.array([centre[0], centre[1], 0.0, 0.0]), covariance,
                      stamp, stamp, size=size, evidence=[stamp] if free else [])
        self._next_id += 1
        return track

    def _predict(self, track: Track, stamp: float) -> None:
        dt = stamp - track.stamp
        if dt <= 0.0:
            return
        transition = _transition(dt)
        track.state = transition @ track.state
        track.covariance = (transition @ track.covariance @ transition.T
                            + _process_noise(dt, self.config.acceleration))
        track.stamp = stamp

    def _correct(self, track: Track, centre: np.ndarray, size: float, stamp: float,
                 free: bool) -> None:
        observe = np.zeros((2, 4))
        observe[0, 0] = observe[1, 1] = 1.0
        innovation = centre - observe @ track.state
        covariance = observe @ track.covariance @ observe.T \
            + np.eye(2) * self.config.measurement ** 2
        gain = track.covariance @ observe.T @ np.linalg.inv(covariance)
        track.state = track.state + gain @ innovation
        track.covariance = (np.eye(4) - gain @ observe) @ track.covariance
        track.seen = stamp
        track.hits += 1
        track.size = size
        config = self.config
        track.evidence = [t for t in track.evidence if stamp - t <= config.evidence_age]
        if free:
            track.evidence.append(stamp)
        speed = float(np.hypot(*track.state[2:]))
        if track.moving:
            track.moving = speed >= 0.5 * config.moving_speed
        else:
            track.moving = (track.hits >= config.confirm
                            and len(track.evidence) >= config.evidence_needed
                            and speed - config.sigmas * track.speed_sigma()
                            > config.moving_speed)
        track.suspect = (not track.moving and track.hits >= 2 and bool(track.evidence)
                         and speed > config.moving_speed)


class TrackLabels(NamedTuple):
    """A scan's returns labelled with their tracks, and which tracks move.

    Attributes:
        per_return: (N,) per return (`scan_points`' order) the id of its track, -1 for none
            (a cluster too large to track).
        moving: The ids of the tracks told moving at this scan.

    """

    per_return: np.ndarray
    moving: frozenset[int]


class _Reference:
    """A kept scan: its stamp, its beams' free space, the laser's pose, and its returns."""

    def __init__(self, stamp: float, free: np.ndarray, laser: np.ndarray, scan: Scan,
                 points: np.ndarray) -> None:
        self.stamp = stamp
        self.free = free
        self.laser = laser
        self.scan = scan
        self.points = points
        self._tree: cKDTree | None = None

    def tree(self) -> cKDTree:
        """Return a k-d tree of the returns (built on first use)."""
        if self._tree is None:
            self._tree = cKDTree(self.points)
        return self._tree


class ScanTracker:
    """Scans in, tracks out: clusters, their free-space evidence, and the `Tracker`.

    Keeps the scans of the last ``reference_age`` seconds and more (the beams' free space and
    the laser's pose), so that each cluster can be checked against the free space a scan at
    least that old saw.

    Args:
        config: The tracking settings.
        gap: The clustering gap (the memory's default, CLUSTER_GAP).

    """

    def __init__(self, config: TrackerConfig | None = None, *,
                 gap: float = CLUSTER_GAP) -> None:
        self.tracker = Tracker(config)
        self.gap = float(gap)
        self._history: list[_Reference] = []
        # the last scan's returns labelled with their tracks (ObstacleMemory.update's tracks)
        self.labels = TrackLabels(np.zeros(0, dtype=np.int64), frozenset())

    @property
    def config(self) -> TrackerConfig:
        """The tracking settings."""
        return self.tracker.config

    def clear(self) -> None:
        """Forget the tracks and the scans kept."""
        self.tracker.clear()
        self._history = []
        self.labels = TrackLabels(np.zeros(0, dtype=np.int64), frozenset())

    def update(self, scan: Scan, robot_pose: Sequence[float], *,
               laser_pose: Sequence[float] = (0.0, 0.0, 0.0),
               body: Footprint | None = None, readings: Beams | None = None,
               points: np.ndarray | None = None) -> list[Track]:
        """Take a valid scan placed at robot_pose (map frame); return the live tracks.

        readings: the scan's beams as `classify_beams` reads them with this body and laser
        pose, when the caller has them (the memory does): None reads them here.
        points: its returns in the map frame as `scan_points` gives them from readings, when
        the caller has them (the memory does; only with readings): None computes them.
        Afterwards `labels` holds this scan's returns labelled with their tracks and the
        moving tracks' ids: what `ObstacleMemory.update` takes as ``tracks``.
        """
        if readings is None:
            readings = classify_beams(scan, body=body, laser_pose=laser_pose)
            points = None
        if points is None:
            points, _ = scan_points(scan, robot_pose, laser_pose=laser_pose, readings=readings)
        first, last = cluster_bounds(points, self.gap)
        clusters = [points[a:b + 1] for a, b in zip(first, last, strict=True)]
        laser = compose_pose(robot_pose, laser_pose)
        stamp = float(scan.stamp)
        reference = self._reference(stamp)
        flags = [self._in_free_space(c, reference) for c in clusters] \
            if reference is not None else None
        tracks = self.tracker.update(clusters, stamp, in_free_space=flags)
        per_return = np.full(len(points), -1, dtype=np.int64)
        for a, b, owner in zip(first, last, self.tracker.matches, strict=True):
            if owner is not None:
                per_return[a:b + 1] = owner
        self.labels = TrackLabels(per_return, frozenset(t.id for t in tracks if t.moving))
        self._history.append(_Reference(stamp, readings.free, laser, scan, points))
        cutoff = stamp - self.config.reference_age
        # keep the newest scan at least reference_age old, and all the newer ones
        while len(self._history) > 1 and self._history[1].stamp <= cutoff:
            self._history.pop(0)
        return tracks

    def _reference(self, stamp: float) -> _Reference | None:
        """The newest kept scan at least reference_age older than stamp, if any."""
        old = [h for h in self._history if stamp - h.stamp >= self.config.reference_age - 1e-9]
        return old[-1] if old else None

    def _in_free_space(self, cluster: np.ndarray, reference: _Reference) -> bool:
        """Whether enough of the cluster's returns lie where the reference scan saw free.

        A return is in free space when it lies more than free_margin short of what the
        reference beams in its direction saw, and more than free_margin from every return
        of the reference: near the robot a static surface seen from two poses is seen
        along very different rays, and a range's noise moves a return sideways past the
        silhouette the reference saw.
        """
        free, laser, scan = reference.free, reference.laser, reference.scan
        offsets = cluster - laser[:2]
        distance = np.hypot(offsets[:, 0], offsets[:, 1])
        bearing = np.arctan2(offsets[:, 1], offsets[:, 0]) - laser[2] - scan.angle_min
        # beams counted from angle_min in the scan's own direction of sweep
        sweep = math.copysign(1.0, scan.angle_increment)
        bearing = np.mod(sweep * bearing, 2.0 * math.pi)
        k = np.rint(bearing / abs(scan.angle_increment)).astype(np.int64)
        beams = len(free)
        inside = (k >= 1) & (k < beams - 1)
        k = np.clip(k, 1, beams - 2)
        nearest = np.minimum(np.minimum(free[k - 1], free[k]), free[k + 1])
        in_free = inside & (distance < nearest - self.config.free_margin)
        if in_free.any() and len(reference.points):
            in_free[in_free] = reference.tree().query(cluster[in_free])[0] \
                > self.config.free_margin
        count = int(np.count_nonzero(in_free))
        return count >= self.config.free_points and count >= self.config.free_share * len(cluster)
