# SPDX-License-Identifier: Apache-2.0
"""A waypoint path checked pose by pose for a polygon footprint.

The path as core/paths.py's WaypointPath makes it: straight segments driven at their heading
and turns in place at the start, at each corner and at the goal. `footprint_path_problem` is
the planner's final check of a whole path; `footprint_motion` is the same rule one motion at
a time, as the grid search's `pull_string` asks it. Both use core/footprint_checks.py's
queries (the swept polygon, the sampled turns), so a path the planner's motions accepted
passes the final check. NumPy only.
"""

from __future__ import annotations

from collections.abc import Callable
import math

import numpy as np

from mpc_local_planner.core.footprint_checks import (
    FootprintChecks,
    FootprintPlan,
    NO_TURN,
    SAME_POINT,
    wrap_heading,
)

__all__ = ['footprint_motion', 'footprint_path_problem', 'xy_text']


class _TurnCheck:
    """The turns in place at one corner from one heading, found lazily, as `TurnRange` does.

    `FootprintChecks.turn_range` allows delta iff no sampled heading k turn_step away on
    delta's side, with (k - 1/2) turn_step < |delta|, is in collision: only those samples are
    checked, and each side's samples once (a small turn at a tight corner costs a few
    polygons, not a full circle).
    """

    def __init__(self, checks: FootprintChecks, xy: np.ndarray, heading: float) -> None:
        self._checks = checks
        self._xy = xy
        self._heading = heading
        self._free = checks.state_free(xy)
        self._clear = [0, 0]  # samples known clear per side (counter-clockwise, clockwise)
        self._blocked = [math.inf, math.inf]  # the first sample in collision per side

    def allows(self, delta: float) -> bool:
        """Say whether turning by delta radians (wrapped) is clear."""
        if self._free or abs(delta) <= NO_TURN:
            return True
        checks, side = self._checks, 0 if delta > 0 else 1
        count = min(math.ceil(abs(delta) / checks.turn_step + 0.5), checks.turn_samples + 1)
        if count <= self._clear[side]:
            return True
        if self._blocked[side] < count:
            return False
        steps = np.arange(self._clear[side], max(count, 2 * self._clear[side]))
        steps = steps[steps <= checks.turn_samples]
        headings = self._heading + math.copysign(checks.turn_step, delta) * steps
        c, s = np.cos(headings)[:, None], np.sin(headings)[:, None]
        x, y = checks.local[None, :, 0], checks.local[None, :, 1]
        polygons = np.stack([self._xy[0] + c * x - s * y, self._xy[1] + s * x + c * y],
                            axis=-1)
        hits = np.flatnonzero(checks.obstacles.polygons_hit(polygons, checks.turn_grow) >= 0)
        if len(hits):
            self._blocked[side] = int(steps[hits[0]])
            self._clear[side] = int(steps[hits[0]])
        else:
            self._clear[side] = int(steps[-1]) + 1
        return count <= self._clear[side]


def _distinct(points: np.ndarray) -> np.ndarray:
    """Drop consecutive points within SAME_POINT of the previous one (as WaypointPath)."""
    keep = np.concatenate([[True], np.linalg.norm(np.diff(points, axis=0), axis=1)
                           > SAME_POINT])
    return points[keep]


def xy_text(point: np.ndarray) -> str:
    """Return a point as '(x, y)' for messages."""
    return f'({point[0]:g}, {point[1]:g})'


