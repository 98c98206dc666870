# SPDX-License-Identifier: Apache-2.0
"""The rigid-body plant (MuJoCo, the optional ``[physics]`` extra) and how to ask for it.

`robots` (the Jackal and the paper's small robot, with their sources), `drive` (the base
controller and wheel odometry as diff_drive_controller has them), `model` (the MJCF written
in code), `laser` (the engine's ray-cast laser) and `plant` (`PhysicsBase`, stepped like
sim/base.py's `Base`). Only `laser` and `plant` import mujoco; `make_plant` imports them when
asked, and says how to install the extra when it is missing.
"""

from __future__ import annotations

import importlib.util
from typing import Any, Sequence, TYPE_CHECKING

from mpc_local_planner.sim.physics.robots import physics_robot, PHYSICS_ROBOTS

if TYPE_CHECKING:
    from mpc_local_planner.core.footprint import Footprint
    from mpc_local_planner.core.models import Unicycle
    from mpc_local_planner.sim.reality import Reality
    from mpc_local_planner.worlds.motion import MovingObstacle
    from mpc_local_planner.worlds.world import Shape

__all__ = ['ODOMETRY_SOURCES', 'PHYSICS_ROBOTS', 'PLANTS', 'make_physics_base', 'mujoco_missing',
           'physics_robot']

#: The plants a simulation can run on: the kinematic `Base` (the default) or MuJoCo's.
PLANTS = ('kinematic', 'mujoco')
#: What the physics plant's odometry integrates (plant.py; kept here, where MuJoCo is not
#: imported): wheels and gyro fused, as the robots ship, or the wheels alone.
ODOMETRY_SOURCES = ('fused', 'wheels')


def mujoco_missing() -> str | None:
    """Return why the MuJoCo plant cannot run here, or None when it can."""
    if importlib.util.find_spec('mujoco') is None:
        return ("the mujoco plant needs MuJoCo, which is not installed: "
                "pip install 'mpc_local_planner[physics]' (or pip install 'mujoco>=3,<4')")
    return None


def make_physics_base(model: Unicycle, reality: Reality, pose: Sequence[float], *,
                      robot: str = 'jackal', footprint: Footprint | None = None,
                      shapes: Sequence[Shape] = (), dt: float = 0.01,
                      odometry: str = 'fused',
                      moving: Sequence[MovingObstacle] = ()) -> Any:
    """Return a `plant.PhysicsBase` (arguments as its own).

    Raises:
        RuntimeError: when MuJoCo is not installed (the message says how to install it).
        ValueError: for an unknown robot, a bad pose or an unknown odometry source.

    """
    problem = mujoco_missing()
    if problem is not None:
        raise RuntimeError(problem)
    from mpc_local_planner.sim.physics.plant import PhysicsBase

    return PhysicsBase(model, reality, pose, robot=robot, footprint=footprint,
                       shapes=shapes, dt=dt, odometry=odometry, moving=moving)
