# SPDX-License-Identifier: Apache-2.0
"""Moving obstacles: a shape in its own frame carried along a trajectory in closed form.

A moving obstacle is a circle or a convex polygon written in its own frame (``circle:
[0, 0, r]`` is a disk centred on the frame's origin) and a trajectory that says where that
origin is at time t, one of:

- `ConstantVelocity`: from ``start`` at ``velocity``, reflected off the sides of a box (the
  world's bounds unless the entry gives its own) so that the whole shape stays inside;
- `Waypoints`: along a polyline at a speed per segment, round a ``loop`` or
  ``back_and_forth``;
- `Sinusoid`: ``centre + amplitude sin(2 pi t / period + phase)``.

Every position is a closed-form function of t alone (the reflections are folds of the
straight motion, not integrated bounces), so the simulator node, which asks at its ticks,
and the ROS-free rollout, which asks at its steps, get the same shape at the same t to the
last digit, whatever their step sizes.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, NamedTuple, Protocol

import numpy as np

from mpc_local_planner.core.obstacles import ConvexPolygon

__all__ = [
    'ConstantVelocity',
    'MovingObstacle',
    'Sinusoid',
    'TRAJECTORY_KINDS',
    'Trajectory',
    'Waypoints',
    'parse_trajectory',
    'shape_extent',
]

#: The trajectory keys of a ``moving_obstacles`` entry.
TRAJECTORY_KINDS = ('constant_velocity', 'waypoints', 'sinusoid')
#: The ways round a waypoint polyline.
WAYPOINT_MODES = ('loop', 'back_and_forth')


class Disk(Protocol):
    """What a moving disk needs of worlds/world.py's `Circle` (world.py imports this module)."""

    x: float
    y: float
    radius: float

    def _replace(self, **fields: float) -> Disk: ...


#: A shape in its own frame: a convex polygon or a `Circle`.
Shape = ConvexPolygon | Disk


@dataclass(frozen=True, eq=False)
class ConstantVelocity:
    """Straight motion at a constant velocity, reflected off the sides of a box.

    Per axis the reference point moves in [low, high] (the box shrunk by the shape's extent,
    so the shape touches a side when it turns): the straight motion folded into that interval
    is a triangle wave, exact at any t. An axis with no room (low == high) keeps still.

    Attributes:
        start: (2,) the frame's origin at t = 0.
        velocity: (2,) its velocity until the first reflection, m/s.
        low: (2,) the smallest x and y the origin reaches.
        high: (2,) the largest.
        box: (xmin, xmax, ymin, ymax) the shape bounces in, as the world file gave it.

    """

    start: np.ndarray
    velocity: np.ndarray
    low: np.ndarray
    high: np.ndarray
    box: tuple[float, float, float, float]

    def spec(self) -> tuple[str, dict[str, Any]]:
        """Return the world file's key and mapping that describe this trajectory."""
        return 'constant_velocity', {'start': self.start.tolist(),
                                     'velocity': self.velocity.tolist(),
                                     'bounds': [float(v) for v in self.box]}

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Return the origin's position and velocity at time t."""
        position = np.empty(2)
        velocity = np.empty(2)
        for axis in range(2):
            lo, hi = float(self.low[axis]), float(self.high[axis])
            v, span = float(self.velocity[axis]), hi - lo
            if v == 0.0 or span <= 0.0:
                position[axis], velocity[axis] = float(self.start[axis]), 0.0
                continue
            u = (float(self.start[axis]) - lo + v * t) % (2.0 * span)
            position[axis] = lo + (u if u <= span else 2.0 * span - u)
            velocity[axis] = v if u < span else -v
        return position, velocity


