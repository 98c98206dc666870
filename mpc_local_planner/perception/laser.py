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

"""A simulated 2-D laser and a contact check against the world's exact geometry.

Both answer questions about the *true* world (known and unknown obstacles, disks as disks),
not about what the robot believes: the laser is how unknown obstacles become known, and a
contact is what the evaluation counts against the controller.

Speed matters because the simulator scans at 10-40 Hz in a BARN world with hundreds of
cylinders. Every obstacle is bounded by a disk; a disk beyond range_max is dropped, and each
remaining disk is paired only with the beams whose angles fall inside the cone it subtends
from the laser. The exact intersection (analytic for disks, Cyrus-Beck style for polygon
edges) is then one NumPy expression over those (beam, obstacle) pairs, and each beam keeps its
nearest hit. Beams that hit nothing are ``inf`` (REP 117), not range_max.
"""

from __future__ import annotations

import math
from typing import Sequence, TYPE_CHECKING

import numpy as np

from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.perception.scan_obstacles import Scan

if TYPE_CHECKING:
    from mpc_local_planner.worlds.world import Shape

__all__ = [
    'JACKAL_FOV',
    'SimulatedLaser',
    'TrueGeometry',
    'contact',
]

#: The Jackal's laser field of view (270 degrees), the BARN challenge's sensor.
JACKAL_FOV = 4.71


def contact(geometry: TrueGeometry, x: float, y: float, radius: float) -> bool:
    """Say whether a robot disk of the given radius at (x, y) touches any obstacle.

    Touching counts (distance <= radius): the simulator counts contacts, and a robot that
    grazes a cylinder has hit it. Only obstacles whose bounding disk is within radius are
    examined, so the cost does not grow with the size of the world.

    Args:
        geometry: The world's exact obstacles (`TrueGeometry.from_world`).
        x: Robot centre x in the world frame.
        y: Robot centre y.
        radius: Radius of the robot's disk, metres (>= 0).

    Returns:
        True if the disk meets an obstacle.

    Raises:
        ValueError: If radius is negative or the position is not finite.

    """
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(radius)) or radius < 0:
        msg = f'contact needs a finite position and radius >= 0, got ({x}, {y}), r={radius}'
        raise ValueError(msg)
    return geometry.distance((x, y), within=radius) <= radius


class SimulatedLaser:
    """A planar laser scanner that sees the true world, with the LaserScan conventions.

    Beam angles are relative to the laser's forward axis: angle_min = -fov / 2,
    angle_increment = fov / (beams - 1), so the middle beam looks straight ahead. Readings are
    the exact distance (plus optional Gaussian noise); a beam that hits nothing within
    range_max is inf. Readings below range_min are reported as measured (consumers discard
    them, as they must for a real sensor).

    Args:
        geometry: The world's exact obstacles, or the shapes to build them from.
        fov: Field of view, radians (default the Jackal's 270 degrees).
        beams: Number of beams (>= 2).
        range_min: Closest valid reading, metres.
        range_max: Farthest valid reading, metres.
        noise_std: Standard deviation of the additive range noise, metres (0: exact).
        rng: Random generator for the noise; required when noise_std > 0, so that runs are
            reproducible.

    Raises:
        ValueError: If an option is out of range.

    """

    def __init__(self, geometry: TrueGeometry | Sequence[Shape], *, fov: float = JACKAL_FOV,
                 beams: int = 720, range_min: float = 0.05, range_max: float = 10.0,
                 noise_std: float = 0.0, rng: np.random.Generator | None = None) -> None:
        if not (0.0 < fov <= 2.0 * math.pi):
            msg = f'fov must be in (0, 2 pi], got {fov}'
            raise ValueError(msg)
        if isinstance(beams, bool) or not isinstance(beams, int) or beams < 2:
            msg = f'beams must be an integer >= 2, got {beams!r}'
            raise ValueError(msg)
        if not (0.0 <= range_min < range_max < math.inf):
            msg = f'need 0 <= range_min < range_max < inf, got {range_min}, {range_max}'
            raise ValueError(msg)
        if not (math.isfinite(noise_std) and noise_std >= 0.0):
            msg = f'noise_std must be >= 0, got {noise_std}'
            raise ValueError(msg)
        if noise_std > 0.0 and rng is None:
            msg = 'noise_std > 0 needs a seeded numpy Generator (rng=...)'
            raise ValueError(msg)
        self.geometry = geometry if isinstance(geometry, TrueGeometry) else TrueGeometry(
            geometry)
        self.fov = float(fov)
        self.beams = beams
        self.range_min = float(range_min)
        self.range_max = float(range_max)
        self.noise_std = float(noise_std)
        self.rng = rng

    @property
    def angle_min(self) -> float:
        """Angle of the first beam relative to the laser's forward axis."""
        return -0.5 * self.fov

    @property
    def angle_increment(self) -> float:
        """Angle between consecutive beams."""
        return self.fov / (self.beams - 1)

    def angles(self) -> np.ndarray:
        """Return the beams' angles relative to the laser's forward axis."""
        return self.angle_min + np.arange(self.beams) * self.angle_increment

    def scan(self, pose: Sequence[float], *, stamp: float = 0.0) -> Scan:
        """Cast every beam from the laser's pose and return the scan.

        Args:
            pose: (x, y, yaw) of the laser in the world frame.
            stamp: Time of the scan, seconds (copied into the result).

        Returns:
            The scan; ``ranges`` has one entry per beam, inf where nothing was hit.

        Raises:
            ValueError: If the pose is not finite.

        """
        x, y, yaw = (float(v) for v in pose[:3])
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            msg = f'laser pose must be finite, got {tuple(pose)}'
            raise ValueError(msg)
        ranges = self.geometry.cast((x, y), yaw + self.angle_min, self.angle_increment,
                                    self.beams, self.range_max)
        if self.noise_std > 0.0 and self.rng is not None:
            hit = np.isfinite(ranges)
            noisy = ranges[hit] + self.rng.normal(0.0, self.noise_std, int(hit.sum()))
            noisy = np.maximum(noisy, 0.0)
            noisy[noisy > self.range_max] = np.inf
            ranges[hit] = noisy
        return Scan(angle_min=self.angle_min, angle_increment=self.angle_increment,
                    range_min=self.range_min, range_max=self.range_max, ranges=ranges,
                    stamp=float(stamp))
