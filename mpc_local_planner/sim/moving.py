# SPDX-License-Identifier: Apache-2.0
"""The true world at a time: static shapes plus moving obstacles where they are then.

`WorldClock` is what the simulator node and the ROS-free rollout both ask for the TRUE
geometry at time t (the laser's scan, the contact check): one `TrueGeometry` of the static
shapes and each moving obstacle's shape at t (worlds/motion.py, closed form in t), so the two
paths see the same world at the same t. A world without moving obstacles gives its one static
geometry at every t, the very object the code used before there were moving ones.

Contacts are told apart as DynaBARN does (Nair et al. 2022): an *active* one when the robot
was moving as it began (the controller drove into something), a *passive* one when it stood
still and an obstacle ran into it. `ContactCounter` counts the episodes of each kind.
"""

from __future__ import annotations

import enum
import math
from typing import Sequence, TYPE_CHECKING

import numpy as np

from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.sim.contact import footprint_distances

if TYPE_CHECKING:
    from mpc_local_planner.core.footprint import Footprint
    from mpc_local_planner.worlds.motion import MovingObstacle
    from mpc_local_planner.worlds.world import Shape, World

__all__ = [
    'ACTIVE_SPEED',
    'ACTIVE_TURN_RATE',
    'ContactCounter',
    'ContactKind',
    'WorldClock',
    'contact_kind',
]

#: The robot moves (an active contact) above this speed, m/s ...
ACTIVE_SPEED = 0.01
#: ... or this turn rate, rad/s: a polygon robot turning in place sweeps its corners.
ACTIVE_TURN_RATE = 0.01


class ContactKind(enum.Enum):
    """Who caused a contact."""

    ACTIVE = 'active'  # the robot was moving
    PASSIVE = 'passive'  # the robot stood still: an obstacle ran into it


def contact_kind(v: float, omega: float) -> ContactKind:
    """Return the kind of a contact that begins while the robot moves at (v, omega).

    Args:
        v: The robot's TRUE speed, m/s (not the command: a lagging base still rolls).
        omega: Its TRUE turn rate, rad/s.

    """
    if abs(v) > ACTIVE_SPEED or abs(omega) > ACTIVE_TURN_RATE:
        return ContactKind.ACTIVE
    return ContactKind.PASSIVE


class ContactCounter:
    """Contact episodes, active and passive: entering contact counts one, staying does not.

    Attributes:
        active: Episodes that began with the robot moving.
        passive: Episodes that began with the robot standing still.

    """

    def __init__(self) -> None:
        self.active = 0
        self.passive = 0
        self._touching = False

    @property
    def total(self) -> int:
        """Every episode, active + passive."""
        return self.active + self.passive

    def update(self, touching: bool, v: float, omega: float) -> ContactKind | None:
        """Take whether the robot touches now and its true motion; return a new episode's kind.

        Returns:
            The kind of the episode that begins now, None when none does.

        """
        began = touching and not self._touching
        self._touching = touching
        if not began:
            return None
        kind = contact_kind(v, omega)
        if kind is ContactKind.ACTIVE:
            self.active += 1
        else:
            self.passive += 1
        return kind


class WorldClock:
    """The true geometry at a time: static shapes, and moving obstacles where they are then.

    Args:
        shapes: The static exact shapes (``world.physical_shapes()``).
        moving: The moving obstacles (``world.moving_obstacles``).

    """

    def __init__(self, shapes: Sequence[Shape],
                 moving: Sequence[MovingObstacle] = ()) -> None:
        self._shapes = tuple(shapes)
        self.moving = tuple(moving)
        self.static = TrueGeometry(self._shapes)
        self._time = math.nan
        self._current = self.static

    @classmethod
    def from_world(cls, world: World | None) -> WorldClock:
        """Return the clock of a world's true geometry (None: an empty world)."""
        if world is None:
            return cls(())
        return cls(world.physical_shapes(), world.moving_obstacles)

    def moving_at(self, t: float) -> tuple[Shape, ...]:
        """Return the moving obstacles' shapes at time t (seconds), without the static ones."""
        return tuple(m.shape_at(t) for m in self.moving)

    def at(self, t: float) -> TrueGeometry:
        """Return everything physically present at time t, packed for casts and contacts.

        The static geometry itself when nothing moves; else a new packing per new t (the
        last one is kept: a tick's laser and contact check ask at the same t).
        """
        if not self.moving:
            return self.static
        if t != self._time:
            self._current = TrueGeometry(self._shapes + self.moving_at(t))
            self._time = t
        return self._current

    def clearance(self, footprint: Footprint, pose: np.ndarray, t: float) -> float:
        """Return the signed distance of footprint at pose (x, y, theta) from the world at t.

        sim/contact.py's footprint_distances: negative is a penetration.
        """
        poses = np.asarray(pose, dtype=float).reshape(1, -1)[:, :3]
        return float(footprint_distances(self.at(float(t)), footprint, poses)[0])
