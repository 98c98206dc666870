# SPDX-License-Identifier: Apache-2.0
"""Settings of the global planner (`core.planner.RrtStarPlanner`), validated on construction.

The global planner node's parameters mirror them; a value refused there is refused for the
same reason as in a script.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from mpc_local_planner.core.footprint import Footprint, parse_footprint
from mpc_local_planner.core.rrt_star import MAX_SEED

__all__ = ['PlannerConfig']


def _footprint_vertices(value: object) -> tuple[tuple[float, float], ...]:
    """Return a footprint setting as hashable vertices (() for a round robot).

    Accepts vertices [[x, y], ...], Nav2's string form, or a polygon `Footprint`; a polygon
    is validated (convex, with an interior) by `Footprint.polygon`.

    Raises:
        ValueError: If it is not a convex polygon, or a round `Footprint` (whose radius is
            ``robot_radius``'s job).

    """
    if value is None:
        return ()
    if isinstance(value, Footprint):
        if value.vertices is None:
            msg = 'a round robot is given by robot_radius, not a circle Footprint'
            raise ValueError(msg)
        vertices = value.vertices
    elif isinstance(value, str):
        parsed = parse_footprint(value)
        if parsed.vertices is None:
            return ()
        vertices = parsed.vertices
    else:
        if len(value) == 0:  # type: ignore[arg-type]
            return ()
        Footprint.polygon(value)  # type: ignore[arg-type]  # refuses what is not convex
        vertices = np.asarray(value, dtype=float)  # kept as given
    return tuple((float(x), float(y)) for x, y in np.asarray(vertices, dtype=float))


@dataclass(frozen=True)
class PlannerConfig:
    """Settings of `RrtStarPlanner` (the global planner node's parameters mirror them).

    Attributes:
        iterations: RRT* iterations per plan (the paper's figure: 1000). With the seed, this
            makes plans reproducible; a time limit alone would not.
        time_limit: Upper bound on planning time in seconds, besides the iterations. A plan cut
            short by it is not reproducible.
        seed: Seed of OMPL's random number generator (any value in [0, 2**32 - 2]).
        range: RRT*'s maximum extension per iteration in metres; 0 lets OMPL choose (a fifth
            of the space's extent).
        robot_radius: Radius of the disk covering the robot, metres (without a footprint).
        clearance: Extra room beyond the robot, metres: room for the MPC to cut the
            polyline's corners and for its own collision margin. With a footprint, the
            distance every pose of the path keeps from the obstacles.
        simplify: Shortcut and smooth the path with OMPL's simplifier. Off by default: the
            paper's point is that the MPC does not need a smoothed path.
        footprint: The robot's convex polygon in its own frame, ((x, y), ...), x forward
            (Nav2's ``footprint``; its string form, a list of pairs or a polygon `Footprint`
            are accepted and stored as a tuple, so the config stays hashable). Empty: a
            circle of robot_radius. A polygon takes precedence over robot_radius, as in Nav2.
        start_clearance: With a footprint, the distance every pose of a plan keeps from the
            obstacles the local controller holds, when a plan is given them
            (``local_obstacles``: the MPC's convex pieces, near the robot), metres; a start
            already closer keeps what it has (`held_checks`). Those pieces may reach
            farther than the planner's grid (a rectangle along a row of cylinders covers the
            hollows between them), and a turn the grid allows but they do not is one the
            controller cannot make: the robot stood there, re-planned the same way at every
            attempt.
        drive_on_heading_distance: With a footprint and ``local_obstacles``, how far a plan
            may first drive straight on a heading the start's turns allow, to where the
            robot can turn, when no plan leaves the start otherwise (Nav2's DriveOnHeading
            behaviour, planned and checked as part of the path), metres; 0 = never. A
            forward-only robot whose start allows no turn towards the way out goes on to
            where it can turn. (Without them a re-plan escapes as before: `replan`.)

    """

    iterations: int = 1000
    time_limit: float = 5.0
    seed: int = 0
    range: float = 0.0
    robot_radius: float = 0.0
    clearance: float = 0.1
    simplify: bool = False
    footprint: tuple[tuple[float, float], ...] = ()
    start_clearance: float = 0.01
    drive_on_heading_distance: float = 1.0

    def __post_init__(self) -> None:
        """Refuse settings that OMPL would misread or silently ignore."""
        problems = []
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int):
            problems.append(f'iterations must be an integer, got {self.iterations!r}')
        elif self.iterations < 1:
            problems.append(f'iterations must be >= 1, got {self.iterations}')
        if not (math.isfinite(self.time_limit) and self.time_limit > 0):
            problems.append(f'time_limit must be > 0 and finite, got {self.time_limit}')
        if not (isinstance(self.seed, int) and 0 <= self.seed <= MAX_SEED):
            problems.append(f'seed must be an integer in [0, {MAX_SEED}], got {self.seed!r}')
        for name in ('range', 'robot_radius', 'clearance', 'start_clearance',
                     'drive_on_heading_distance'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                problems.append(f'{name} must be >= 0 and finite, got {value}')
        try:
            object.__setattr__(self, 'footprint', _footprint_vertices(self.footprint))
        except (TypeError, ValueError) as err:
            problems.append(f'footprint must be a convex polygon [[x, y], ...] or empty: {err}')
        if problems:
            msg = 'invalid PlannerConfig: ' + '; '.join(problems)
            raise ValueError(msg)

    @property
    def robot_footprint(self) -> Footprint:
        """The robot the planner plans for: the polygon, or a circle of robot_radius."""
        return parse_footprint(self.footprint, self.robot_radius)

    @property
    def inflation(self) -> float:
        """Distance by which the planner grows the obstacles where the robot may turn, metres.

        robot_radius + clearance for a circle; for a polygon its circumscribed radius +
        clearance (the disc an intermediate waypoint needs free, and the least inflation of
        the grid `RrtStarPlanner.on_grid` accepts).
        """
        if self.footprint:
            return self.robot_footprint.radius + self.clearance
        return self.robot_radius + self.clearance

    @property
    def inscribed_radius(self) -> float:
        """The largest disc about the robot's origin inside its footprint, metres.

        What a re-plan that starts from a robot inside the inflation keeps from the
        obstacles on its first, short segment (PlanningGrid.escape_point). For a polygon,
        its faces' distances from the origin (Footprint.body, unit rows).
        """
        footprint = self.robot_footprint
        if footprint.is_circle:
            return footprint.radius
        return float(np.min(footprint.body.b))
