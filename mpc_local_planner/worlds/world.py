# SPDX-License-Identifier: Apache-2.0
"""Worlds: the scenario a run happens in (bounds, obstacles, start, goal).

Two formats feed the same `World` record so that the planner, the MPC, the nodes and the
experiments never care where a scenario came from:

- YAML (``config/worlds/*.yaml``), the package's own format: boxes, polygons and circles.
- BARN JSON (Perille et al. 2020, as converted under ``data/barn``): cylinders of one radius,
  approximated by circumscribed octagons so that avoiding the polygon avoids the cylinder.

The robot's shape is either ``robot_radius`` (a round robot) or ``footprint`` (a convex polygon
in the robot frame, x forward: a list of [x, y] or Nav2's string form ``"[[x, y], ...]"``). A
file gives one or the other, never both: Nav2 silently ignores robot_radius when a footprint is
set, and a world file that says two things about the robot's size is more likely a mistake than
an intention. With a polygon, `World.robot_radius` is its circumscribed radius (the disk that
covers the robot), so that code which only knows disks stays on the safe side.

A world may also hold ``unknown_obstacles``: things that exist in the simulated world (the
laser sees them, the robot can hit them) but in no map and in no node's prior knowledge, so
that perception has something to discover. ``World.true_shapes`` keeps the exact geometry of
everything physically present (circles as `Circle`, not as their octagons) for the simulated
laser and the contact check, which must not inherit the planner's conservative approximation.

A world may also hold ``moving_obstacles``: circles and convex polygons, each in its own frame,
carried along a trajectory (worlds/motion.py: constant velocity reflected off a box,
waypoints with speeds, a sinusoid). Like unknown obstacles they are in no map and in no node's
prior knowledge; the simulated laser and the contact check see them where they are at the
time asked (`World.shapes_at`).

Everything is validated on load. A malformed world fails here, with the file and the field in
the message, instead of as a NaN deep inside a solver.
"""

from __future__ import annotations

from dataclasses import dataclass
import json
import math
from pathlib import Path
from typing import Any, NamedTuple, NoReturn

import numpy as np
import yaml

from mpc_local_planner.core.errors import WorldError
from mpc_local_planner.core.footprint import Footprint, parse_footprint
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.worlds.motion import MovingObstacle, parse_trajectory, TRAJECTORY_KINDS

__all__ = [
    'BARN_MARGIN',
    'BARN_ROBOT_RADIUS',
    'Circle',
    'Shape',
    'World',
    'load_barn_world',
    'load_world',
    'paper_world',
    'world_from_dict',
]

#: Margin (metres) added around the cylinders, start and goal to make a BARN world's bounds.
BARN_MARGIN = 1.0
#: The round robot a BARN world assumes when neither robot_radius nor footprint is given.
BARN_ROBOT_RADIUS = 0.2

_YAML_KEYS = frozenset(
    {
        'bounds',
        'obstacles',
        'start',
        'goal',
        'robot_radius',
        'footprint',
        'path',
        'goal_tolerance',
        'time_limit',
        'name',
        'description',
        'unknown_obstacles',
        'moving_obstacles',
    }
)
_BARN_KEYS = ('cylinder_radius', 'cylinders', 'start', 'goal')

# The paper's scenario; config/worlds/paper_obstacle.yaml holds the same numbers (a test checks).
# The start and goal headings are those of p(s) = [2.5 s, 1.1 sin(pi s)] at s = 0 and s = 1, so
# that the robot starts on the path's steady-state manifold (the MPC's initial guess is feasible).
_PAPER_HEADING = math.atan(1.1 * math.pi / 2.5)
_PAPER_WORLD = {
    'bounds': [-0.5, 3.0, -1.5, 1.8],
    'obstacles': [{'box': [1.0, -1.0, 1.5, 1.0]}],
    'start': [0.0, 0.0, _PAPER_HEADING],
    'goal': [2.5, 0.0, -_PAPER_HEADING],
    'path': 'paper_sinusoid',
    'robot_radius': 0.0,
}


class Circle(NamedTuple):
    """A disk, kept exactly: a BARN cylinder or a world file's ``circle``.

    The obstacles the MPC sees are polygons circumscribed about it; the simulated laser and
    the contact check use the disk itself, so the robot is not blamed for touching corners
    that do not exist.
    """

    x: float
    y: float
    radius: float


