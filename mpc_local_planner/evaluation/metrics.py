# SPDX-License-Identifier: Apache-2.0
"""Metrics of a closed-loop run, computed from its trajectory rows alone.

Computing them from rows (not from live objects) lets the experiments, closed_loop and
analyze_bag (which only has a bag) report the same numbers the same way.

Clearance is measured from the robot's footprint: a circle of ``robot_radius`` (the numbers
this module always gave, conventions included), or a convex polygon at each row's pose
(x, y, theta), whose exact signed distance to the true shapes is what the BARN challenge's
"no contact of the true footprint" is about (`footprint_clearance`).
"""

from __future__ import annotations

import math
from typing import Any, Callable, Sequence

import numpy as np

from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.mpc import LyapunovCase
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import wrap_angle
from mpc_local_planner.evaluation.trajectory import TRAJECTORY_INDEX as COL
from mpc_local_planner.perception.raycast import TrueGeometry
from mpc_local_planner.sim.contact import footprint_distances
from mpc_local_planner.worlds.world import Circle, Shape

__all__ = ['PoseClearance', 'arrivals', 'compute_metrics', 'footprint_clearance',
           'reached_mask', 'travelled']

#: poses (n, 3) [x, y, theta] -> clearance (n,) in metres; <= 0 is contact.
PoseClearance = Callable[[np.ndarray], np.ndarray]


def footprint_clearance(shapes: Sequence[Shape], footprint: Footprint) -> PoseClearance:
    """Return poses (n, 3) -> clearance of the footprint from the shapes (m; <= 0: contact).

    A circle footprint keeps the rollout's conventions exactly (``polygon_clearance`` and
    ``circle_clearance`` of evaluation/rollout.py, so switching to this function changes no
    result): from a polygon, the centre's distance minus the radius, and -1 - radius when
    the centre is inside; from a disk, the centres' distance minus both radii. A polygon
    footprint gives the exact signed distance at the pose's heading (minus the penetration
    depth when overlapping). No shapes: inf.

    Args:
        shapes: The true obstacles (`ConvexPolygon` and `Circle`, e.g.
            ``world.physical_shapes()``), not inflated.
        footprint: The robot's shape.

    Returns:
        The clearance function; a circle footprint also accepts (n, 2) points.

    """
    shapes = tuple(shapes)
    if footprint.is_circle:
        polygons = tuple(s for s in shapes if isinstance(s, ConvexPolygon))
        circles = np.array([tuple(s) for s in shapes if isinstance(s, Circle)],
                           dtype=float).reshape(-1, 3)
        radius = footprint.radius

        def circle_clearance(poses: np.ndarray) -> np.ndarray:
            points = np.atleast_2d(np.asarray(poses, dtype=float))[:, :2]
            result = np.full(len(points), math.inf)
            if polygons:
                result = np.minimum(result, _circle_polygon_clearance(polygons, points, radius))
            if len(circles):
                d = np.linalg.norm(points[:, None, :] - circles[None, :, :2], axis=2)
                result = np.minimum(result, np.min(d - (circles[None, :, 2] + radius), axis=1))
            return result
        return circle_clearance
    geometry = TrueGeometry(shapes)

    def polygon_clearance(poses: np.ndarray) -> np.ndarray:
        return footprint_distances(geometry, footprint, poses)
    return polygon_clearance


def _circle_polygon_clearance(obstacles: Sequence[ConvexPolygon], points: np.ndarray,
                              robot_radius: float) -> np.ndarray:
    """Return the round robot's clearance from polygons (-1 - radius with the centre inside).

    The expression compute_metrics has always used, kept as it was so circle results stay
    identical to the last bit.
    """
    distances = np.min(np.stack([o.distance(points) for o in obstacles]), axis=0)
    inside = np.zeros(len(points), dtype=bool)
    for o in obstacles:
        inside |= o.contains(points)
    return np.where(inside, -1.0, distances) - robot_radius



def reached_mask(
    rows: np.ndarray, goal: np.ndarray, *, position_tolerance: float, heading_tolerance: float
) -> np.ndarray:
    """Say, per row, whether the pose is within the tolerances of the goal."""
    rows = np.atleast_2d(rows)
    pos_err = np.hypot(rows[:, COL['x']] - goal[0], rows[:, COL['y']] - goal[1])
    head_err = np.abs(wrap_angle(rows[:, COL['theta']] - goal[2]))
    return (pos_err <= position_tolerance) & (head_err <= heading_tolerance)


