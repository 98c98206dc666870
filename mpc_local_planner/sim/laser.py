# SPDX-License-Identifier: Apache-2.0
"""A simulated 2-D laser: ray casting against the world's exact geometry.

It sees the *true* world (known and unknown obstacles, disks as disks), not what the
robot believes: it is how unknown obstacles become known.

Speed matters because the simulator scans at 10-40 Hz in a BARN world with hundreds of
cylinders. Every obstacle is bounded by a disk; a disk beyond range_max is dropped, and each
remaining disk is paired only with the beams whose angles fall inside the cone it subtends
from the laser. The exact intersection (analytic for disks, Cyrus-Beck style for polygon
edges) is then one NumPy expression over those (beam, obstacle) pairs, and each beam keeps its
nearest hit. Beams that hit nothing are ``inf`` (REP 117), not range_max.

Given a `WorldClock` (sim/moving.py), the laser casts against the world as it is at the scan's
stamp: moving obstacles are seen where they are at that time.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
import math
from typing import Sequence, TYPE_CHECKING

import numpy as np

from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.perception.scans import Scan
from mpc_local_planner.sim.moving import WorldClock

if TYPE_CHECKING:
    from mpc_local_planner.worlds.world import Shape

__all__ = ['BeamLayout', 'JACKAL_FOV', 'SimulatedLaser']

#: The Jackal's laser field of view (270 degrees), the BARN challenge's sensor.
JACKAL_FOV = 4.71


class BeamLayout(ABC):
    """The beams of a planar laser scanner and its scan, with the LaserScan conventions.

    Every simulated laser shares this layout so that perception takes any of their scans
    unchanged; a subclass only casts the beams. Beam angles are relative to the laser's
    forward axis: angle_min = -fov / 2, angle_increment = fov / (beams - 1), so the middle
    beam looks straight ahead. Readings are the exact distance (a real laser's noise and
    dropouts are sim/scan_channel.py's ScanChannel, applied to the scan by whoever simulates a
    real one); a beam that hits nothing within range_max is inf. Readings below range_min are
    reported as measured (consumers discard them, as they must for a real sensor).

    Args:
        fov: Field of view, radians.
        beams: Number of beams (>= 2).
        range_min: Closest valid reading, metres.
        range_max: Farthest valid reading, metres.

    Raises:
        ValueError: If an option is out of range.

    """

    def __init__(self, *, fov: float, beams: int, range_min: float, range_max: float) -> None:
        if not (0.0 < fov <= 2.0 * math.pi):
            msg = f'fov must be in (0, 2 pi], got {fov}'
            raise ValueError(msg)
        if isinstance(beams, bool) or not isinstance(beams, int) or beams < 2:
            msg = f'beams must be an integer >= 2, got {beams!r}'
            raise ValueError(msg)
        if not (0.0 <= range_min < range_max < math.inf):
            msg = f'need 0 <= range_min < range_max < inf, got {range_min}, {range_max}'
            raise ValueError(msg)
        self.fov = float(fov)
        self.beams = beams
        self.range_min = float(range_min)
        self.range_max = float(range_max)

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
        return Scan(angle_min=self.angle_min, angle_increment=self.angle_increment,
                    range_min=self.range_min, range_max=self.range_max,
                    ranges=self._cast(x, y, yaw), stamp=float(stamp))

    @abstractmethod
    def _cast(self, x: float, y: float, yaw: float) -> np.ndarray:
        """Return each beam's range from the finite pose (x, y, yaw), inf for no return."""


class SimulatedLaser(BeamLayout):
    """A planar laser scanner that sees the true world (`BeamLayout`'s conventions).

    Args:
        geometry: The world's exact obstacles, or the shapes to build them from, or a
            `WorldClock` (the world at each scan's stamp: moving obstacles where they are).
        fov: Field of view, radians (default the Jackal's 270 degrees).
        beams: Number of beams (>= 2).
        range_min: Closest valid reading, metres.
        range_max: Farthest valid reading, metres.

    Raises:
        ValueError: If an option is out of range.

    """

    def __init__(self, geometry: TrueGeometry | WorldClock | Sequence[Shape], *,
                 fov: float = JACKAL_FOV, beams: int = 720, range_min: float = 0.05,
                 range_max: float = 10.0) -> None:
        super().__init__(fov=fov, beams=beams, range_min=range_min, range_max=range_max)
        self.clock = geometry if isinstance(geometry, WorldClock) else None
        if isinstance(geometry, WorldClock):
            geometry = geometry.static
        self.geometry = geometry if isinstance(geometry, TrueGeometry) else TrueGeometry(
            geometry)

    def scan(self, pose: Sequence[float], *, stamp: float = 0.0) -> Scan:
        """Cast every beam from the laser's pose at time stamp (see `BeamLayout.scan`).

        With a `WorldClock` the world is the one at stamp (moving obstacles where they are).
        """
        if self.clock is not None:
            self.geometry = self.clock.at(float(stamp))
        return super().scan(pose, stamp=stamp)

    def _cast(self, x: float, y: float, yaw: float) -> np.ndarray:
        """Cast against the exact geometry (see the module docstring)."""
        return self.geometry.cast((x, y), yaw + self.angle_min, self.angle_increment,
                                  self.beams, self.range_max)
