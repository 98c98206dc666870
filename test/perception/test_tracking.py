# SPDX-License-Identifier: Apache-2.0
"""Tracks from scans: walkers followed through a crossing, static clutter left static."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.evaluation.metrics import footprint_clearance
from mpc_local_planner.perception.scan_obstacles import ObstacleMemory
from mpc_local_planner.perception.scans import ScanError
from mpc_local_planner.perception.tracking import (
    ScanTracker,
    Track,
    Tracker,
    TrackerConfig,
    TrackLabels,
)
from mpc_local_planner.sim.laser import SimulatedLaser
from mpc_local_planner.sim.moving import WorldClock
from mpc_local_planner.sim.reality import reality_preset
from mpc_local_planner.sim.scan_channel import ScanChannel
from mpc_local_planner.worlds.data_files import BARN_DIR
from mpc_local_planner.worlds.world import load_barn_world, world_from_dict

SCAN_PERIOD = 0.1


def crossing_walkers() -> WorldClock:
    """Two people (0.25 m) at 1 m/s whose paths cross at (3, 0) at t = 2 s.

    The laser stands at the origin, facing them.
    """
    world = world_from_dict({
        'bounds': [-1.0, 8.0, -4.0, 4.0], 'obstacles': [], 'start': [0.0, 0.0, 0.0],
        'goal': [6.0, 0.0, 0.0],
        'moving_obstacles': [
            {'circle': [0.0, 0.0, 0.25],
             'waypoints': {'points': [[3.0, -2.0], [3.0, 3.5]], 'speed': 1.0,
                           'mode': 'back_and_forth'}},
            {'circle': [0.0, 0.0, 0.25],
             'waypoints': {'points': [[5.0, 0.0], [1.0, 0.0]], 'speed': 1.0,
                           'mode': 'back_and_forth'}}]}, name='crossing')
    return WorldClock.from_world(world)


def nearest(tracks: list[Track], point: np.ndarray) -> Track:
    return min(tracks, key=lambda t: float(np.hypot(*(t.position - point))))


def track_scans(clock: WorldClock, seconds: float, config: TrackerConfig | None = None
                ) -> dict[float, list[Track]]:
    """Scan at 10 Hz from the origin; return the tracks (copies) after each scan."""
    pose = (0.0, 0.0, 0.0)
    laser = SimulatedLaser(clock)
    tracker = ScanTracker(config)
    seen = {}
    for k in range(int(round(seconds / SCAN_PERIOD)) + 1):
        t = round(k * SCAN_PERIOD, 9)
        scan = laser.scan(pose, stamp=t)
        seen[t] = [Track(**vars(track)) for track in tracker.update(scan, pose)]
    return seen


def test_two_walkers_keep_their_ids_through_a_crossing() -> None:
    clock = crossing_walkers()
    walker_a, walker_b = clock.moving
    seen = track_scans(clock, 4.0)
    before = {name: nearest(seen[1.0], walker.position(1.0)).id
              for name, walker in (('a', walker_a), ('b', walker_b))}
    after = {name: nearest(seen[3.5], walker.position(3.5)) for name, walker in
             (('a', walker_a), ('b', walker_b))}
    assert before['a'] != before['b']
    assert after['a'].id == before['a'] and after['b'].id == before['b']
    # each is told moving, at its own velocity
    for name, walker in (('a', walker_a), ('b', walker_b)):
        track = after[name]
        assert track.moving
        assert np.allclose(track.velocity, walker.velocity(3.5), atol=0.25)


def test_a_walker_is_told_moving_within_a_second_and_its_velocity_is_known() -> None:
    clock = crossing_walkers()
    walker_a = clock.moving[0]
    seen = track_scans(clock, 1.2)
    first = min(t for t, tracks in seen.items()
                if any(tr.moving and np.hypot(*(tr.position - walker_a.position(t))) < 0.4
                       for tr in tracks))
    assert first <= 1.0
    track = nearest(seen[1.2], walker_a.position(1.2))
    assert np.allclose(track.velocity, [0.0, 1.0], atol=0.2)
    position, covariance = track.predicted(2.2)
    assert np.allclose(position, walker_a.position(2.2), atol=0.35)
    assert np.all(np.linalg.eigvalsh(covariance) > 0.0)


def test_a_walker_passing_close_by_a_cylinder_keeps_its_velocity() -> None:
    """A walker (0.2 m, 1 m/s) passes 0.2 m in front of a cylinder, seen from the laser.

    For a few scans the laser's returns of the two join into one cluster, whose centre lies
    between them: a track corrected with it got a velocity off by 0.55 m/s. Its track coasts
    through the merge instead, and is told moving at its own velocity throughout.
    """
    world = world_from_dict({
        'bounds': [-1.0, 8.0, -4.0, 4.0], 'obstacles': [{'circle': [3.0, 0.3, 0.2]}],
        'start': [0.0, 0.0, 0.0], 'goal': [6.0, 0.0, 0.0],
        'moving_obstacles': [
            {'circle': [0.0, 0.0, 0.2],
             'waypoints': {'points': [[2.6, -2.0], [2.6, 3.5]], 'speed': 1.0,
                           'mode': 'back_and_forth'}}]}, name='passing a cylinder')
    clock = WorldClock.from_world(world)
    walker = clock.moving[0]
    seen = track_scans(clock, 4.0)
    for t, tracks in seen.items():
        if t < 1.0:
            continue
        mine = [tr for tr in tracks
                if tr.moving and np.hypot(*(tr.position - walker.position(t))) < 0.5]
        assert mine, f'no moving track at the walker at {t} s'
        error = min(float(np.hypot(*(tr.velocity - walker.velocity(t)))) for tr in mine)
        assert error < 0.2, f'{t} s: velocity off by {error:.2f} m/s'


@pytest.mark.parametrize(('world_index', 'reality'),
                         [(0, 'ideal'), (250, 'ideal'), (26, 'real'), (35, 'real'),
                          (99, 'real'), (228, 'real')])
def test_static_cylinders_stay_static_while_the_jackal_drives_past_at_2_m_s(
        world_index: int, reality: str) -> None:
    """BARN's cylinders seen from a Jackal weaving along its start-goal line at 2 m/s.

    Poses where the body would touch a cylinder are left out (the line crosses some). With
    the `real` laser's noise these worlds had a cluster beside the robot told moving when
    free space was judged by the beams alone: a return's noise near the robot, seen from
    two poses 0.6 m apart, moved it past the silhouette the older scan saw.
    """
    world = load_barn_world(BARN_DIR / f'world_{world_index:03d}.json', footprint=JACKAL)
    laser = SimulatedLaser(world.physical_shapes())
    channel = ScanChannel(reality_preset(reality).with_seed(world_index))
    clearance = footprint_clearance(world.physical_shapes(), JACKAL)
    tracker = ScanTracker()
    start, goal = world.start[:2], world.goal[:2]
    heading = math.atan2(*(goal - start)[::-1])
    steps = int(np.hypot(*(goal - start)) / (2.0 * SCAN_PERIOD))
    tracked = 0
    for k in range(steps):
        position = start + (goal - start) * k / steps
        pose = (float(position[0]), float(position[1]), heading + 0.3 * math.sin(k / 5))
        if float(clearance(np.array([pose]))[0]) < 0.05:
            continue
        scan = laser.scan(pose, stamp=k * SCAN_PERIOD)
        scan = scan._replace(ranges=channel.corrupt(scan.ranges, scan.range_max))
        tracks = tracker.update(scan, pose, body=JACKAL)
        tracked = max(tracked, len(tracks))
        assert not [t.id for t in tracks if t.moving], f'step {k}'
    assert tracked > 0  # there was clutter to track


def test_bad_input_is_refused() -> None:
    tracker = Tracker()
    tracker.update([np.array([[1.0, 0.0]])], 1.0)
    with pytest.raises(ValueError, match='older'):
        tracker.update([], 0.5)
    with pytest.raises(ValueError, match='non-finite'):
        tracker.update([np.array([[math.nan, 0.0]])], 2.0)
    with pytest.raises(ValueError, match='gate'):
        TrackerConfig(gate=0.0)
    with pytest.raises(ValueError, match='confirm'):
        TrackerConfig(confirm=0)


def passing_walker() -> WorldClock:
    """A person (0.25 m) walking at 1 m/s along y = -1.5, past a robot at the origin."""
    world = world_from_dict({
        'bounds': [-6.0, 6.0, -4.0, 4.0], 'obstacles': [], 'start': [0.0, 0.0, 0.0],
        'goal': [5.0, 0.0, 0.0],
        'moving_obstacles': [
            {'circle': [0.0, 0.0, 0.25],
             'waypoints': {'points': [[1.5, -1.5], [-5.0, -1.5]], 'speed': 1.0,
                           'mode': 'back_and_forth'}}]}, name='passing')
    return WorldClock.from_world(world)


def walker_trail(track: bool) -> tuple[int, int]:
    """Run the memory (with or without the tracker) as the walker passes; count what it held.

    The robot turns left in place at 1 rad/s while the walker passes its right side: the
    right edge of the laser's view turns away from where the walker was before any beam
    crosses that place again. Returns the most pieces held at once, after the first second,
    that lie more than 0.15 m from the walker where it is (its trail), and the pieces held on
    the walker at t = 1 s.
    """
    clock = passing_walker()
    walker = clock.moving[0]
    laser = SimulatedLaser(clock)
    memory = ObstacleMemory(5.0, tracker=ScanTracker() if track else None)
    trail, on_walker = 0, 0
    for k in range(41):
        t = round(k * SCAN_PERIOD, 9)
        pose = (0.0, 0.0, t)
        scan = laser.scan(pose, stamp=t)
        memory.update(scan, pose)
        gaps = [float(o.distance(walker.position(t))[0]) for o in memory.obstacles()]
        if t >= 1.0:
            trail = max(trail, sum(g > 0.25 + 0.15 for g in gaps))
        if t == 1.0:
            on_walker = sum(g <= 0.25 + 0.15 for g in gaps)
    return trail, on_walker


def test_a_walker_leaves_no_trail_in_the_memory() -> None:
    """Without the tracker the memory keeps pieces where the walker was, out of view.

    With the tracker, what was built from a moving track is forgotten at the next scan: the
    walker is held where it is, and nowhere else.
    """
    assert walker_trail(track=False)[0] >= 1  # the trail
    trail, on_walker = walker_trail(track=True)
    assert on_walker > 0
    assert trail == 0


def test_the_memory_refuses_moving_flags_that_do_not_fit_the_scan() -> None:
    laser = SimulatedLaser(passing_walker())
    scan = laser.scan((0.0, 0.0, 0.0), stamp=0.0)
    labels = TrackLabels(np.zeros(3, dtype=np.int64), frozenset({0}))
    with pytest.raises(ScanError, match='returns'):
        ObstacleMemory(5.0).update(scan, (0.0, 0.0, 0.0), tracks=labels)
