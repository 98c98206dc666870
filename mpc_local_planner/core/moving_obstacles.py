# SPDX-License-Identifier: Apache-2.0
"""Obstacles that move: a polygon now, its velocity, and how fast its uncertainty grows.

A walker the laser tracks (perception/tracking.py) is handed to the MPC as a polygon where
it is at the control step's time, with the track's velocity and the rate at which the
prediction's uncertainty grows. The MPC constrains stage k of its horizon (time t_k = k h)
against the obstacle where constant velocity puts it then, grown by what the prediction may
be off by:

    O_k = {q : A q <= b + t_k A v + d_k},   d_k = t_k growth + h/2 (|v| + growth)

t_k A v moves every face with the obstacle (a translation by t_k v); t_k growth grows it with
the uncertainty; and h/2 (|v| + growth) covers where it may be over the half step on each
side of the sample, as the robot's own sweep covers the robot's motion between samples
(formulation.sweep_rate): a sample clear of O_k by the clearance its motion needs keeps the
continuous motion clear of the moving obstacle too. A static obstacle is the same with v = 0
and growth = 0, and then O_k is the polygon itself, to the bit, at every stage.

Growing shifts every face (ConvexPolygon.inflate): the grown polygon contains the rounded
Minkowski sum, so it is conservative as the NLP's other inflations are. The NLP writes these
offsets with CasADi symbols (formulation.py); `stage_polygons` here builds the same polygons in
numbers, for the geometric checks that do not trust the solver.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Sequence

import numpy as np

from mpc_local_planner.core.obstacles import ConvexPolygon

__all__ = ['heading_anywhere', 'MOTION_SIZE', 'MovingPolygon', 'motion_of', 'moving',
           'offsets_by_stage', 'stage_lower_bound', 'stage_pad', 'stage_polygons']

# Numbers per obstacle slot that say how it moves: vx, vy, growth and speed |v| (m/s). The
# speed is given, not computed in the NLP: the derivative of a norm at a static obstacle's
# v = 0 is infinite, and forward derivatives with respect to the parameters (zero seeds)
# would make it 0 * inf = NaN.
MOTION_SIZE = 4


@dataclass(frozen=True, eq=False)
class MovingPolygon(ConvexPolygon):
    """A convex polygon where it is now, moving at a constant velocity, its extent uncertain.

    Attributes:
        velocity: (2,) m/s, in the polygon's frame.
        growth: how fast the prediction's uncertainty grows (m/s, >= 0): at time t ahead the
            obstacle is the polygon moved by t velocity and grown by t growth.

    """

    velocity: np.ndarray = field(default_factory=lambda: np.zeros(2))
    growth: float = 0.0

    def __post_init__(self) -> None:
        velocity = np.asarray(self.velocity, dtype=float).reshape(-1)
        if velocity.shape != (2,) or not np.all(np.isfinite(velocity)):
            msg = f'a moving polygon needs a finite (2,) velocity, got {self.velocity!r}'
            raise ValueError(msg)
        if not (math.isfinite(self.growth) and self.growth >= 0.0):
            msg = f'a moving polygon needs a finite growth >= 0, got {self.growth!r}'
            raise ValueError(msg)
        object.__setattr__(self, 'velocity', velocity)
        object.__setattr__(self, 'growth', float(self.growth))

    @classmethod
    def moving(cls, polygon: ConvexPolygon, velocity: Sequence[float],
               growth: float = 0.0) -> MovingPolygon:
        """Return polygon, set moving at velocity with its uncertainty growing at growth."""
        return cls(A=polygon.A, b=polygon.b, vertices=polygon.vertices,
                   velocity=np.asarray(velocity, dtype=float), growth=growth)

    @property
    def speed(self) -> float:
        """|velocity|, m/s."""
        return float(np.hypot(*self.velocity))

    def inflate(self, distance: float) -> MovingPolygon:
        """Shift every face outwards by distance (it moves on as before)."""
        grown = ConvexPolygon(A=self.A, b=self.b, vertices=self.vertices).inflate(distance)
        return MovingPolygon.moving(grown, self.velocity, self.growth)

    def at(self, t: float, pad: float = 0.0) -> ConvexPolygon:
        """Return where it is t seconds ahead: moved by t velocity, grown by t growth + pad."""
        shift = t * self.velocity
        moved = ConvexPolygon(A=self.A, b=self.b + self.A @ shift,
                              vertices=self.vertices + shift)
        return moved.inflate(t * self.growth + pad)


def heading_anywhere(obstacle: MovingPolygon) -> MovingPolygon:
    """Return the obstacle if it may turn any way at its speed: standing, growing at |v| + growth.

    What a walker who turns can reach: the constant-velocity prediction is one of its paths.
    """
    polygon = ConvexPolygon(A=obstacle.A, b=obstacle.b, vertices=obstacle.vertices)
    return MovingPolygon.moving(polygon, (0.0, 0.0), obstacle.speed + obstacle.growth)


def motion_of(obstacle: ConvexPolygon) -> np.ndarray:
    """Return (vx, vy, growth, speed) of an obstacle: zeros for a static one."""
    if isinstance(obstacle, MovingPolygon):
        return np.array([obstacle.velocity[0], obstacle.velocity[1], obstacle.growth,
                         obstacle.speed])
    return np.zeros(MOTION_SIZE)


def moving(obstacle: ConvexPolygon) -> bool:
    """Say whether the obstacle moves (or its uncertainty grows)."""
    return isinstance(obstacle, MovingPolygon) and (obstacle.speed > 0.0
                                                    or obstacle.growth > 0.0)


def stage_pad(obstacle: MovingPolygon, step: float) -> float:
    """Return h/2 (|v| + growth): how far it may get within half a step of a sample."""
    return step / 2.0 * (obstacle.speed + obstacle.growth)


def stage_polygons(obstacle: MovingPolygon, stages: int, step: float) -> list[ConvexPolygon]:
    """Return O_0..O_{stages-1}: the obstacle at each stage time k h, as the NLP holds it."""
    pad = stage_pad(obstacle, step)
    return [obstacle.at(k * step, pad) for k in range(stages)]


def offsets_by_stage(obstacle: ConvexPolygon, stages: int, step: float) -> np.ndarray:
    """Return (stages, faces): the faces' offsets at each stage time k h, as the NLP has them.

    b + t_k A v + t_k growth + h/2 (|v| + growth) for a moving obstacle; b at every stage for
    a static one.
    """
    if not isinstance(obstacle, MovingPolygon):
        return np.broadcast_to(obstacle.b, (stages, obstacle.num_faces))
    t = np.arange(stages) * step
    drift = obstacle.A @ obstacle.velocity
    pad = t * obstacle.growth + stage_pad(obstacle, step)
    return obstacle.b[None] + t[:, None] * drift[None] + pad[:, None]


def stage_lower_bound(obstacle: ConvexPolygon, points: np.ndarray, step: float, *,
                      first: int = 0, stages: np.ndarray | None = None) -> np.ndarray:
    """Return max_i (a_i p - b_i(t_k)) of each point against the obstacle at its stage's time.

    The signed-distance lower bound of ConvexPolygon.signed_distance_lower_bound, row k of
    points taken against O_{stages[k]}: by default stage first + k (the rows are a plan's
    poses); given stages, any stage per row (the poses of many plans at once).
    """
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    stages = first + np.arange(len(pts)) if stages is None else np.asarray(stages, dtype=int)
    offsets = offsets_by_stage(obstacle, int(np.max(stages, initial=-1)) + 1, step)[stages]
    return np.max(pts @ obstacle.A.T - offsets, axis=1)