@dataclass(frozen=True, eq=False)
class Waypoints:
    """Along a polyline at a speed per segment, round a loop or back and forth.

    Attributes:
        points: (n, 2) the corners, in the order first travelled.
        speeds: (m,) the speed on each segment of one lap (a loop closes with the segment
            from the last point to the first; back and forth runs the segments forward,
            then backward at the same speeds).
        mode: ``loop`` or ``back_and_forth``.

    """

    points: np.ndarray
    speeds: np.ndarray
    mode: str

    def spec(self) -> tuple[str, dict[str, Any]]:
        """Return the world file's key and mapping that describe this trajectory."""
        return 'waypoints', {'points': self.points.tolist(), 'speed': self.speeds.tolist(),
                             'mode': self.mode}

    def _lap(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the lap's segment starts, ends and cumulative start times."""
        points = self.points
        if self.mode == 'loop':
            starts, ends, speeds = points, np.roll(points, -1, axis=0), self.speeds
        else:
            starts = np.vstack([points[:-1], points[:0:-1]])
            ends = np.vstack([points[1:], points[-2::-1]])
            speeds = np.concatenate([self.speeds, self.speeds[::-1]])
        durations = np.hypot(*(ends - starts).T) / speeds
        return starts, ends, np.concatenate([[0.0], np.cumsum(durations)])

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Return the origin's position and velocity at time t (periodic in the lap)."""
        starts, ends, times = self._lap()
        tau = float(t) % float(times[-1])
        segment = min(int(np.searchsorted(times, tau, side='right')) - 1, len(starts) - 1)
        duration = times[segment + 1] - times[segment]
        fraction = (tau - times[segment]) / duration
        delta = ends[segment] - starts[segment]
        return starts[segment] + fraction * delta, delta / duration


@dataclass(frozen=True, eq=False)
class Sinusoid:
    """``centre + amplitude * sin(2 pi t / period + phase)``.

    Attributes:
        centre: (2,) the middle of the swing.
        amplitude: (2,) the largest displacement from it (a direction and a length).
        period: seconds per swing there and back.
        phase: radians at t = 0.

    """

    centre: np.ndarray
    amplitude: np.ndarray
    period: float
    phase: float

    def spec(self) -> tuple[str, dict[str, Any]]:
        """Return the world file's key and mapping that describe this trajectory."""
        return 'sinusoid', {'centre': self.centre.tolist(),
                            'amplitude': self.amplitude.tolist(),
                            'period': float(self.period), 'phase': float(self.phase)}

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Return the origin's position and velocity at time t."""
        omega = 2.0 * math.pi / self.period
        angle = omega * float(t) + self.phase
        return (self.centre + self.amplitude * math.sin(angle),
                self.amplitude * omega * math.cos(angle))


Trajectory = ConstantVelocity | Waypoints | Sinusoid


class MovingObstacle(NamedTuple):
    """A shape in its own frame and the trajectory of that frame's origin.

    Attributes:
        shape: A `Circle` or `ConvexPolygon` around the frame's origin.
        trajectory: Where the origin is at time t.

    """

    shape: Shape
    trajectory: Trajectory

    def position(self, t: float) -> np.ndarray:
        """Return the frame's origin at time t (seconds of simulated time)."""
        return self.trajectory.state(t)[0]

    def velocity(self, t: float) -> np.ndarray:
        """Return the obstacle's velocity at time t (it translates, never turns)."""
        return self.trajectory.state(t)[1]

    def shape_at(self, t: float) -> Shape:
        """Return the shape where it is at time t, in the world frame."""
        dx, dy = (float(v) for v in self.position(t))
        shape = self.shape
        if isinstance(shape, ConvexPolygon):
            offset = np.array([dx, dy])
            return ConvexPolygon(A=shape.A, b=shape.b + shape.A @ offset,
                                 vertices=shape.vertices + offset)
        return shape._replace(x=shape.x + dx, y=shape.y + dy)


def shape_extent(shape: Shape) -> tuple[np.ndarray, np.ndarray]:
    """Return the lowest and highest (x, y) of a shape in its own frame."""
    if isinstance(shape, ConvexPolygon):
        return shape.vertices.min(axis=0), shape.vertices.max(axis=0)
    centre = np.array([shape.x, shape.y])
    return centre - shape.radius, centre + shape.radius


def parse_trajectory(kind: str, spec: Any, shape: Shape,
                     bounds: tuple[float, float, float, float]) -> Trajectory:
    """Return the trajectory a world entry describes, checked.

    Args:
        kind: One of `TRAJECTORY_KINDS`.
        spec: Its mapping (see the module docstring and docs/usage.md for the keys).
        shape: The obstacle's shape in its own frame (a reflection keeps all of it inside).
        bounds: The world's (xmin, xmax, ymin, ymax), the default box of reflections.

    Returns:
        The trajectory.

    Raises:
        ValueError: Naming the key and what is wrong with it.

    """
    if kind not in TRAJECTORY_KINDS:
        msg = f'unknown trajectory {kind!r} (one of {", ".join(TRAJECTORY_KINDS)})'
        raise ValueError(msg)
    parse = {'constant_velocity': _constant_velocity, 'waypoints': _waypoints,
             'sinusoid': _sinusoid}[kind]
    allowed = {'constant_velocity': ('start', 'velocity', 'bounds'),
               'waypoints': ('points', 'speed', 'mode'),
               'sinusoid': ('centre', 'amplitude', 'period', 'phase')}[kind]
    if not isinstance(spec, dict):
        msg = f'{kind} must be a mapping with keys {", ".join(allowed)}, got {spec!r}'
        raise ValueError(msg)
    unknown = sorted(str(key) for key in set(spec) - set(allowed))
    if unknown:
        msg = f'{kind}: unknown key(s) {unknown}; allowed: {list(allowed)}'
        raise ValueError(msg)
    return parse(spec, shape, bounds)


def _required(spec: dict[str, Any], key: str, kind: str) -> Any:
    if key not in spec:
        msg = f'{kind}: missing required key {key!r}'
        raise ValueError(msg)
    return spec[key]


def _number(value: Any, what: str) -> float:
    """Return value as a finite float (no bools, strings or None)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(float(value)):
        msg = f'{what} must be a finite number, got {value!r}'
        raise ValueError(msg)
    return float(value)


def _vector(value: Any, length: int, what: str) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or len(value) != length:
        msg = f'{what} must be a list of {length} numbers, got {value!r}'
        raise ValueError(msg)
    return np.array([_number(v, f'{what}[{i}]') for i, v in enumerate(value)])


def _constant_velocity(spec: dict[str, Any], shape: Shape,
                       bounds: tuple[float, float, float, float]) -> ConstantVelocity:
    start = _vector(_required(spec, 'start', 'constant_velocity'), 2,
                    'constant_velocity.start')
    velocity = _vector(_required(spec, 'velocity', 'constant_velocity'), 2,
                       'constant_velocity.velocity')
    box = spec.get('bounds', list(bounds))
    xmin, xmax, ymin, ymax = (float(v) for v in _vector(box, 4, 'constant_velocity.bounds'))
    if not (xmin < xmax and ymin < ymax):
        msg = (f'constant_velocity.bounds must be [xmin, xmax, ymin, ymax] with min < max, '
               f'got {box!r}')
        raise ValueError(msg)
    lowest, highest = shape_extent(shape)
    low = np.array([xmin, ymin]) - lowest
    high = np.array([xmax, ymax]) - highest
    if np.any(low > high) or np.any(start < low - 1e-12) or np.any(start > high + 1e-12):
        msg = (f'the shape at start {start.tolist()} must lie inside the box it bounces in, '
               f'[xmin, xmax, ymin, ymax] = {[xmin, xmax, ymin, ymax]}')
        raise ValueError(msg)
    return ConstantVelocity(start=start, velocity=velocity, low=low, high=high,
                            box=(xmin, xmax, ymin, ymax))


def _waypoints(spec: dict[str, Any], shape: Shape,
               bounds: tuple[float, float, float, float]) -> Waypoints:
    del shape, bounds  # the polyline says where the obstacle goes, wherever that is
    raw = _required(spec, 'points', 'waypoints')
    if not isinstance(raw, list) or len(raw) < 2:
        msg = f'waypoints.points must be a list of >= 2 [x, y], got {raw!r}'
        raise ValueError(msg)
    points = np.array([_vector(p, 2, f'waypoints.points[{i}]') for i, p in enumerate(raw)])
    mode = spec.get('mode', 'loop')
    if mode not in WAYPOINT_MODES:
        msg = f'waypoints.mode must be one of {", ".join(WAYPOINT_MODES)}, got {mode!r}'
        raise ValueError(msg)
    ends = np.roll(points, -1, axis=0) if mode == 'loop' else points[1:]
    lengths = np.hypot(*(ends - points[:len(ends)]).T)
    if np.any(lengths == 0.0):
        index = int(np.argmax(lengths == 0.0))
        following = (index + 1) % len(points)
        msg = (f'waypoints.points[{index}] and [{following}] are the same point: a segment '
               f'needs a length' + (' (a loop closes itself: do not repeat the first point)'
                                    if mode == 'loop' and following == 0 else ''))
        raise ValueError(msg)
    speed = _required(spec, 'speed', 'waypoints')
    if isinstance(speed, list):
        if len(speed) != len(lengths):
            msg = (f'waypoints.speed: a list needs one speed per segment ({len(lengths)} for '
                   f'{len(points)} points, {mode}), got {len(speed)}')
            raise ValueError(msg)
        speeds = np.array([_number(s, f'waypoints.speed[{i}]') for i, s in enumerate(speed)])
    else:
        speeds = np.full(len(lengths), _number(speed, 'waypoints.speed'))
    if np.any(speeds <= 0.0):
        msg = f'waypoints.speed must be > 0 (m/s), got {speed!r}'
        raise ValueError(msg)
    return Waypoints(points=points, speeds=speeds, mode=str(mode))


def _sinusoid(spec: dict[str, Any], shape: Shape,
              bounds: tuple[float, float, float, float]) -> Sinusoid:
    del shape, bounds
    centre = _vector(_required(spec, 'centre', 'sinusoid'), 2, 'sinusoid.centre')
    amplitude = _vector(_required(spec, 'amplitude', 'sinusoid'), 2, 'sinusoid.amplitude')
    period = _number(_required(spec, 'period', 'sinusoid'), 'sinusoid.period')
    if period <= 0.0:
        msg = f'sinusoid.period must be > 0 (s), got {period:g}'
        raise ValueError(msg)
    phase = _number(spec.get('phase', 0.0), 'sinusoid.phase')
    return Sinusoid(centre=centre, amplitude=amplitude, period=period, phase=phase)