#: The exact geometry of one physical obstacle: a convex polygon or a disk.
Shape = ConvexPolygon | Circle


@dataclass(frozen=True, eq=False)
class World:
    """A scenario: where the robot may go, what it must avoid, where it starts and ends.

    ``eq=False`` because the fields hold NumPy arrays, whose ``==`` is element-wise; worlds
    compare by identity. The arrays are read-only, in the spirit of ``frozen``.

    Attributes:
        name: Short name (the file's stem for loaded worlds).
        bounds: (xmin, xmax, ymin, ymax) of the workspace, metres.
        obstacles: The obstacles as described, NOT inflated: inflation depends on who asks
            (the planner adds a clearance, the MPC a collision margin).
        start: (3,) start pose x, y, theta.
        goal: (3,) goal pose x, y, theta.
        robot_radius: Radius of the disk that covers the robot, metres: the circle's radius,
            or the polygon footprint's circumscribed radius (derived from ``footprint``).
        path: Name of an analytic reference path (e.g. ``'paper_sinusoid'``), or None when the
            path comes from the global planner.
        goal_tolerance: Distance to the goal that counts as arrival, when the world sets one.
        time_limit: Time budget of a run in seconds, when the world sets one.
        unknown_obstacles: Obstacles that exist (laser, contacts) but are in no map and in no
            node's prior knowledge; as polygons, circles circumscribed like ``obstacles``.
        true_shapes: The exact geometry of every physical obstacle, known and unknown (disks
            as `Circle`). Empty means the polygons themselves are exact; use `physical_shapes`.
            It describes the world, not a representation of it, so replacing ``obstacles`` by
            a merged or simplified set leaves it valid.
        footprint: The robot's true shape, what contacts and clearances are measured from.
            None when constructing means a circle of ``robot_radius``; after construction it is
            always a `Footprint`. A polygon sets ``robot_radius`` to its circumscribed radius
            (a different nonzero robot_radius is refused: the two would disagree).
        moving_obstacles: Obstacles that move (worlds/motion.py), exact shapes in their own
            frames; like unknown ones they are in no map. Not in ``true_shapes``: where they
            are depends on the time (`shapes_at`).

    """

    name: str
    bounds: tuple[float, float, float, float]
    obstacles: tuple[ConvexPolygon, ...]
    start: np.ndarray
    goal: np.ndarray
    robot_radius: float = 0.0
    path: str | None = None
    goal_tolerance: float | None = None
    time_limit: float | None = None
    unknown_obstacles: tuple[ConvexPolygon, ...] = ()
    true_shapes: tuple[Shape, ...] = ()
    footprint: Footprint | None = None
    moving_obstacles: tuple[MovingObstacle, ...] = ()

    def __post_init__(self) -> None:
        """Make ``footprint`` and ``robot_radius`` describe the same robot.

        One source of truth for the robot's size: consumers that only know disks read
        robot_radius, the exact checks read footprint, and they must not disagree.

        Raises:
            ValueError: A footprint whose radius contradicts a nonzero robot_radius.

        """
        footprint = self.footprint
        if footprint is None:
            object.__setattr__(self, 'footprint', Footprint.circle(self.robot_radius))
            return
        if self.robot_radius not in (0.0, footprint.radius):
            msg = (f'robot_radius {self.robot_radius:g} contradicts the footprint, whose '
                   f'covering radius is {footprint.radius:g}; give only the footprint')
            raise ValueError(msg)
        object.__setattr__(self, 'robot_radius', float(footprint.radius))

    def physical_shapes(self) -> tuple[Shape, ...]:
        """Return the exact shapes of everything the laser sees and the robot can touch.

        ``true_shapes`` when the world has them, else the known and unknown polygons (a world
        built in code from polygons only).
        """
        if self.true_shapes:
            return self.true_shapes
        return tuple(self.obstacles) + tuple(self.unknown_obstacles)

    def shapes_at(self, t: float) -> tuple[Shape, ...]:
        """Return the exact shapes of everything physically present at time t (seconds).

        The static ones (`physical_shapes`), then each moving obstacle where it is at t.
        """
        return self.physical_shapes() + tuple(m.shape_at(t) for m in self.moving_obstacles)

    def inflated_obstacles(self, extra: float = 0.0) -> tuple[ConvexPolygon, ...]:
        """Return the obstacles inflated by the robot radius plus extra (metres)."""
        return tuple(obstacle.inflate(self.robot_radius + extra) for obstacle in self.obstacles)

    def in_bounds(self, point: np.ndarray) -> bool:
        """Say whether the (x, y) of point lies inside the bounds (boundary included)."""
        xmin, xmax, ymin, ymax = self.bounds
        return bool(xmin <= point[0] <= xmax and ymin <= point[1] <= ymax)


