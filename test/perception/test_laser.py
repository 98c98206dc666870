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

"""Tests of the simulated laser and the contact check against the exact world."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.laser import contact, JACKAL_FOV, SimulatedLaser
from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.worlds.data_files import BARN_DIR
from mpc_local_planner.worlds.world import Circle, load_barn_world, world_from_dict


def brute_force(shapes: list, origin: np.ndarray, angles: np.ndarray, range_max: float
                ) -> np.ndarray:
    """Cast every beam against every shape densely (no pruning): the reference."""
    ranges = np.full(len(angles), np.inf)
    d = np.column_stack([np.cos(angles), np.sin(angles)])
    for shape in shapes:
        if isinstance(shape, Circle):
            f = origin - (shape.x, shape.y)
            proj = d @ f
            disc = proj**2 - (f @ f - shape.radius**2)
            t = np.where(disc >= 0, -proj - np.sqrt(np.maximum(disc, 0)), np.inf)
            t[t < 0] = np.inf
        else:
            t = np.full(len(angles), np.inf)
            v = shape.vertices
            for s, e in zip(v, np.roll(v, -1, axis=0), strict=True):
                edge, rel = e - s, s - origin
                den = d[:, 0] * edge[1] - d[:, 1] * edge[0]
                with np.errstate(divide='ignore', invalid='ignore'):
                    tt = (rel[0] * edge[1] - rel[1] * edge[0]) / den
                    u = (rel[0] * d[:, 1] - rel[1] * d[:, 0]) / den
                ok = (np.abs(den) > 1e-12) & (tt >= 0) & (u >= 0) & (u <= 1)
                t = np.minimum(t, np.where(ok, tt, np.inf))
        ranges = np.minimum(ranges, t)
    ranges[ranges > range_max] = np.inf
    return ranges


def test_laser_uses_rep117_conventions_and_centres_beams_on_the_forward_axis() -> None:
    laser = SimulatedLaser([ConvexPolygon.from_box(2.0, -1.0, 3.0, 1.0)])
    scan = laser.scan((0.0, 0.0, 0.0))

    assert len(scan.ranges) == 720
    assert scan.angle_min == pytest.approx(-JACKAL_FOV / 2)
    assert scan.angle_min + 719 * scan.angle_increment == pytest.approx(JACKAL_FOV / 2)
    assert scan.ranges[359] == pytest.approx(2.0, abs=1e-3)
    assert scan.ranges[360] == pytest.approx(2.0, abs=1e-3)
    assert np.isinf(scan.ranges[0]) and np.isinf(scan.ranges[-1])  # nothing there: inf


def test_laser_hits_a_circle_exactly_and_follows_the_pose_yaw() -> None:
    laser = SimulatedLaser([Circle(0.0, 3.0, 0.5)], beams=361, fov=math.pi)
    scan = laser.scan((0.0, 0.0, math.pi / 2))

    assert scan.ranges[180] == pytest.approx(2.5, abs=1e-12)
    angles = laser.angles() + math.pi / 2
    np.testing.assert_allclose(scan.ranges,
                               brute_force([Circle(0.0, 3.0, 0.5)], np.zeros(2), angles, 10.0))


def test_barn_scan_matches_a_brute_force_cast_against_every_cylinder() -> None:
    world = load_barn_world(BARN_DIR / 'world_000.json')
    laser = SimulatedLaser(TrueGeometry.from_world(world))
    for pose in ([-2.25, 3.5, 1.57], [-1.0, 6.0, -2.5], [-3.5, 9.0, 0.3]):
        scan = laser.scan(pose)
        angles = pose[2] + laser.angles()
        reference = brute_force(list(world.true_shapes), np.array(pose[:2]), angles, 10.0)
        np.testing.assert_allclose(scan.ranges, reference, atol=1e-9)
        assert np.isfinite(scan.ranges).sum() > 100


def test_laser_drops_hits_beyond_range_max() -> None:
    laser = SimulatedLaser([Circle(5.0, 0.0, 0.5)], range_max=4.0)

    assert np.all(np.isinf(laser.scan((0.0, 0.0, 0.0)).ranges))


def test_laser_sees_unknown_obstacles_of_a_world() -> None:
    world = world_from_dict({
        'bounds': [-1, 5, -2, 2], 'obstacles': [], 'start': [0, 0, 0], 'goal': [4, 0, 0],
        'unknown_obstacles': [{'circle': [2.0, 0.0, 0.25]}],
    }, name='hidden')
    scan = SimulatedLaser(TrueGeometry.from_world(world)).scan(world.start)

    assert np.min(scan.ranges) == pytest.approx(1.75, abs=1e-3)
    assert isinstance(world.true_shapes[0], Circle)  # cast against the disk itself


def test_laser_noise_is_reproducible_with_a_seeded_generator_and_required_for_noise() -> None:
    shapes = [ConvexPolygon.from_box(2.0, -1.0, 3.0, 1.0)]
    first = SimulatedLaser(shapes, noise_std=0.01, rng=np.random.default_rng(7))
    second = SimulatedLaser(shapes, noise_std=0.01, rng=np.random.default_rng(7))
    exact = SimulatedLaser(shapes).scan((0, 0, 0)).ranges

    noisy = first.scan((0, 0, 0)).ranges
    np.testing.assert_array_equal(noisy, second.scan((0, 0, 0)).ranges)
    hit = np.isfinite(exact)
    assert 0.0 < np.std(noisy[hit] - exact[hit]) < 0.02
    with pytest.raises(ValueError, match='seeded numpy Generator'):
        SimulatedLaser(shapes, noise_std=0.01)


@pytest.mark.parametrize('options', [{'beams': 1}, {'fov': 0.0}, {'range_max': math.inf},
                                     {'range_min': 2.0, 'range_max': 1.0}])
def test_laser_refuses_bad_options(options: dict) -> None:
    with pytest.raises(ValueError):
        SimulatedLaser([], **options)


def test_contact_uses_exact_distances_to_polygons_and_disks() -> None:
    geometry = TrueGeometry([ConvexPolygon.from_box(0.0, 0.0, 1.0, 1.0), Circle(3.0, 0.0, 0.5)])

    assert contact(geometry, 1.2, 0.5, 0.2)  # touching a face counts
    assert not contact(geometry, 1.21, 0.5, 0.2)
    corner = 1.0 + 0.2 / math.sqrt(2)
    assert contact(geometry, corner, corner, 0.2 + 1e-9)  # the corner is round, not a box
    assert not contact(geometry, corner + 0.01, corner + 0.01, 0.2)
    assert contact(geometry, 0.5, 0.5, 0.0)  # inside
    assert contact(geometry, 3.69, 0.0, 0.2) and not contact(geometry, 3.71, 0.0, 0.2)
    assert not contact(TrueGeometry([]), 0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match='finite'):
        contact(geometry, math.nan, 0.0, 0.2)
