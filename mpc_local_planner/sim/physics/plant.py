# SPDX-License-Identifier: Apache-2.0
"""The rigid-body plant: a wheeled robot in MuJoCo, stepped as the kinematic `Base` is.

`PhysicsBase` offers `Base`'s calls (command, stop, advance, odometry, twist, pose,
odom_pose, time, velocity, target), so the rollout and the simulator node step it
unchanged. Underneath, a command reaches the robot's base controller (`DiffDrive`, at its
update rate: timeout, limits, wheel speeds), the wheels' servos drive the wheels with
limited torque, the engine moves the body on the floor's friction (the Jackal's four wheels
scrub when it turns) and against the world's obstacles, and odometry is integrated from the
wheels' joint angles (`WheelOdometry`), so it drifts from the TRUE pose (the body's) when
the wheels slip. With ``odometry='fused'`` (the default, as the robots ship: drive.py) the
heading comes from a gyro instead: the body's yaw rate with a constant bias drawn from the
reality's seed (the robot's ``gyro_bias``), so the distance still slips with the wheels.
The world's moving obstacles are mocap bodies placed where their trajectories are at every
engine step (one step at a time then), and at the base's time when `advance` returns, so the
engine's laser sees them where they are. A `Reality`'s command latency and odometry noise
still apply on top; its lag, acceleration limits and odometry drift are the engine's and the
base controller's own here, and are not added.
"""

from __future__ import annotations

import math
from typing import Sequence, TYPE_CHECKING

import mujoco
import numpy as np

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.sim.commands import CommandQueue
from mpc_local_planner.sim.physics import ODOMETRY_SOURCES
from mpc_local_planner.sim.physics.drive import DiffDrive, WheelOdometry
from mpc_local_planner.sim.physics.laser import PhysicsLaser
from mpc_local_planner.sim.physics.model import MOVING_BODY, robot_mjcf, TIMESTEP, WHEEL_JOINTS
from mpc_local_planner.sim.physics.robots import physics_robot, WheeledRobot
from mpc_local_planner.sim.reality import Reality

if TYPE_CHECKING:
    from mpc_local_planner.worlds.motion import MovingObstacle
    from mpc_local_planner.worlds.world import Shape

__all__ = ['PhysicsBase']

# Rounding slack when counting engine steps and update times (s).
_EPS = 1e-9


