# SPDX-License-Identifier: Apache-2.0
"""When the collision margin is used up: a standing robot plans among the obstacles as sensed.

MpcConfig.collision_margin grows every obstacle by how far a lagging base departs from the
verified motion, so that the base's real path stays clear where the plan keeps the margin.
A base can depart by more than that: a skid-steer slips in a turn, a stop brakes later than
the plan it follows. It then stands with its footprint within the margin of an obstacle,
and every plan from there must first leave the grown obstacle; a forward-only robot facing
it often cannot (the first steps start from rest within the rate bounds, and a turn in place
sweeps the corners), so the solver finds no plan and the robot stands for good. Through the
nodes on the MuJoCo Jackal that is how BARN 23, 272, 276 and 296 ended: standing 27 to 56 mm
from the laser's pieces with a 30 mm margin, no feasible plan at any step; with the margin
at zero the same solves found one.

`MarginRelief` says when the MPC solves with a smaller margin instead: only after a step
whose solver found no plan, with the robot standing (its twist within STANDING_TWIST) and its
footprint nearer an obstacle than RELIEF_FACTOR times the margin; until the footprint is that
far from every obstacle again. The smaller margin is RELIEVED_SHARE of the clearance the robot
stands at when the relief starts, fixed while it lasts: the start is feasible, with room, and
the robot never gets nearer the laser's pieces than that. (Not zero: the pieces are fitted to
the returns, and a cylinder's surface between and beyond them can lie a few millimetres
outside them; with a margin of zero, BARN 222 through the nodes turned in place into one,
9 mm deep.) From rest the base departs least from a plan, which is why the relief starts only
there; every plan is still verified against the obstacles (with the smaller margin) and the
footprint's swept clearance.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.obstacles import (
    ConvexPolygon,
    min_clearance,
    ObstacleSet,
    polygon_separation,
)

__all__ = ['footprint_clearance_at', 'MarginRelief', 'RELIEF_FACTOR', 'RELIEVED_SHARE',
           'STANDING_TWIST']

# The relief starts within, and ends beyond, this many margins of an obstacle: a robot that
# stands with less room than one margin beyond the grown obstacles has no room to turn away.
RELIEF_FACTOR = 2.0
# The relieved margin, as a share of the clearance the robot stands at when the relief starts.
RELIEVED_SHARE = 0.5
# |v| (m/s) and |omega| (rad/s) below which a measured twist is a standing robot's (a
# standing base's odometry noise is well below both).
STANDING_TWIST = (0.02, 0.05)


def footprint_clearance_at(footprint: Footprint, poses: np.ndarray,
                           obstacles: Sequence[ConvexPolygon]) -> float:
    """Return the footprint's least signed distance from an obstacle at poses (inf: none).

    poses: one pose (3,) or several (M, >= 3). A polygon: the exact distance (minus the
    penetration depth when overlapping); a circle: the centre's distance less the radius.
    """
    if not obstacles:
        return float('inf')
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    if footprint.is_circle:
        return float(min_clearance(list(obstacles), poses[:, :2])) - footprint.radius
    signed, _ = polygon_separation(footprint.at_poses(poses), ObstacleSet(list(obstacles)))
    return float(np.min(signed))


def standing(twist: np.ndarray | None) -> bool:
    """Say whether a measured (v, omega) is a standing robot's (None: not known to be)."""
    if twist is None:
        return False
    v, omega = (abs(float(a)) for a in np.asarray(twist, dtype=float).reshape(-1)[:2])
    return v <= STANDING_TWIST[0] and omega <= STANDING_TWIST[1]


class MarginRelief:
    """Whether the MPC's obstacles are grown by the collision margin or taken as sensed."""

    def __init__(self) -> None:
        self.active = False
        self.margin = 0.0  # the relieved margin while active, metres

    def update(self, *, margin: float, clearance: float, solver_stopped: bool,
               is_standing: bool) -> bool:
        """Return whether the relief is in force for this step (and keep it).

        Args:
            margin: MpcConfig.collision_margin (a relief needs one: 0 or None, never).
            clearance: the footprint's distance from the nearest obstacle (as sensed), m.
            solver_stopped: the last step's solver found no plan (the robot was stopped).
            is_standing: the robot stands (its measured twist within STANDING_TWIST).

        """
        near = clearance < RELIEF_FACTOR * margin
        if margin <= 0:
            self.active = False
        elif self.active:
            self.active = near
        else:
            self.active = near and solver_stopped and is_standing
            if self.active:  # fixed while it lasts: creeping nearer must not shrink it
                self.margin = min(margin, max(0.0, RELIEVED_SHARE * clearance))
        return self.active
