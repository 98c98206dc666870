# SPDX-License-Identifier: Apache-2.0
"""step_response: what the physics plant does with a step command, and how odometry drifts.

    python3 -m mpc_local_planner.sim.step_response --robot jackal   (or: small, all)

On flat ground, from rest, commands re-sent at 20 Hz as a controller would:

- **linear**: (v_max, 0): the time to 90 % of v_max, the mean acceleration to there and the
  speed held;
- **yaw**: (0, omega_max), turning in place: the yaw rate held (the body's, against the
  command), its time constant (63 %) and rise time (10-90 %);
- **odometry after a turn**: a 360 degree turn in place at omega_max and a 2 m arc of radius
  1 m (at most v_max), each ended by odometry (it says: done), then stopped: how far the
  odometry's pose is from the true one, for the wheels' odometry alone and for odometry
  fused with the gyro (the robots' default, sim/physics/drive.py).

What it printed (MuJoCo 3.17, the robots of sim/physics/robots.py; the plant is
deterministic). Odometry errors are position / heading of the odometry's pose from the true
one after the manoeuvre, the wheels' alone, then fused:

======  =======  ==========  ===========  =======  =======  ==============  ==============
robot   90 % of  mean        yaw rate     yaw tau  yaw rise 360 deg turn    2 m arc
        v_max    accel       held         (63 %)   10-90 %  in place        (radius 1 m)
======  =======  ==========  ===========  =======  =======  ==============  ==============
jackal  0.375 s  4.80 m/s^2  3.74 of 4.0  0.177 s  0.274 s  0.7 cm, 28.7 d  15.9 cm, 25.8 d
(fused)                                                     1.5 cm, 0.0 d   14.4 cm, 0.0 d
small   0.130 s  2.15 m/s^2  1.83 of 1.9  0.377 s  0.469 s  0.0 cm, 7.3 d   2.8 cm, 1.4 d
(fused)                                                     0.1 cm, 0.1 d   1.3 cm, 0.1 d
======  =======  ==========  ===========  =======  =======  ==============  ==============
(d: degrees)

The Jackal accelerates at the floor's friction limit (mu 0.5: 4.9 m/s^2; its wheels spin
at first, 20 m/s^2 being its controller's cap) and turns in place at 93 % of the command;
its wheel odometry, which divides the wheels' difference by 1.5 times the track, counts 360
degrees when the body has turned 331: skid-steer odometry is poor in heading, which is why
the vendor fuses it with an IMU. Fused, the heading is the gyro's and the error left is the
distance the scrubbing wheels overcount on an arc (7 % of it). The small robot rolls without
scrub: its wheel odometry's error is the wheels' slip while the turn starts and stops.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import math
import sys
from typing import Callable, TYPE_CHECKING

import numpy as np

from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.sim.physics import make_physics_base, mujoco_missing, PHYSICS_ROBOTS
from mpc_local_planner.sim.reality import Reality

if TYPE_CHECKING:
    from mpc_local_planner.sim.physics.plant import PhysicsBase

__all__ = ['StepResponse', 'main', 'measure']

# Commands are re-sent at this rate (Hz), a controller's.
COMMAND_RATE = 20.0
# Each step is held this long (s); the settling after a manoeuvre lasts SETTLE.
HOLD = 3.0
SETTLE = 1.0
ARC_LENGTH = 2.0
ARC_RADIUS = 1.0
_FOOTPRINTS = {'jackal': JACKAL, 'small': Footprint.circle(0.2)}


@dataclass(frozen=True)
class StepResponse:
    """The figures of one robot (SI units; headings in radians)."""

    robot: str
    v_max: float
    omega_max: float
    t90_linear: float
    mean_accel: float
    v_held: float
    omega_held: float
    tau_yaw: float
    rise_yaw: float
    turn_position_error: float
    turn_heading_error: float
    arc_position_error: float
    arc_heading_error: float
    fused_turn_position_error: float = math.nan
    fused_turn_heading_error: float = math.nan
    fused_arc_position_error: float = math.nan
    fused_arc_heading_error: float = math.nan


def _base(name: str, odometry: str = 'wheels') -> PhysicsBase:
    drive = PHYSICS_ROBOTS[name].drive
    model = Unicycle(v_max=drive.max_velocity[0], omega_max=drive.max_velocity[1])
    return make_physics_base(model, Reality(), (0.0, 0.0, 0.0), robot=name,
                             footprint=_FOOTPRINTS[name], odometry=odometry)


def _hold(base: PhysicsBase, u: tuple[float, float],
          seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """Send u at COMMAND_RATE for seconds; return the times and the body's velocities."""
    period = 1.0 / COMMAND_RATE
    times, velocities = [], []
    for _ in range(int(round(seconds * COMMAND_RATE))):
        base.command(u, base.time)
        base.advance(base.time + period)
        times.append(base.time)
        velocities.append(base.velocity)
    return np.array(times), np.array(velocities)


