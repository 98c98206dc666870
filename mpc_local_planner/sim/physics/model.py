# SPDX-License-Identifier: Apache-2.0
"""The MJCF of a wheeled robot in a world, written in code (no files to ship).

The world's obstacles are static geoms of the world body (circles as cylinders, convex
polygons as prisms: convex meshes), 1 m tall, in geom group 0; the floor is a plane in
group 2; the robot's geoms are in group 1, so a ray cast over group 0 sees obstacles only.
Contacts are filtered by bits: the wheels touch only the floor, the robot's bumper (its
footprint as a prism, 0.03-0.35 m above the ground) touches only the obstacles. So the
engine's contacts are those of the footprint the suites judge, and a wheel's sphere never
catches on a cylinder outside it. A moving obstacle is a mocap body (its shape in its own
frame, in the same group and with the same contact bits), which the plant places where its
trajectory is at each engine step: the laser sees it and the bumper meets it, and it pushes
the robot, never the other way round. Each wheel is a sphere on a hinge with a velocity servo
whose force is limited to the robot's torque; casters are frictionless spheres.
"""

from __future__ import annotations

import math
from typing import Sequence, TYPE_CHECKING
from xml.sax.saxutils import quoteattr

import numpy as np

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.sim.physics.robots import WheeledRobot
from mpc_local_planner.worlds.world import Circle

if TYPE_CHECKING:
    from mpc_local_planner.worlds.motion import MovingObstacle
    from mpc_local_planner.worlds.world import Shape

__all__ = ['BUMPER', 'LASER_HEIGHT', 'MOVING_BODY', 'OBSTACLE_GROUP', 'OBSTACLE_HEIGHT',
           'TIMESTEP', 'WHEEL_JOINTS', 'robot_mjcf']

#: The engine's time step (s): the wheel contacts stay stable and a 100 s run takes ~1 s.
TIMESTEP = 0.002
#: Height of every obstacle (m) and of the laser above the ground.
OBSTACLE_HEIGHT = 1.0
LASER_HEIGHT = 0.2
#: The geom group the laser's rays see.
OBSTACLE_GROUP = 0
#: The bumper's bottom and top above the ground (m).
BUMPER = (0.03, 0.35)
#: The wheels' joint names: (side, index) -> name; side 0 left, 1 right.
WHEEL_JOINTS = 'wheel_{side}_{index}'
#: The mocap bodies of the moving obstacles, by index.
MOVING_BODY = 'moving_{index}'
# Contact bits: wheels and floor share bit 1, bumper and obstacles bit 2.
_FLOOR_BIT, _BUMPER_BIT = 1, 2


def _numbers(values: Sequence[float]) -> str:
    return ' '.join(f'{float(v):.9g}' for v in values)


def _prism(vertices: np.ndarray, bottom: float, top: float) -> str:
    """Return the vertex attribute of a convex prism over a polygon's vertices."""
    points = [(x, y, z) for z in (bottom, top) for x, y in np.asarray(vertices, dtype=float)]
    return _numbers([c for point in points for c in point])


def _obstacles(shapes: Sequence[Shape], name: str = 'obstacle') -> tuple[list[str], list[str]]:
    """Return the assets and the geoms of obstacles (named name_i), in their frame."""
    assets: list[str] = []
    geoms: list[str] = []
    half = 0.5 * OBSTACLE_HEIGHT
    common = (f'group="{OBSTACLE_GROUP}" contype="{_BUMPER_BIT}" '
              f'conaffinity="{_BUMPER_BIT}" rgba="0.5 0.5 0.5 1"')
    for i, shape in enumerate(shapes):
        if isinstance(shape, Circle):
            geoms.append(f'<geom name="{name}_{i}" type="cylinder" '
                         f'size="{_numbers([shape.radius, half])}" '
                         f'pos="{_numbers([shape.x, shape.y, half])}" {common}/>')
        else:
            assets.append(f'<mesh name="{name}_{i}" '
                          f'vertex="{_prism(shape.vertices, 0.0, OBSTACLE_HEIGHT)}"/>')
            geoms.append(f'<geom name="{name}_{i}" type="mesh" mesh="{name}_{i}" '
                         f'{common}/>')
    return assets, geoms