def _lyapunov_by_case(lyapunov_ok: Sequence[bool | None],
                      cases: Sequence[LyapunovCase | None]
                      ) -> dict[str, dict[str, int]] | None:
    """Return {case: {'checks': n, 'violations': m}} over the checked steps (None: unknown).

    Checks without a case (a recording from before cases were reported) are left out.
    """
    if len(cases) != len(lyapunov_ok) or not any(case is not None for case in cases):
        return None
    counts: dict[str, dict[str, int]] = {}
    for flag, case in zip(lyapunov_ok, cases, strict=True):
        if flag is None or case is None:
            continue
        entry = counts.setdefault(LyapunovCase(case).value, {'checks': 0, 'violations': 0})
        entry['checks'] += 1
        entry['violations'] += int(not flag)
    return counts


def arrivals(rows: np.ndarray, goal: np.ndarray, settings: ControllerSettings) -> np.ndarray:
    """Say, per row, whether the controller would have declared arrival by then.

    The controller's own rule (ControllerSettings.goal_check) over the rows' poses, for a
    recording without the controller's verdict: with settings.stateful the position once met
    stays met, and arrival once declared stays (until a new plan, which rows do not show).
    """
    rows = np.atleast_2d(rows)
    position = np.hypot(rows[:, COL['x']] - goal[0], rows[:, COL['y']] - goal[1])
    heading = np.abs(wrap_angle(rows[:, COL['theta']] - goal[2]))
    arrived = np.zeros(len(rows), dtype=bool)
    met = done = False
    for i in range(len(rows)):
        met, now = settings.goal_check(float(position[i]), float(heading[i]), position_met=met)
        done = now or (settings.stateful and done)
        arrived[i] = done
    return arrived


def travelled(speed: np.ndarray, start: float, end: float) -> float:
    """Return the distance (m) that speeds held from their times cover from start to end.

    Args:
        speed: (m, 2) times (s, increasing) and forward speeds (m/s); each holds until the
            next time, the last one until then only.
        start: from this time.
        end: to this time.

    """
    speed = np.asarray(speed, dtype=float).reshape(-1, 2)
    t, v = speed[:, 0], np.abs(speed[:, 1])
    lo = np.clip(t[:-1], start, end)
    hi = np.clip(t[1:], start, end)
    return float(np.sum(v[:-1] * (hi - lo)))


def _arrival_row(arrived: np.ndarray) -> int | None:
    """Return the row from which the run stays arrived to its end (None: not arrived then)."""
    if not len(arrived) or not arrived[-1]:
        return None
    away = np.flatnonzero(~arrived)
    return int(away[-1]) + 1 if len(away) else 0


def _finite_stats(values: np.ndarray) -> tuple[float | None, float | None, float | None]:
    """Return median, p95 and max of the finite values (None when there are none: JSON)."""
    values = values[np.isfinite(values)]
    if len(values) == 0:
        return None, None, None
    return (float(np.median(values)), float(np.percentile(values, 95)), float(np.max(values)))