def load_world(path: str | Path) -> World:
    """Load a world file, choosing the format by suffix.

    Args:
        path: A ``.yaml``/``.yml`` file in the package's format or a ``.json`` BARN world.

    Returns:
        The validated world, named after the file's stem.

    Raises:
        FileNotFoundError: If the file does not exist.
        WorldError: If the file is malformed or its suffix is unknown.

    """
    path = Path(path)
    if not path.is_file():
        msg = f'world file not found: {path}'
        raise FileNotFoundError(msg)
    suffix = path.suffix.lower()
    if suffix == '.json':
        return load_barn_world(path)
    if suffix not in ('.yaml', '.yml'):
        msg = f'{path}: unknown world format {suffix!r} (expected .yaml, .yml or .json)'
        raise WorldError(msg)
    try:
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        msg = f'{path}: not valid YAML: {err}'
        raise WorldError(msg) from err
    return world_from_dict(data, name=path.stem, source=str(path))


def world_from_dict(data: Any, *, name: str, source: str | None = None) -> World:
    """Build a world from the YAML format's mapping (see the module docstring).

    Args:
        data: The parsed mapping with ``bounds``, ``obstacles``, ``start``, ``goal`` and the
            optional ``path``, ``robot_radius`` or ``footprint`` (not both),
            ``goal_tolerance``, ``time_limit``, ``unknown_obstacles``, ``moving_obstacles``.
        name: Name of the world.
        source: Where the data came from, for error messages (defaults to the name).

    Returns:
        The validated world.

    Raises:
        WorldError: Naming the source and the field, if anything is missing or malformed.

    """
    where = source if source is not None else name
    if not isinstance(data, dict):
        _fail(where, f'a world must be a mapping, got {type(data).__name__}')
    unknown = sorted(str(key) for key in set(data) - _YAML_KEYS)
    if unknown:
        _fail(where, f'unknown key(s) {unknown}; allowed: {sorted(_YAML_KEYS)}')
    for key in ('bounds', 'start', 'goal'):
        if key not in data:
            _fail(where, f'missing required key {key!r}')

    bounds = _bounds(data['bounds'], where)
    obstacles, known_shapes = _obstacles(data.get('obstacles') or [], where)
    unknown_obstacles, unknown_shapes = _obstacles(
        data.get('unknown_obstacles') or [], where, key='unknown_obstacles'
    )
    moving = _moving_obstacles(data.get('moving_obstacles') or [], bounds, where)
    start = _vector(data['start'], 3, 'start', where)
    goal = _vector(data['goal'], 3, 'goal', where)
    robot_radius = _number(data.get('robot_radius', 0.0), 'robot_radius', where, minimum=0.0)
    footprint = _footprint(data.get('footprint'), where)
    if footprint is not None and 'robot_radius' in data:
        _fail(where, 'give either robot_radius (a round robot) or footprint (a polygon, whose '
                     'covering radius is derived), not both')
    path = data.get('path')
    if path is not None and (not isinstance(path, str) or not path):
        _fail(where, f'path must be the name of an analytic path, got {path!r}')
    goal_tolerance = _optional_positive(data.get('goal_tolerance'), 'goal_tolerance', where)
    time_limit = _optional_positive(data.get('time_limit'), 'time_limit', where)
    return _make_world(
        name=name,
        where=where,
        bounds=bounds,
        obstacles=obstacles,
        start=start,
        goal=goal,
        robot_radius=robot_radius,
        footprint=footprint,
        path=path,
        goal_tolerance=goal_tolerance,
        time_limit=time_limit,
        unknown_obstacles=unknown_obstacles,
        true_shapes=known_shapes + unknown_shapes,
        moving_obstacles=moving,
    )


