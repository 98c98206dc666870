# SPDX-License-Identifier: Apache-2.0
"""The local controllers by name: one factory each, building a `LocalController`.

The suites, the experiments and the navigator name a controller (`ControllerName`, the
names of runs.csv's ``controller`` column) and get it from `build_controller`, with how far
obstacles can matter to its next command (`Built.reach`, what the navigator hands it). Every
factory reads what it needs from one `ControllerSetup`: the robot's model and footprint, the
MPCs' config and the paper's controller settings, the world's goal tolerance, and the base's
control period and acceleration limits when the robot is a real one.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import Enum
import math
from typing import Callable, NamedTuple

from mpc_local_planner.core.baselines.dwa import Dwa, DwaConfig
from mpc_local_planner.core.baselines.pure_pursuit import PurePursuit, PurePursuitConfig
from mpc_local_planner.core.baselines.tracking_mpc import TrackingMPC
from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.local_controller import LocalController
from mpc_local_planner.core.models import Unicycle

__all__ = [
    'build_controller',
    'Built',
    'controller_name',
    'ControllerName',
    'ControllerSetup',
    'FACTORIES',
    'FOLLOWER_ARRIVAL',
]

# The path followers stop within this of the plan's end (metres), or within half the world's
# goal tolerance where that is less, so that they arrive wherever the run counts as arrived.
FOLLOWER_ARRIVAL = 0.03


class ControllerName(str, Enum):
    """A local controller's name (its value is runs.csv's and the command line's word)."""

    PROPOSED = 'proposed'  # the paper's MPC (MpcController)
    TRACKING = 'tracking'  # Limon et al.'s tracking MPC: it tracks the plan's end
    PURE_PURSUIT = 'pure_pursuit'  # classic pure pursuit, blind to obstacles
    DWA = 'dwa'  # the dynamic window approach (ROS's DWB)
    REGULATED_PURE_PURSUIT = 'regulated_pure_pursuit'  # Nav2's RPP

    def __str__(self) -> str:
        """Return the name itself (a row, an f-string and a file name read the word)."""
        return self.value


@dataclass(frozen=True)
class ControllerSetup:
    """What the factories build a controller from.

    Attributes:
        model: The robot's model (its speed limits bound every controller's commands).
        footprint: The robot's true footprint (the DWA's and RPP's collision checks).
        config: The MPCs' settings (the paper's and the tracking MPC's).
        settings: The paper's controller settings (arrival, braking, hold).
        goal_tolerance: The world's goal tolerance, metres: the path followers stop within
            min(FOLLOWER_ARRIVAL, goal_tolerance / 2) of the plan's end.
        control_period: A real base's control period, seconds: the DWA's window is the
            accelerations over it (None: the DWA's default).
        acceleration: A real base's (linear, angular) acceleration limits: the DWA's
            (a non-finite one leaves the DWA's default; None: both defaults).

    """

    model: Unicycle
    footprint: Footprint
    config: MpcConfig = MpcConfig()
    settings: ControllerSettings = ControllerSettings()
    goal_tolerance: float = 2.0 * FOLLOWER_ARRIVAL
    control_period: float | None = None
    acceleration: tuple[float, float] | None = None

    @property
    def arrival(self) -> float:
        """How close to the plan's end the path followers stop, metres."""
        return min(FOLLOWER_ARRIVAL, 0.5 * self.goal_tolerance)


class Built(NamedTuple):
    """A controller and how far from the robot obstacles can matter to its next command.

    Attributes:
        controller: The controller.
        reach: Metres; 0 for a controller that ignores obstacles (the navigator still
            assembles the obstacles within its reach for the re-planner).

    """

    controller: LocalController
    reach: float


def _proposed(setup: ControllerSetup) -> Built:
    controller = MpcController(setup.model, setup.config, settings=setup.settings)
    return Built(controller, setup.config.reach(float(setup.model.u_max[0])))


def _tracking(setup: ControllerSetup) -> Built:
    return Built(TrackingMPC(setup.model, setup.config),
                 setup.config.reach(float(setup.model.u_max[0])))


def _pure_pursuit(setup: ControllerSetup) -> Built:
    config = PurePursuitConfig(v_max=setup.model.v_max, omega_max=setup.model.omega_max,
                               goal_tolerance=setup.arrival)
    return Built(PurePursuit(config=config), 0.0)


def _regulated_pure_pursuit(setup: ControllerSetup) -> Built:
    config = PurePursuitConfig.regulated(setup.model.v_max, setup.model.omega_max,
                                         footprint=setup.footprint,
                                         goal_tolerance=setup.arrival)
    # as a user configures RPP: its collision check sees the local costmap's obstacles (the
    # sensed ones, as the DWA and the MPC get them), its lookahead the measured speed
    reach = (min(setup.model.v_max * config.collision_time, config.max_lookahead)
             + setup.footprint.radius)
    return Built(PurePursuit(config=config), reach)


def _dwa(setup: ControllerSetup) -> Built:
    config = DwaConfig(max_vel_x=setup.model.v_max, max_vel_theta=setup.model.omega_max,
                       footprint=setup.footprint, xy_goal_tolerance=setup.arrival)
    # as a user configures DWB for a robot: its control rate and its limits
    if setup.control_period is not None:
        config = replace(config, control_period=setup.control_period)
    if setup.acceleration is not None:
        linear, angular = setup.acceleration
        if math.isfinite(linear):
            config = replace(config, acc_lim_x=linear, decel_lim_x=linear)
        if math.isfinite(angular):
            config = replace(config, acc_lim_theta=angular)
    reach = (setup.model.v_max * config.sim_time + setup.footprint.radius
             + config.inflation_radius)
    return Built(Dwa(config=config), reach)


FACTORIES: dict[ControllerName, Callable[[ControllerSetup], Built]] = {
    ControllerName.PROPOSED: _proposed,
    ControllerName.TRACKING: _tracking,
    ControllerName.PURE_PURSUIT: _pure_pursuit,
    ControllerName.DWA: _dwa,
    ControllerName.REGULATED_PURE_PURSUIT: _regulated_pure_pursuit,
}


def controller_name(name: ControllerName | str) -> ControllerName:
    """Return the ControllerName of a name.

    Raises:
        ValueError: for a name that is not one.

    """
    try:
        return ControllerName(name)
    except ValueError:
        known = ', '.join(n.value for n in ControllerName)
        msg = f'unknown controller {str(name)!r} (known: {known})'
        raise ValueError(msg) from None


def build_controller(name: ControllerName | str, setup: ControllerSetup) -> Built:
    """Return the named controller built for setup, with its reach.

    Raises:
        ValueError: for a name that is not a ControllerName.

    """
    return FACTORIES[controller_name(name)](setup)