def _first(times: np.ndarray, values: np.ndarray, level: float) -> float:
    """Return the first time values reach level (linear between samples), nan if never."""
    above = np.flatnonzero(values >= level)
    if not len(above):
        return math.nan
    k = int(above[0])
    if k == 0:
        return float(times[0])
    t0, t1, v0, v1 = times[k - 1], times[k], values[k - 1], values[k]
    return float(t0 + (level - v0) / (v1 - v0) * (t1 - t0)) if v1 != v0 else float(t1)


def _until_odometry(base: PhysicsBase, u: tuple[float, float],
                    done: Callable[[np.ndarray], bool]) -> None:
    """Send u until done(odometry's pose change) says the manoeuvre is over, then settle."""
    period = 1.0 / COMMAND_RATE
    start = base.odom_pose.copy()
    for _ in range(int(60.0 * COMMAND_RATE)):
        if done(base.odom_pose - start):
            break
        base.command(u, base.time)
        base.advance(base.time + period)
    _hold(base, (0.0, 0.0), SETTLE)


def _errors(base: PhysicsBase) -> tuple[float, float]:
    """Return odometry's position and heading error against the true pose."""
    gap = base.odom_pose - base.pose
    return float(np.hypot(gap[0], gap[1])), float(abs(gap[2]))


def measure(name: str) -> StepResponse:
    """Return the step response of the named robot (see the module docstring)."""
    drive = PHYSICS_ROBOTS[name].drive
    v_max, omega_max = drive.max_velocity
    base = _base(name)
    times, velocity = _hold(base, (v_max, 0.0), HOLD)
    t90 = _first(times, velocity[:, 0], 0.9 * v_max)
    v_held = float(np.mean(velocity[-10:, 0]))
    base = _base(name)
    times, velocity = _hold(base, (0.0, omega_max), HOLD)
    omega_held = float(np.mean(velocity[len(velocity) // 2:, 1]))
    rise = _first(times, velocity[:, 1], 0.9 * omega_held) - _first(
        times, velocity[:, 1], 0.1 * omega_held)
    tau = _first(times, velocity[:, 1], (1.0 - math.exp(-1.0)) * omega_held)
    errors = []
    for odometry in ('wheels', 'fused'):
        base = _base(name, odometry)
        _until_odometry(base, (0.0, omega_max), lambda d: d[2] >= 2.0 * math.pi)
        errors += _errors(base)
        base = _base(name, odometry)
        speed = min(v_max, omega_max * ARC_RADIUS, 1.0)
        _until_odometry(base, (speed, speed / ARC_RADIUS),
                        lambda d: d[2] * ARC_RADIUS >= ARC_LENGTH)
        errors += _errors(base)
    return StepResponse(name, v_max, omega_max, t90, 0.9 * v_max / t90, v_held, omega_held,
                        tau, rise, *errors)


def report(result: StepResponse) -> str:
    """Return the figures as lines of text."""
    r = result
    return '\n'.join([
        f'{r.robot}: v_max {r.v_max:g} m/s, omega_max {r.omega_max:g} rad/s',
        f'  linear: 90 % of v_max after {r.t90_linear:.3f} s (mean {r.mean_accel:.2f} '
        f'm/s^2), speed held {r.v_held:.3f} m/s',
        f'  yaw, turning in place: {r.omega_held:.3f} rad/s held ('
        f'{100.0 * r.omega_held / r.omega_max:.0f} % of the command), time constant '
        f'{r.tau_yaw:.3f} s, rise 10-90 % {r.rise_yaw:.3f} s',
        f'  wheel odometry after a 360 deg turn in place: '
        f'{100.0 * r.turn_position_error:.1f} cm, '
        f'{math.degrees(r.turn_heading_error):.1f} deg from the true pose '
        f'(fused with the gyro: {100.0 * r.fused_turn_position_error:.1f} cm, '
        f'{math.degrees(r.fused_turn_heading_error):.1f} deg)',
        f'  wheel odometry after a {ARC_LENGTH:g} m arc of radius {ARC_RADIUS:g} m: '
        f'{100.0 * r.arc_position_error:.1f} cm, {math.degrees(r.arc_heading_error):.1f} deg '
        f'from the true pose (fused with the gyro: {100.0 * r.fused_arc_position_error:.1f} '
        f'cm, {math.degrees(r.fused_arc_heading_error):.1f} deg)',
    ])


def main(argv: list[str] | None = None) -> int:
    """Print the step responses (exit 2 with the reason when MuJoCo is missing)."""
    parser = argparse.ArgumentParser(prog='step_response', description=__doc__.split('\n')[0])
    parser.add_argument('--robot', choices=(*PHYSICS_ROBOTS, 'all'), default='all')
    args = parser.parse_args(argv)
    problem = mujoco_missing()
    if problem is not None:
        print(f'step_response: {problem}', file=sys.stderr)
        return 2
    names = list(PHYSICS_ROBOTS) if args.robot == 'all' else [args.robot]
    for name in names:
        print(report(measure(name)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
