# SPDX-License-Identifier: Apache-2.0
"""The laser of the physics plant: the engine ray-casts every beam (mj_multiRay).

The rays leave the laser LASER_HEIGHT above the ground, level, and see only the obstacle
geoms (group OBSTACLE_GROUP: not the floor, not the robot's own bodies). The scan has
`SimulatedLaser`'s conventions (beam angles from -fov / 2, the exact distance, ``inf`` for
no return within range_max per REP 117), so perception takes it unchanged.
"""

from __future__ import annotations

import math
from typing import Sequence

import mujoco
import numpy as np

from mpc_local_planner.perception.scans import Scan
from mpc_local_planner.sim.physics.model import LASER_HEIGHT, OBSTACLE_GROUP

__all__ = ['PhysicsLaser']


class PhysicsLaser:
    """A planar laser scanner cast by the engine, with the LaserScan conventions.

    Args:
        engine: The plant's MjModel.
        data: Its MjData (the obstacles' placement).
        fov: Field of view, radians.
        beams: Number of beams (>= 2).
        range_min: Closest valid reading, metres.
        range_max: Farthest valid reading, metres.

    Raises:
        ValueError: If an option is out of range.

    """

    def __init__(self, engine: mujoco.MjModel, data: mujoco.MjData, *, fov: float,
                 beams: int, range_min: float, range_max: float) -> None:
        if not (0.0 < fov <= 2.0 * math.pi):
            msg = f'fov must be in (0, 2 pi], got {fov}'
            raise ValueError(msg)
        if isinstance(beams, bool) or not isinstance(beams, int) or beams < 2:
            msg = f'beams must be an integer >= 2, got {beams!r}'
            raise ValueError(msg)
        if not (0.0 <= range_min < range_max < math.inf):
            msg = f'need 0 <= range_min < range_max < inf, got {range_min}, {range_max}'
            raise ValueError(msg)
        self.engine = engine
        self.data = data
        self.fov = float(fov)
        self.beams = beams
        self.range_min = float(range_min)
        self.range_max = float(range_max)
        self._groups = np.zeros(6, dtype=np.uint8)
        self._groups[OBSTACLE_GROUP] = 1
        self._geoms = np.zeros(beams, dtype=np.int32)
        self._dist = np.zeros(beams)

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

        Raises:
            ValueError: If the pose is not finite.

        """
        x, y, yaw = (float(v) for v in pose[:3])
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            msg = f'laser pose must be finite, got {tuple(pose)}'
            raise ValueError(msg)
        angles = yaw + self.angles()
        directions = np.column_stack([np.cos(angles), np.sin(angles),
                                      np.zeros(self.beams)]).reshape(-1)
        mujoco.mj_multiRay(self.engine, self.data, np.array([x, y, LASER_HEIGHT]), directions,
                           self._groups, 1, -1, self._geoms, self._dist, None, self.beams,
                           self.range_max)
        ranges = np.where((self._dist >= 0.0) & (self._geoms >= 0)
                          & (self._dist <= self.range_max), self._dist, np.inf)
        return Scan(angle_min=self.angle_min, angle_increment=self.angle_increment,
                    range_min=self.range_min, range_max=self.range_max, ranges=ranges,
                    stamp=float(stamp))
