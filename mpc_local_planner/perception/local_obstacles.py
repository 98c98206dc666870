# SPDX-License-Identifier: Apache-2.0
"""What the controller avoids near the robot: the map's cells as rectangles, the laser's memory.

The controller node and the ROS-free rollout assemble their obstacles here, the same way:
the occupied cells of the map within a radius of the robot, merged into rectangles
(`grid_rectangles`, recomputed only when the robot enters another cell), plus the obstacles
the scan memory holds within that radius; every polygon fitted to the NLP's faces and rid of
needle corners (`within_faces`). The radius is what the horizon can reach plus the inflation
and a margin: nothing farther can matter to the next solve. A memory that tracks
(perception/tracking.py) hands its moving tracks over as moving polygons, with their
velocity, instead of the pieces they built: the MPC predicts them over its horizon.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from mpc_local_planner.core.identity_memo import IdentityMemo
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet, within_faces
from mpc_local_planner.perception.grids import grid_rectangles
from mpc_local_planner.perception.scan_obstacles import ObstacleMemory
from mpc_local_planner.perception.tracking import moving_polygon, Track
from mpc_local_planner.worlds.map_files import OccupancyMap

__all__ = ['LocalObstacles', 'SENSING_MARGIN']

# Metres beyond the horizon's reach (MpcConfig.reach: v_max N h, the inflation and a
# polygon's circumscribed radius) within which map cells and remembered scan obstacles are
# handed to the MPC (the controller node's, and a replay of its steps: ros/replay_step.py).
SENSING_MARGIN = 0.5


class LocalObstacles:
    """The map's and the laser's obstacles near the robot, as the MPC takes them.

    Args:
        faces: Largest number of faces of an obstacle (the NLP's faces_per_obstacle).
        occupancy: The static map, or None.
        memory: The scan memory, or None (the laser is not a source).
        predict_moving: A memory that tracks hands its moving tracks over as moving
            polygons (for a controller that predicts them: the MPC); False: as the pieces
            the last scan built of them, where they are (for one that does not).

    """

    def __init__(self, faces: int, *, occupancy: OccupancyMap | None = None,
                 memory: ObstacleMemory | None = None, predict_moving: bool = True) -> None:
        self.faces = int(faces)
        self.memory = memory
        self.predict_moving = predict_moving
        self._occupancy = occupancy
        self._window: tuple | None = None
        self._map_obstacles: list[ConvexPolygon] = []
        self._scan_obstacles = ObstacleSet([])
        self._movers: list[Track] = []
        # the memory's pieces fitted to the faces: each once, when it enters the memory (the
        # memory keeps a piece's object as long as it remembers it), not at every scan
        self._fitted: IdentityMemo[ConvexPolygon, ConvexPolygon] = IdentityMemo()

    @property
    def occupancy(self) -> OccupancyMap | None:
        """The static map in force."""
        return self._occupancy

    @occupancy.setter
    def occupancy(self, occupancy: OccupancyMap | None) -> None:
        self._occupancy = occupancy
        self._window = None

    def scan_updated(self) -> None:
        """Take the memory's obstacles in after it changed (fitted once per scan).

        A memory that tracks hands over its static pieces here, and its moving tracks
        (`near` predicts them to its time).
        """
        memory = self.memory
        predict = self.predict_moving
        polygons = memory.obstacles(static=predict) if memory is not None else []
        self._scan_obstacles = ObstacleSet(self._fit(polygons))
        # a suspect (perception/tracking.py `Track.suspect`) is predicted as a mover while
        # its pieces stay among the static ones: until the tracker knows, both hold
        self._movers = memory.moving_tracks + memory.suspect_tracks \
            if memory is not None and predict else []

    def _fit(self, polygons: Sequence[ConvexPolygon]) -> list[ConvexPolygon]:
        """Return the polygons fitted to the faces (`within_faces`), each fitted only once."""
        return self._fitted.map(polygons, self.faces,
                                lambda polygon: within_faces([polygon], self.faces)[0])

    def near(self, position: Sequence[float], radius: float, now: float | None = None
             ) -> list[ConvexPolygon]:
        """Return the map's rectangles and the remembered obstacles within radius of position.

        Then every moving track, as a MovingPolygon where it is at now (its last scan's
        stamp if None) with its velocity (perception/tracking.py `moving_polygon`): the
        MPC predicts it over its horizon, and it may come from beyond radius.

        Args:
            position: (x, y) of the robot, map frame.
            radius: Distance of interest, metres.
            now: The time the obstacles are wanted for (the control step's), seconds.

        """
        centre = np.asarray(position, dtype=float).reshape(-1)[:2]
        found: list[ConvexPolygon] = []
        if self._occupancy is not None and math.isfinite(radius):
            rows, cols = self._occupancy.world_to_cell(centre[None, :])
            window = (int(rows[0]), int(cols[0]), float(radius))
            if window != self._window:
                self._map_obstacles = within_faces(
                    grid_rectangles(self._occupancy, centre=centre, radius=radius), self.faces)
                self._window = window
            found += self._map_obstacles
        if len(self._scan_obstacles):
            chosen, _ = self._scan_obstacles.near(centre[None, :], radius)
            found += [self._scan_obstacles.obstacles[i] for i in sorted(chosen)]
        found += [moving_polygon(t, t.stamp if now is None else max(now, t.stamp))
                  for t in self._movers]
        return found