def load_barn_world(path: str | Path, *, robot_radius: float | None = None, sides: int = 8,
                    footprint: Footprint | None = None) -> World:
    """Load a BARN world converted to JSON.

    Cylinders become regular polygons circumscribed about them (conservative: outside the
    polygon means outside the cylinder). The goal heading, absent from BARN, is the heading
    from start to goal: BARN only scores reaching the goal position, and this choice makes the
    straight-line steady state a sensible default. Bounds are the bounding box of the
    cylinders, start and goal grown by `BARN_MARGIN`.

    Args:
        path: The ``world_NNN.json`` file.
        robot_radius: Radius of a round robot (BARN's Jackal: about 0.2 to 0.33 m); None
            means `BARN_ROBOT_RADIUS` unless a footprint is given.
        sides: Number of sides of the polygon that replaces each cylinder.
        footprint: The robot's true shape (e.g. `JACKAL`, as the challenge scores contacts);
            exclusive with robot_radius, like the YAML keys.

    Returns:
        The validated world, named after the file's stem, with the file's goal tolerance and
        time limit.

    Raises:
        FileNotFoundError: If the file does not exist.
        WorldError: If the file is malformed, or both robot_radius and footprint are given.

    """
    path = Path(path)
    where = str(path)
    if footprint is not None and robot_radius is not None:
        _fail(where, 'give either robot_radius or footprint, not both')
    if not path.is_file():
        msg = f'world file not found: {path}'
        raise FileNotFoundError(msg)
    try:
        data = json.loads(path.read_text(encoding='utf-8'))
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        msg = f'{where}: not valid JSON: {err}'
        raise WorldError(msg) from err
    if not isinstance(data, dict):
        _fail(where, f'a BARN world must be a JSON object, got {type(data).__name__}')
    for key in _BARN_KEYS:
        if key not in data:
            _fail(where, f'missing required key {key!r}')
    if not isinstance(sides, int) or sides < 3:
        _fail(where, f'sides must be an integer >= 3, got {sides!r}')
    radius = _number(data['cylinder_radius'], 'cylinder_radius', where, minimum=0.0)
    if radius == 0.0:
        _fail(where, 'cylinder_radius must be > 0')
    if footprint is None:
        radius_given = BARN_ROBOT_RADIUS if robot_radius is None else robot_radius
        robot_radius = _number(radius_given, 'robot_radius', where, minimum=0.0)
    else:
        robot_radius = footprint.radius
    cylinders = data['cylinders']
    if not isinstance(cylinders, list):
        _fail(where, f'cylinders must be a list of [x, y], got {type(cylinders).__name__}')
    centres = np.array(
        [_vector(c, 2, f'cylinders[{i}]', where) for i, c in enumerate(cylinders)]
    ).reshape(-1, 2)
    start = _vector(data['start'], 3, 'start', where)
    goal_xy = _vector(data['goal'], 2, 'goal', where)
    heading = math.atan2(goal_xy[1] - start[1], goal_xy[0] - start[0])
    goal = np.array([goal_xy[0], goal_xy[1], heading])

    points = np.vstack([centres - radius, centres + radius, start[None, :2], goal_xy[None, :]])
    lo = points.min(axis=0) - BARN_MARGIN
    hi = points.max(axis=0) + BARN_MARGIN
    bounds = (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))
    obstacles = tuple(
        ConvexPolygon.from_circle(float(x), float(y), radius, sides=sides) for x, y in centres
    )
    cylinders_exact = tuple(Circle(float(x), float(y), radius) for x, y in centres)
    return _make_world(
        name=path.stem,
        where=where,
        bounds=bounds,
        obstacles=obstacles,
        start=start,
        goal=goal,
        robot_radius=robot_radius,
        footprint=footprint,
        path=None,
        goal_tolerance=_optional_positive(data.get('goal_tolerance'), 'goal_tolerance', where),
        time_limit=_optional_positive(data.get('time_limit_s'), 'time_limit_s', where),
        true_shapes=cylinders_exact,
    )


def paper_world() -> World:
    """Return the paper's scenario: one box between start and target on a sinusoidal path.

    The same world as ``config/worlds/paper_obstacle.yaml``, built in code so that tests and
    benchmarks need no installed data files.
    """
    return world_from_dict(_PAPER_WORLD, name='paper_obstacle', source='paper_world()')