class PhysicsBase:
    """A wheeled robot simulated by MuJoCo, driven by velocity commands like `Base`.

    Time is the caller's (seconds from 0). The engine steps TIMESTEP; `advance` runs it
    to the step nearest until.

    Args:
        model: The unicycle whose bounds saturate the commands (the node's v_max, omega_max).
        reality: Its command latency and odometry noise apply (see the module docstring).
        pose: The start pose (x, y, theta).
        robot: The robot (`robots.PHYSICS_ROBOTS` or its name).
        footprint: The robot's bumper in the plane (None: a circle around its wheels).
        shapes: The world's obstacles (the true ones: static geoms).
        dt: Kept for `Base`'s interface (the node sets it to its tick); the engine's step
            and the base controller's rate are the robot's.
        odometry: One of ODOMETRY_SOURCES.
        moving: The world's moving obstacles (worlds/motion.py), moved on the caller's time.

    Raises:
        ValueError: for a non-finite pose, an unknown robot name or odometry source.

    """

    def __init__(self, model: Unicycle, reality: Reality, pose: Sequence[float], *,
                 robot: WheeledRobot | str = 'jackal', footprint: Footprint | None = None,
                 shapes: Sequence[Shape] = (), dt: float = 0.01,
                 odometry: str = 'fused', moving: Sequence[MovingObstacle] = ()) -> None:
        start = np.asarray(pose, dtype=float).reshape(-1)[:3]
        if len(start) != 3 or not np.all(np.isfinite(start)):
            msg = f'the start pose must be 3 finite numbers, got {pose!r}'
            raise ValueError(msg)
        if odometry not in ODOMETRY_SOURCES:
            msg = f'odometry must be one of {", ".join(ODOMETRY_SOURCES)}, got {odometry!r}'
            raise ValueError(msg)
        self.robot = physics_robot(robot) if isinstance(robot, str) else robot
        self.model = model
        self.reality = reality
        self.dt = float(dt)
        self.time = 0.0
        self.footprint = footprint or Footprint.circle(0.0)
        self.engine = mujoco.MjModel.from_xml_string(
            robot_mjcf(self.robot, self.footprint, tuple(shapes), start, tuple(moving)))
        self.data = mujoco.MjData(self.engine)
        self._moving = tuple(moving)
        self._mocap = [int(self.engine.body(MOVING_BODY.format(index=i)).mocapid[0])
                       for i in range(len(self._moving))]
        mujoco.mj_forward(self.engine, self.data)
        self.drive = DiffDrive(self.robot.drive)
        self.wheel_odometry = WheelOdometry(self.robot.drive, start)
        self._period = 1.0 / self.robot.drive.update_rate
        self._steps = 0
        self._next_update = 0.0
        self._commands = CommandQueue()
        self._yaw = float(start[2])
        self._rng = np.random.default_rng(reality.seed)
        # the gyro's bias: its own draw, so the odometry noise's sequence is the same either way
        self._gyro_bias = (float(np.random.default_rng([reality.seed, 1]).normal(
            0.0, self.robot.gyro_bias)) if odometry == 'fused' else None)
        self._gyro_yaw = self._yaw
        sides = []
        for side in (0, 1):
            names = [WHEEL_JOINTS.format(side=side, index=i)
                     for i in range(len(self.robot.wheel_x))]
            sides.append(np.array([self.engine.joint(n).qposadr[0] for n in names]))
        self._wheel_qpos = sides
        self._actuators = [np.array([self.engine.actuator(
            WHEEL_JOINTS.format(side=side, index=i)).id for i in range(len(self.robot.wheel_x))])
            for side in (0, 1)]

    # ------------------------------------------------------------------ Base's calls
    def command(self, u: Sequence[float], t: float | None = None) -> None:
        """Send the command u at time t (default: now); it acts from t + latency.

        A command that is not two finite numbers is a broken sender: it is taken as zero
        (stop), as `Base` does (`CommandQueue`).
        """
        self._commands.send(u, self.time if t is None else t, self.model, self.reality.latency)

    def stop(self, t: float | None = None) -> None:
        """Send a zero command (a command timeout, a dead controller)."""
        self.command(np.zeros(2), t)

    @property
    def target(self) -> np.ndarray:
        """The command that has reached the base controller."""
        return self._commands.applied

    @property
    def pose(self) -> np.ndarray:
        """The TRUE pose (x, y, theta) of ``base_link``, theta unwrapped."""
        return np.array([self.data.qpos[0], self.data.qpos[1], self._yaw])

    @property
    def odom_pose(self) -> np.ndarray:
        """The pose the wheels' odometry integrates (no noise)."""
        return self.wheel_odometry.pose.copy()

    @property
    def velocity(self) -> np.ndarray:
        """The body's TRUE (forward speed, yaw rate)."""
        heading = np.array([math.cos(self._yaw), math.sin(self._yaw)])
        return np.array([float(self.data.qvel[:2] @ heading), float(self.data.qvel[5])])

    def advance(self, until: float) -> None:
        """Run the engine from the base's time to until (to its nearest step)."""
        until = float(until)
        if until - self.time <= 1e-12:
            return
        last = int(round(until / TIMESTEP))
        while self._steps < last:
            now = self._steps * TIMESTEP
            self._take_commands(now)
            if now >= self._next_update - _EPS:
                self._update(now)
                self._next_update += self._period
            # up to the next update or command, whichever comes first, in one call
            arrival = self._commands.next_arrival
            event = self._next_update if arrival is None else min(self._next_update, arrival)
            ahead = min(int(math.ceil((event - now) / TIMESTEP - _EPS)), last - self._steps)
            ahead = max(ahead, 1)
            if self._moving:  # each step with the obstacles where they are then
                ahead = 1
                self._place_moving(now)
            mujoco.mj_step(self.engine, self.data, nstep=ahead)
            self._steps += ahead
            self._unwrap()
        self.time = until
        if self._moving:  # the laser casts against geoms placed at the base's time
            self._place_moving(until)
            mujoco.mj_kinematics(self.engine, self.data)

    def odometry(self) -> tuple[np.ndarray, np.ndarray]:
        """Return what odometry reports now: (the wheels' pose with noise, their twist)."""
        pose = self.odom_pose
        std_position, std_heading = self.reality.odom_noise
        if std_position > 0.0 or std_heading > 0.0:
            pose += self._rng.normal(0.0, 1.0, 3) * np.array(
                [std_position, std_position, std_heading])
        return pose, self.twist()

    def twist(self) -> np.ndarray:
        """Return the twist odometry reports (the wheels' rolling mean)."""
        return self.wheel_odometry.twist

    def laser(self, *, fov: float, beams: int, range_min: float,
              range_max: float) -> PhysicsLaser:
        """Return a laser that the engine ray-casts in this plant's world."""
        return PhysicsLaser(self.engine, self.data, fov=fov, beams=beams, range_min=range_min,
                            range_max=range_max)

    # ------------------------------------------------------------------ inside
    def _take_commands(self, now: float) -> None:
        """Hand the commands that have arrived by now to the base controller."""
        for arrival, u in self._commands.take(now):
            self.drive.receive(u, arrival)

    def _update(self, now: float) -> None:
        """One update of the base controller: odometry from the wheels, then wheel speeds."""
        qpos = self.data.qpos
        gyro_turn = None
        if self._gyro_bias is not None:
            gyro_turn = self._yaw - self._gyro_yaw + self._gyro_bias * self._period
            self._gyro_yaw = self._yaw
        self.wheel_odometry.update(float(np.mean(qpos[self._wheel_qpos[0]])),
                                   float(np.mean(qpos[self._wheel_qpos[1]])), self._period,
                                   gyro_turn)
        left, right = self.drive.update(now, self._period)
        self.data.ctrl[self._actuators[0]] = left
        self.data.ctrl[self._actuators[1]] = right

    def _place_moving(self, t: float) -> None:
        """Put the moving obstacles' mocap bodies where their trajectories are at t."""
        for mocap, obstacle in zip(self._mocap, self._moving, strict=True):
            self.data.mocap_pos[mocap, :2] = obstacle.position(t)

    def _unwrap(self) -> None:
        """Follow the body's yaw without wrapping (as the kinematic base's theta)."""
        w, _, _, z = self.data.qpos[3:7]
        yaw = 2.0 * math.atan2(z, w)  # the robot stays level: its rotation is about z
        self._yaw += (yaw - self._yaw + math.pi) % (2.0 * math.pi) - math.pi