def footprint_path_problem(checks: FootprintChecks, waypoints: np.ndarray,
                       start_heading: float | None, goal_heading: float | None) -> str | None:
    """Check every pose of a waypoint path for a polygon footprint (see `path_problem`).

    The same queries as the planner's motions (`FootprintPlan`), so a path RRT* built
    passes: segments by the swept polygon, turns by `FootprintChecks.turn_range` (from
    the start heading, from the incoming heading at a corner, and from the goal heading
    backwards at the goal).
    """
    points = _distinct(np.atleast_2d(np.asarray(waypoints, dtype=float))[:, :2])
    if len(points) == 1:  # a turn in place only
        if start_heading is None or goal_heading is None:
            return None
        delta = wrap_heading(goal_heading - start_heading)
        turns = checks.turn_range(points[0], start_heading)
        if turns.allows(delta):
            return None
        return (f'turning in place at {xy_text(points[0])} from heading {start_heading:.3g} to '
                f'{goal_heading:.3g} rad: {turns.why(delta)}')
    # math.atan2, as the planner's motions compute it (bit for bit the same headings)
    headings = [math.atan2(b[1] - a[1], b[0] - a[0])
                for a, b in zip(points[:-1], points[1:], strict=True)]
    if start_heading is not None:
        delta = wrap_heading(headings[0] - start_heading)
        turns = checks.turn_range(points[0], start_heading)
        if not turns.allows(delta):
            return (f'turning in place at the start {xy_text(points[0])} from heading '
                    f'{start_heading:.3g} to {headings[0]:.3g} rad: {turns.why(delta)}')
    for i, (a, b) in enumerate(zip(points[:-1], points[1:], strict=True)):
        hit = checks.sweep_hit(a, b)
        if hit >= 0:
            return (f'segment {i} from {xy_text(a)} to {xy_text(b)}: the footprint driven '
                    f'along it at heading {headings[i]:.3g} rad meets '
                    f'{checks.obstacles.describe(hit)} grown by the clearance '
                    f'{checks.clearance:g} m')
        if i == 0:
            continue
        delta = wrap_heading(headings[i] - headings[i - 1])
        if abs(delta) <= NO_TURN:
            continue
        turns = checks.turn_range(a, headings[i - 1])
        if not turns.allows(delta):
            return (f'turning in place at waypoint {i} {xy_text(a)} from heading '
                    f'{headings[i - 1]:.3g} to {headings[i]:.3g} rad: {turns.why(delta)}')
    if goal_heading is not None:
        delta = wrap_heading(goal_heading - headings[-1])
        turns = checks.turn_range(points[-1], goal_heading)
        if not turns.allows(-delta):
            return (f'turning in place at the goal {xy_text(points[-1])} from heading '
                    f'{headings[-1]:.3g} to the goal heading {goal_heading:.3g} rad: '
                    f'{turns.why(-delta)}')
    return None


def footprint_motion(rules: FootprintPlan,
                      points: np.ndarray) -> Callable[[int, int, int | None], bool]:
    """Return `pull_string`'s motion check for a footprint (`path_problem`'s rules).

    The motion i -> j: the turn in place at i (from the start heading at the start, else
    from the segment into i), the swept footprint, and the turn to the goal heading
    where j is the goal.
    """
    checks, last = rules.checks, len(points) - 1
    turns: dict[tuple[int, int], _TurnCheck] = {}

    def motion_ok(i: int, j: int, previous: int | None) -> bool:
        a, b = points[i], points[j]
        if math.hypot(b[0] - a[0], b[1] - a[1]) <= SAME_POINT:
            return False
        heading = math.atan2(b[1] - a[1], b[0] - a[0])
        if previous is None:
            if (rules.start_turns is not None and rules.start_heading is not None
                    and not rules.start_turns.allows(
                        wrap_heading(heading - rules.start_heading))):
                return False
        else:
            p = points[previous]
            incoming = math.atan2(a[1] - p[1], a[0] - p[0])
            delta = wrap_heading(heading - incoming)
            if abs(delta) > NO_TURN:
                if (previous, i) not in turns:
                    turns[previous, i] = _TurnCheck(checks, a, incoming)
                if not turns[previous, i].allows(delta):
                    return False
        if (j == last and rules.goal_turns is not None and rules.goal_heading is not None
                and not rules.goal_turns.allows(
                    -wrap_heading(rules.goal_heading - heading))):
            return False
        return checks.sweep_hit(a, b) < 0
    return motion_ok