def _make_world(*, name: str, where: str, **fields: Any) -> World:
    """Check the cross-field rules (start and goal inside the bounds and free), then build."""
    world = World(name=name, **fields)
    for label in ('start', 'goal'):
        pose = getattr(world, label)
        pose.setflags(write=False)
        if not world.in_bounds(pose):
            _fail(
                where,
                f'{label} ({pose[0]:g}, {pose[1]:g}) is outside the bounds {world.bounds}',
            )
        for index, obstacle in enumerate(world.obstacles):
            if bool(obstacle.contains(pose[:2])[0]):
                _fail(where, f'{label} ({pose[0]:g}, {pose[1]:g}) is inside obstacle {index}')
        for index, obstacle in enumerate(world.unknown_obstacles):
            if bool(obstacle.contains(pose[:2])[0]):
                _fail(
                    where,
                    f'{label} ({pose[0]:g}, {pose[1]:g}) is inside unknown obstacle {index}',
                )
        if label == 'start':
            for index, moving in enumerate(world.moving_obstacles):
                if _shape_contains(moving.shape_at(0.0), pose[:2]):
                    _fail(where, f'start ({pose[0]:g}, {pose[1]:g}) is inside moving '
                                 f'obstacle {index} at t = 0')
    return world


def _shape_contains(shape: Shape, point: np.ndarray) -> bool:
    """Say whether the point lies in the shape (boundary included)."""
    if isinstance(shape, ConvexPolygon):
        return bool(shape.contains(point)[0])
    return math.hypot(point[0] - shape.x, point[1] - shape.y) <= shape.radius


def _fail(where: str, problem: str) -> NoReturn:
    """Raise the WorldError for a problem found in where (a file name or a world name)."""
    msg = f'{where}: {problem}'
    raise WorldError(msg)


