# SPDX-License-Identifier: Apache-2.0
"""The wheeled robots the physics plant simulates: their bodies, wheels, servos and drive.

Two robots, with where each figure comes from:

**The Jackal** (Clearpath; the BARN challenge's robot), from the vendor's description,
jackal/jackal ``jackal_description/urdf/jackal.urdf.xacro``: wheelbase 0.262 m, track
0.37559 m, wheel radius 0.098 m and width 0.040 m, wheel axles 0.0345 m above ``base_link``
(so ``base_link`` is 0.0635 m above the ground), chassis 0.420 x 0.310 x 0.184 m of 16.523 kg
(centre of mass (0.012, 0.002, 0.067), inertia diagonal 0.3136, 0.3922, 0.4485 kg m^2), four
wheels of 0.477 kg (inertia 0.0013, 0.0024, 0.0013 kg m^2), and Gazebo's wheel friction
mu1 = mu2 = 0.5; four wheels, one velocity joint each, two per side: skid-steer, the wheels
scrub sideways when it turns. Its base controller, jackal/jackal
``jackal_control/config/control.yaml`` (``jackal_velocity_controller``, a
diff_drive_controller): ``wheel_separation_multiplier: 1.5`` (the skid-steer's effective
separation is 1.5 x the track, 0.563 m), ``wheel_radius_multiplier: 1.0``, linear
``max_velocity: 2.0`` m/s and ``max_acceleration: 20.0`` m/s^2, angular ``max_velocity: 4.0``
rad/s and ``max_acceleration: 25.0`` rad/s^2, ``cmd_vel_timeout: 0.25`` s, ``publish_rate:
50`` (the update rate taken here). Assumed (not in the description): each wheel's servo
delivers at most 6.0 N m (4 x 6.0 / 0.098 = 245 N, 13 m/s^2 for the 18.4 kg robot: more
than the friction transmits at mu 0.5, so on this floor the Jackal is traction-limited, not
torque-limited) with a velocity gain of 10 N m s/rad, and its gearbox reflects 0.05 kg m^2
of rotor inertia onto each wheel (``armature``; a rotor of 2e-5 kg m^2 behind a 50:1
reduction). The reflected inertia matters beyond the acceleration: MuJoCo's soft contacts
share a sliding contact's friction between directions by the inertia behind them, and with
a bare wheel (0.0024 kg m^2) the Jackal turned in place at half the rate Coulomb friction
gives for its geometry; with it, at 93 % of that rate (4.04 rad/s for the wheels' 4.0 rad/s
command: for four wheels at (+-a, +-b) Coulomb scrub makes the effective separation
(a^2 + b^2) / b^2 = 1.49 times the track, which is the vendor's multiplier of 1.5).

**The paper's small robot** (a Turtlebot 4: its bounds 0.31 m/s and 1.9 rad/s are
core/models.py `Unicycle`'s defaults and config/mpc_controller.yaml's). Assumed from the
iRobot Create 3 it is built on: 3.9 kg, two wheels of radius 0.036 m (72 mm diameter)
0.235 m apart, one frictionless caster 0.13 m ahead of the axle, the centre of mass 0.02 m
ahead of the axle (the wheels carry 85 % of the weight), a round body (the footprint's
circle, 0.2 m in the suites), wheel friction 0.5, 0.5 N m per wheel with a velocity gain of
0.5 N m s/rad and 0.002 kg m^2 of reflected rotor inertia; its diff_drive_controller
has wheel_separation = the wheels' 0.235 m (two wheels: no scrub), the model's speed bounds,
the acceleration limits of Nav2's default velocity_smoother (nav2_bringup
``nav2_params.yaml``: max_accel [2.5, 0.0, 3.2]) and diff_drive_controller's default
cmd_vel_timeout of 0.5 s.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ['JACKAL_ROBOT', 'PHYSICS_ROBOTS', 'SMALL_ROBOT', 'DriveLimits', 'WheeledRobot',
           'physics_robot']


@dataclass(frozen=True)
class DriveLimits:
    """The base controller's settings, as diff_drive_controller's parameters name them.

    Attributes:
        wheel_separation: The separation the controller computes wheel speeds and
            odometry with (m): the URDF's times wheel_separation_multiplier.
        wheel_radius: The radius it converts with (m).
        max_velocity: linear.x.max_velocity (m/s) and angular.z.max_velocity (rad/s).
        max_acceleration: linear.x.max_acceleration (m/s^2) and angular.z's (rad/s^2).
        cmd_vel_timeout: Seconds after the last command at which the base brakes to zero.
        update_rate: The controller's update rate (Hz).
        velocity_window: velocity_rolling_window_size: odometry's twist is the mean of so
            many updates (diff_drive_controller's default, 10).

    """

    wheel_separation: float
    wheel_radius: float
    max_velocity: tuple[float, float]
    max_acceleration: tuple[float, float]
    cmd_vel_timeout: float
    update_rate: float = 50.0
    velocity_window: int = 10


@dataclass(frozen=True)
class WheeledRobot:
    """A wheeled robot's body, wheels and drive (metres, kilograms, seconds).

    The chassis frame is ``base_link``: x forward, origin on the robot's axis of rotation
    at ``base_height`` above the ground. Wheels sit at (x, +-y) for each x in ``wheel_x``,
    y = track / 2, their axles ``wheel_z`` above ``base_link``.

    Attributes:
        name: ``jackal`` or ``small``.
        mass: The chassis's mass (wheels apart).
        centre_of_mass: Its centre of mass in ``base_link``.
        inertia: Its principal moments (kg m^2).
        base_height: Height of ``base_link`` above the ground.
        wheel_radius: The wheels' true radius.
        wheel_mass: One wheel's mass.
        wheel_inertia: One wheel's principal moments (kg m^2), the axle's second.
        track: Distance between the left and right wheels' mid-planes.
        wheel_x: The wheels' x in ``base_link`` (two for a skid-steer, one for a
            differential drive).
        wheel_z: The axles' height above ``base_link``.
        casters: (x, radius) of frictionless casters (none for a skid-steer).
        friction: Sliding friction coefficient of wheels and floor.
        torque: Largest torque of one wheel's servo (N m).
        servo_gain: The velocity servo's gain (N m per rad/s of error).
        armature: The rotor inertia the gearbox reflects onto each wheel (kg m^2).
        drive: The base controller's settings.
        gyro_bias: Standard deviation of the yaw gyro's constant bias (rad/s), which fused
            odometry integrates (drive.py). Assumed for both robots: 0.002 rad/s (0.11 deg/s),
            a MEMS gyro of their class after the bias estimate taken at rest on start-up.

    """

    name: str
    mass: float
    centre_of_mass: tuple[float, float, float]
    inertia: tuple[float, float, float]
    base_height: float
    wheel_radius: float
    wheel_mass: float
    wheel_inertia: tuple[float, float, float]
    track: float
    wheel_x: tuple[float, ...]
    wheel_z: float
    casters: tuple[tuple[float, float], ...]
    friction: float
    torque: float
    servo_gain: float
    armature: float
    drive: DriveLimits
    gyro_bias: float = 0.002

    @property
    def total_mass(self) -> float:
        """Chassis and wheels (kg)."""
        return self.mass + 2 * len(self.wheel_x) * self.wheel_mass


_JACKAL_TRACK = 0.37559
_JACKAL_WHEELBASE = 0.262
_JACKAL_WHEEL_RADIUS = 0.098
_JACKAL_WHEEL_Z = 0.0345

JACKAL_ROBOT = WheeledRobot(
    name='jackal', mass=16.523, centre_of_mass=(0.012, 0.002, 0.067),
    inertia=(0.3136, 0.3922, 0.4485), base_height=_JACKAL_WHEEL_RADIUS - _JACKAL_WHEEL_Z,
    wheel_radius=_JACKAL_WHEEL_RADIUS, wheel_mass=0.477, wheel_inertia=(0.0013, 0.0024, 0.0013),
    track=_JACKAL_TRACK, wheel_x=(_JACKAL_WHEELBASE / 2, -_JACKAL_WHEELBASE / 2),
    wheel_z=_JACKAL_WHEEL_Z, casters=(), friction=0.5, torque=6.0, servo_gain=10.0,
    armature=0.05,
    drive=DriveLimits(wheel_separation=1.5 * _JACKAL_TRACK, wheel_radius=_JACKAL_WHEEL_RADIUS,
                      max_velocity=(2.0, 4.0), max_acceleration=(20.0, 25.0),
                      cmd_vel_timeout=0.25))

_SMALL_WHEEL_RADIUS = 0.036
_SMALL_SEPARATION = 0.235

SMALL_ROBOT = WheeledRobot(
    name='small', mass=3.9 - 2 * 0.1, centre_of_mass=(0.02, 0.0, 0.03),
    inertia=(0.025, 0.025, 0.04), base_height=_SMALL_WHEEL_RADIUS,
    wheel_radius=_SMALL_WHEEL_RADIUS,
    wheel_mass=0.1, wheel_inertia=(0.00005, 0.0001, 0.00005), track=_SMALL_SEPARATION,
    wheel_x=(0.0,), wheel_z=0.0, casters=((0.13, 0.015),), friction=0.5, torque=0.5,
    servo_gain=0.5, armature=0.002,
    drive=DriveLimits(wheel_separation=_SMALL_SEPARATION, wheel_radius=_SMALL_WHEEL_RADIUS,
                      max_velocity=(0.31, 1.9), max_acceleration=(2.5, 3.2),
                      cmd_vel_timeout=0.5))

PHYSICS_ROBOTS: dict[str, WheeledRobot] = {'jackal': JACKAL_ROBOT, 'small': SMALL_ROBOT}


def physics_robot(name: str) -> WheeledRobot:
    """Return the robot called name.

    Raises:
        ValueError: for an unknown name (the message lists the known ones).

    """
    try:
        return PHYSICS_ROBOTS[name]
    except KeyError:
        msg = f'unknown physics robot {name!r}; choose one of {", ".join(PHYSICS_ROBOTS)}'
        raise ValueError(msg) from None