def compute_metrics(
    rows: np.ndarray,
    *,
    goal: np.ndarray,
    obstacles: Sequence[Shape],
    robot_radius: float = 0.0,
    footprint: Footprint | None = None,
    reference_length: float | None = None,
    solver_failures: int = 0,
    lyapunov_ok: Sequence[bool | None] = (),
    lyapunov_cases: Sequence[LyapunovCase | None] = (),
    position_tolerance: float = 0.05,
    heading_tolerance: float = 0.1,
    arrived: Sequence[bool] | np.ndarray | None = None,
    odometry_speed: np.ndarray | None = None,
) -> dict[str, Any]:
    """Return the run's metrics (arrival, errors, length, clearance, V_N, timing) as a dict.

    Args:
        rows: (n, 9) trajectory rows (t, x, y, theta, v, omega, s, V_N, solve_ms).
        goal: target pose (x, y, theta).
        obstacles: the obstacles as described (not inflated): polygons, and `Circle`s for
            exact disks (e.g. ``world.physical_shapes()``).
        robot_radius: clearance is measured from the robot's circle, not its centre.
        footprint: the robot's shape, replacing robot_radius (a polygon is placed at each
            row's x, y, theta); see `footprint_clearance` for what the clearance means.
        reference_length: length of the reference path, reported beside the run's own.
        solver_failures: steps without a verified solver solution.
        lyapunov_ok: per step, whether V_N decreased as the theorem says (None: no check).
        lyapunov_cases: per step as lyapunov_ok (or empty: not known), whether the theorem
            covers the check (LyapunovCase.COVERED: a violation there is a defect) or what
            changed; counted by case in lyapunov_by_case.
        position_tolerance: metres, for "reached" (without arrived).
        heading_tolerance: radians, for "reached" (without arrived).
        arrived: per row, whether the run had arrived by then (the controller's verdict,
            or `arrivals`); None: the pose within the tolerances (reached_mask). The run has
            reached the target if its last row has arrived; time_to_target and path_length
            run to the row from which it stays arrived.
        odometry_speed: (m, 2) times (the rows' clock) and forward speeds the base measured
            (odometry's twist), each held until the next; given, path_length is their
            integral over the rows' time (to the arrival), not the polyline through the rows'
            positions, whose noise it would count (path_length_source says which).

    Raises:
        ValueError: robot_radius is neither 0 nor the footprint's covering radius (as in
            `World`, where robot_radius is derived from a footprint): which one counts
            would be a guess.
            Or arrived is not one flag per row.

    """
    if footprint is not None and robot_radius not in (0.0, footprint.radius):
        msg = (f'robot_radius {robot_radius:g} contradicts the footprint (covering radius '
               f'{footprint.radius:g}); give only the footprint')
        raise ValueError(msg)
    robot = footprint if footprint is not None else Footprint.circle(robot_radius)
    rows = np.atleast_2d(np.asarray(rows, dtype=float))
    goal = np.asarray(goal, dtype=float)
    if rows.size == 0:
        return {'steps': 0, 'reached': False, 'collision': False}
    xy = rows[:, [COL['x'], COL['y']]]
    final = rows[-1]
    final_pos_err = float(math.hypot(final[COL['x']] - goal[0], final[COL['y']] - goal[1]))
    final_head_err = float(abs(wrap_angle(final[COL['theta']] - goal[2])))
    if arrived is None:
        reached_rows = reached_mask(rows, goal, position_tolerance=position_tolerance,
                                    heading_tolerance=heading_tolerance)
    else:
        reached_rows = np.asarray(arrived, dtype=bool).reshape(-1)
        if len(reached_rows) != len(rows):
            msg = f'arrived has {len(reached_rows)} entries for {len(rows)} rows'
            raise ValueError(msg)
    first = _arrival_row(reached_rows)
    reached = first is not None
    time_to_target = float(rows[first, COL['t']] - rows[0, COL['t']]) if first is not None \
        else None
    end = (first + 1) if first is not None else len(rows)
    if odometry_speed is not None and len(odometry_speed) > 1:
        path_length = travelled(odometry_speed, float(rows[0, COL['t']]),
                                float(rows[end - 1, COL['t']]))
        path_length_source = 'odometry speed'
    else:
        path_length = float(np.sum(np.linalg.norm(np.diff(xy[:end], axis=0), axis=1)))
        path_length_source = 'positions'
    if obstacles:
        poses = rows[:, [COL['x'], COL['y'], COL['theta']]]
        min_clearance = float(np.min(footprint_clearance(obstacles, robot)(poses)))
        # a centre inside a polygon has clearance -1 - radius < 0: no separate test needed
        collision = bool(min_clearance < 0)
    else:
        min_clearance, collision = math.inf, False
    median, p95, worst = _finite_stats(rows[:, COL['solve_ms']])
    checks = [flag for flag in lyapunov_ok if flag is not None]
    violations = int(sum(1 for flag in checks if not flag))
    by_case = _lyapunov_by_case(lyapunov_ok, lyapunov_cases)
    return {
        'steps': int(len(rows)),
        'reached': reached,
        'collision': collision,
        'final_position_error': final_pos_err,
        'final_heading_error': final_head_err,
        'time_to_target': time_to_target,
        'path_length': path_length,
        'path_length_source': path_length_source,
        'reference_length': reference_length,
        'min_clearance': min_clearance if math.isfinite(min_clearance) else None,
        'solve_ms_median': median,
        'solve_ms_p95': p95,
        'solve_ms_max': worst,
        'lyapunov_checks': len(checks),
        'lyapunov_violations': violations,
        'lyapunov_nonincreasing': violations == 0,
        'lyapunov_by_case': by_case,
        'lyapunov_covered_violations': (
            by_case.get(LyapunovCase.COVERED.value, {}).get('violations', 0)
            if by_case is not None else None),
        'solver_failures': int(solver_failures),
        'position_tolerance': position_tolerance if arrived is None else None,
        'heading_tolerance': heading_tolerance if arrived is None else None,
    }