def _bumper(footprint: Footprint, robot: WheeledRobot) -> tuple[list[str], str]:
    """Return the asset and the geom of the robot's bumper: its footprint as a prism."""
    bottom = BUMPER[0] - robot.base_height
    top = BUMPER[1] - robot.base_height
    common = (f'group="1" contype="{_BUMPER_BIT}" conaffinity="{_BUMPER_BIT}" '
              f'rgba="0.8 0.7 0.1 0.5"')
    if footprint.is_circle:
        radius = max(footprint.radius, robot.track / 2)
        return [], (f'<geom name="bumper" type="cylinder" '
                    f'size="{_numbers([radius, 0.5 * (top - bottom)])}" '
                    f'pos="0 0 {0.5 * (top + bottom):.9g}" {common}/>')
    mesh = f'<mesh name="bumper" vertex="{_prism(footprint.vertices, bottom, top)}"/>'
    return [mesh], f'<geom name="bumper" type="mesh" mesh="bumper" {common}/>'


def robot_mjcf(robot: WheeledRobot, footprint: Footprint, shapes: Sequence[Shape],
               pose: Sequence[float], moving: Sequence[MovingObstacle] = ()) -> str:
    """Return the MJCF of robot (its bumper the footprint) at pose among the shapes.

    Args:
        robot: The robot's body, wheels and servos.
        footprint: Its shape in the plane (the bumper that touches obstacles).
        shapes: The world's obstacles (static).
        pose: The start pose (x, y, theta).
        moving: The world's moving obstacles: mocap bodies MOVING_BODY, where they are at
            t = 0.

    """
    x, y, theta = (float(v) for v in pose[:3])
    assets, geoms = _obstacles(shapes)
    moving_assets, moving_geoms = _obstacles([m.shape for m in moving], 'moving')
    assets += moving_assets
    for index, (obstacle, geom) in enumerate(zip(moving, moving_geoms, strict=True)):
        where = _numbers([*obstacle.position(0.0), 0.0])
        geoms.append(f'<body name="{MOVING_BODY.format(index=index)}" mocap="true" '
                     f'pos="{where}">{geom}</body>')
    bumper_assets, bumper = _bumper(footprint, robot)
    assets += bumper_assets
    wheels: list[str] = []
    actuators: list[str] = []
    r = robot.wheel_radius
    for side, sign in ((0, 1.0), (1, -1.0)):
        for index, wx in enumerate(robot.wheel_x):
            name = WHEEL_JOINTS.format(side=side, index=index)
            where = _numbers([wx, sign * robot.track / 2, robot.wheel_z])
            wheels.append(
                f'<body name="{name}" pos="{where}">'
                f'<inertial pos="0 0 0" mass="{robot.wheel_mass:.9g}" '
                f'diaginertia="{_numbers(robot.wheel_inertia)}"/>'
                f'<joint name="{name}" type="hinge" axis="0 1 0" damping="0.001" '
                f'armature="{robot.armature:.9g}"/>'
                f'<geom type="sphere" size="{r:.9g}" group="1" contype="{_FLOOR_BIT}" '
                f'conaffinity="0" friction="{robot.friction:.9g} 0.005 0.0001" '
                f'rgba="0.1 0.1 0.1 1"/></body>')
            actuators.append(
                f'<velocity name="{name}" joint="{name}" kv="{robot.servo_gain:.9g}" '
                f'forcelimited="true" forcerange="{-robot.torque:.9g} {robot.torque:.9g}"/>')
    for k, (cx, radius) in enumerate(robot.casters):
        wheels.append(
            f'<geom name="caster_{k}" type="sphere" size="{radius:.9g}" '
            f'pos="{_numbers([cx, 0.0, radius - robot.base_height])}" group="1" '
            f'contype="{_FLOOR_BIT}" conaffinity="0" condim="1" friction="0 0 0" mass="0"/>')
    quat = _numbers([math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2)])
    return f"""<mujoco model={quoteattr(robot.name)}>
<compiler angle="radian"/>
<option timestep="{TIMESTEP}" integrator="implicitfast" cone="elliptic"/>
<asset>{''.join(assets)}</asset>
<worldbody>
<geom name="floor" type="plane" size="0 0 1" group="2" contype="{_FLOOR_BIT}"
 conaffinity="{_FLOOR_BIT}" friction="{robot.friction:.9g} 0.005 0.0001"/>
{''.join(geoms)}
<body name="base_link" pos="{_numbers([x, y, robot.base_height])}" quat="{quat}">
<freejoint name="base"/>
<inertial pos="{_numbers(robot.centre_of_mass)}" mass="{robot.mass:.9g}"
 diaginertia="{_numbers(robot.inertia)}"/>
{bumper}
{''.join(wheels)}
</body>
</worldbody>
<actuator>{''.join(actuators)}</actuator>
</mujoco>"""
