# SPDX-License-Identifier: Apache-2.0
"""The laser of the physics plant: the engine ray-casts every beam (mj_multiRay).

The rays leave the laser LASER_HEIGHT above the ground, level, and see only the obstacle
geoms (group OBSTACLE_GROUP: not the floor, not the robot's own bodies). The beams and
the scan are `BeamLayout`'s, as `SimulatedLaser`'s are (beam angles from -fov / 2, the exact
distance, ``inf`` for no return within range_max per REP 117), so perception takes the scan
unchanged.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mpc_local_planner.sim.laser import BeamLayout
from mpc_local_planner.sim.physics.model import LASER_HEIGHT, OBSTACLE_GROUP

__all__ = ['PhysicsLaser']


class PhysicsLaser(BeamLayout):
    """A planar laser scanner cast by the engine (`BeamLayout`'s conventions).

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
        super().__init__(fov=fov, beams=beams, range_min=range_min, range_max=range_max)
        self.engine = engine
        self.data = data
        self._groups = np.zeros(6, dtype=np.uint8)
        self._groups[OBSTACLE_GROUP] = 1
        self._geoms = np.zeros(beams, dtype=np.int32)
        self._dist = np.zeros(beams)

    def _cast(self, x: float, y: float, yaw: float) -> np.ndarray:
        """Cast every beam with mj_multiRay from LASER_HEIGHT, level, at the obstacles."""
        angles = yaw + self.angles()
        directions = np.column_stack([np.cos(angles), np.sin(angles),
                                      np.zeros(self.beams)]).reshape(-1)
        mujoco.mj_multiRay(self.engine, self.data, np.array([x, y, LASER_HEIGHT]), directions,
                           self._groups, 1, -1, self._geoms, self._dist, None, self.beams,
                           self.range_max)
        return np.where((self._dist >= 0.0) & (self._geoms >= 0)
                        & (self._dist <= self.range_max), self._dist, np.inf)