def _number(value: Any, what: str, where: str, *, minimum: float | None = None) -> float:
    """Return value as a finite float, refusing bools, strings and None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        _fail(where, f'{what} must be a number, got {value!r}')
    number = float(value)
    if not math.isfinite(number):
        _fail(where, f'{what} must be finite, got {value!r}')
    if minimum is not None and number < minimum:
        _fail(where, f'{what} must be >= {minimum:g}, got {number:g}')
    return number


def _optional_positive(value: Any, what: str, where: str) -> float | None:
    """Return None for a missing value, else a finite float > 0."""
    if value is None:
        return None
    number = _number(value, what, where)
    if number <= 0.0:
        _fail(where, f'{what} must be > 0, got {number:g}')
    return number


def _vector(value: Any, length: int, what: str, where: str) -> np.ndarray:
    """Return value as a finite float vector of the given length."""
    if not isinstance(value, (list, tuple)) or len(value) != length:
        _fail(where, f'{what} must be a list of {length} numbers, got {value!r}')
    return np.array([_number(v, f'{what}[{i}]', where) for i, v in enumerate(value)])


def _bounds(value: Any, where: str) -> tuple[float, float, float, float]:
    """Return [xmin, xmax, ymin, ymax] as a tuple, checking that the box is not empty."""
    xmin, xmax, ymin, ymax = (float(v) for v in _vector(value, 4, 'bounds', where))
    if not (xmin < xmax and ymin < ymax):
        _fail(where, f'bounds must be [xmin, xmax, ymin, ymax] with min < max, got {value!r}')
    return (xmin, xmax, ymin, ymax)


def _footprint(value: Any, where: str) -> Footprint | None:
    """Parse ``footprint``: a list of [x, y] or Nav2's string ``"[[x, y], ...]"``.

    Returns None for a missing or empty footprint (``[]``, ``''``, ``'[]'``, as Nav2 reads
    them): the robot is then the circle of robot_radius.
    """
    if value is None:
        return None
    if not isinstance(value, (str, list)):
        _fail(where, f'footprint must be a list of [x, y] or a string "[[x, y], ...]", '
                     f'got {value!r}')
    if isinstance(value, list):  # checked like every other list of numbers in a world
        value = [_vector(v, 2, f'footprint[{i}]', where).tolist() for i, v in enumerate(value)]
    try:
        footprint = parse_footprint(value)
    except ValueError as err:
        problem = str(err)
    else:
        return None if footprint.is_circle else footprint
    _fail(where, f'footprint: {problem}')


def _circle_or_polygon(kind: str, spec: Any, label: str, where: str
                       ) -> tuple[ConvexPolygon, Shape]:
    """Return a circle's or a polygon's planning polygon and exact shape.

    The polygon a circle is planned with is circumscribed; a polygon is its own shape. label
    names the item in messages (``obstacles[3]``, ``moving_obstacles[0].polygon``). A
    ConvexPolygon's own refusal (a ValueError) is the caller's to place.
    """
    if kind == 'circle':
        x, y, r = _vector(spec, 3, label, where)
        return ConvexPolygon.from_circle(x, y, r), Circle(float(x), float(y), float(r))
    if not isinstance(spec, list) or len(spec) < 3:
        _fail(where, f'{label}: a polygon needs a list of >= 3 [x, y], got {spec!r}')
    polygon = ConvexPolygon.from_vertices(
        [_vector(v, 2, f'{label}[{i}]', where) for i, v in enumerate(spec)])
    return polygon, polygon


def _obstacles(
    value: Any, where: str, *, key: str = 'obstacles'
) -> tuple[tuple[ConvexPolygon, ...], tuple[Shape, ...]]:
    """Parse an obstacle list: each item is one of {box: ...}, {polygon: ...}, {circle: ...}.

    Returns the polygons (circles circumscribed) and, in the same order, the exact shapes.
    """
    if not isinstance(value, list):
        _fail(where, f'{key} must be a list, got {type(value).__name__}')
    obstacles: list[ConvexPolygon] = []
    shapes: list[Shape] = []
    for index, item in enumerate(value):
        what = f'{key}[{index}]'
        if not isinstance(item, dict) or len(item) != 1:
            _fail(where, f'{what} must have exactly one key (box, polygon or circle): {item!r}')
        kind, spec = next(iter(item.items()))
        try:
            if kind == 'box':
                obstacles.append(ConvexPolygon.from_box(*_vector(spec, 4, what, where)))
                shapes.append(obstacles[-1])
            elif kind in ('circle', 'polygon'):
                polygon, shape = _circle_or_polygon(kind, spec, what, where)
                obstacles.append(polygon)
                shapes.append(shape)
            else:
                _fail(where, f'{what}: unknown obstacle kind {kind!r} (box, polygon or circle)')
        except WorldError:
            raise
        except ValueError as err:
            msg = f'{where}: {what}: {err}'
            raise WorldError(msg) from None
    return tuple(obstacles), tuple(shapes)


def _moving_obstacles(value: Any, bounds: tuple[float, float, float, float],
                      where: str) -> tuple[MovingObstacle, ...]:
    """Parse ``moving_obstacles``: each a shape (circle or polygon) and one trajectory.

    The shape is in the obstacle's own frame; the trajectory (worlds/motion.py) moves that
    frame's origin. Problems name the entry (``moving_obstacles[i]``) and the key.
    """
    if not isinstance(value, list):
        _fail(where, f'moving_obstacles must be a list, got {type(value).__name__}')
    moving: list[MovingObstacle] = []
    for index, item in enumerate(value):
        what = f'moving_obstacles[{index}]'
        if not isinstance(item, dict):
            _fail(where, f'{what} must be a mapping with a shape (circle or polygon) and a '
                         f'trajectory ({", ".join(TRAJECTORY_KINDS)}), got {item!r}')
        extra = sorted(str(k) for k in set(item) - {'circle', 'polygon', *TRAJECTORY_KINDS})
        if extra:
            _fail(where, f'{what}: unknown key(s) {extra}; a shape (circle or polygon) and a '
                         f'trajectory ({", ".join(TRAJECTORY_KINDS)})')
        shapes = [k for k in ('circle', 'polygon') if k in item]
        kinds = [k for k in TRAJECTORY_KINDS if k in item]
        if len(shapes) != 1:
            _fail(where, f'{what} needs exactly one shape, circle or polygon, got {shapes}')
        if len(kinds) != 1:
            _fail(where, f'{what} needs exactly one trajectory '
                         f'({", ".join(TRAJECTORY_KINDS)}), got {kinds}')
        try:
            # a static obstacle's checks; the circle's planning polygon is not kept
            _, shape = _circle_or_polygon(shapes[0], item[shapes[0]], f'{what}.{shapes[0]}',
                                          where)
        except ValueError as err:
            if isinstance(err, WorldError):
                raise
            msg = f'{where}: {what}.{shapes[0]}: {err}'
            raise WorldError(msg) from None
        try:
            trajectory = parse_trajectory(kinds[0], item[kinds[0]], shape, bounds)
        except ValueError as err:
            msg = f'{where}: {what}: {err}'
            raise WorldError(msg) from None
        moving.append(MovingObstacle(shape, trajectory))
    return tuple(moving)
