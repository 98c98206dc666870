# Copyright 2026 mpc_local_planner developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""What a real robot does with a command, and what its sensors give back: ONE model.

The unicycle_simulator node and the ROS-free rollout (the evaluation suites) both drive a
`Base` and pass scans through a `ScanChannel`, so the suites measure what the nodes see. An
ideal robot takes each command at once and exactly, its odometry is its pose and its laser
is exact; a real one does not:

- **command latency**: a command sent at t reaches the motors at t + ``latency``;
- **actuator lag**: the wheels follow the command as a first-order system with time constants
  ``lag`` (v, omega);
- **acceleration limits**: |dv/dt| and |domega/dt| at most ``acceleration`` (the motor
  drivers' limits, also on braking);
- **odometry**: integrated from the wheels with a scale error and a heading bias per metre
  (``odom_drift``), and published with white noise (``odom_noise``: what wheel slip and
  encoder quantisation look like to a controller at 50 Hz);
- **the laser**: Gaussian range noise, beams that read NaN (an erroneous reading, REP 117) or
  -inf (too close), and whole scans that never arrive;
- **a localizer** (`Localizer`, AMCL's stand-in): since odometry drifts, a robot that is not
  ideal is told where it is in ``map`` by a localizer, late and noisy; composed with
  odometry (perception/localization.py) it gives the pose in the plan's frame.

`REALITY_PRESETS` gives four levels; `Reality.ideal` (all off) is what every simulation was
before, and with it a `Base` reproduces the model's own step exactly.

Where the preset values come from:

- The Jackal's ``jackal_control/config/control.yaml`` lets its diff_drive_controller
  accelerate at up to 20 m/s^2 and 25 rad/s^2 and times commands out after 0.25 s; those are
  software caps, not what the 17 kg robot does. Navigation configurations for it plan with
  about 2 m/s^2 linear, which is ``real``; a skid-steer base turns in place at 4 rad/s, and
  ``real`` lets it reach that in 2/3 s (6 rad/s^2, a quarter of the cap). ``harsh`` halves
  both, as a loaded robot on grass would; ``mild`` doubles them.
- Lag: a velocity-controlled base with wheel PID loops settles in 0.1-0.3 s (time constants
  of 0.05-0.1 s are typical of small differential-drive bases; 0.3 s is a heavy one).
- Latency: a command crosses DDS, the driver's serial link and the motor controller's cycle:
  a few tens of milliseconds on a healthy robot, 0.2 s on a loaded computer or over Wi-Fi.
- Odometry: 0.5-3 cm of jitter (the issue's outside simulator) and about 1 % scale error
  (wheel radius and tyre pressure), a heading bias of a few milliradians per metre (skid).
- Laser: the Hokuyo UST-10LX the BARN Jackal carries specifies +-40 mm accuracy (about
  0.01-0.02 m standard deviation); real drivers report a percent or so of NaN beams (no
  echo, dust, glass) and -inf for objects closer than range_min; a scan now and then is lost
  on a busy network.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field, fields, replace
import math
from typing import Any, Sequence

import numpy as np

from mpc_local_planner.core.models import Unicycle, unicycle_arc

__all__ = [
    'Base',
    'Localizer',
    'LOCALIZER_NOISE',
    'LOCALIZER_RATE',
    'POSE_ERROR',
    'REALITY_PRESETS',
    'Reality',
    'reality_preset',
    'ScanChannel',
    'true_goal_tolerance',
]

# The localizer stand-in of every localized run (closed_loop with --drift or a non-ideal
# --reality, the suites with a non-ideal reality): AMCL updates a moving robot's pose a few
# times a second (5 Hz) to about a centimetre in a well-mapped place (noise on x, y, and in
# rad on theta).
LOCALIZER_RATE = 5.0
LOCALIZER_NOISE = 0.01
# How far a localized pose estimate may be from the truth (m): the localizer's noise (3
# sigma, 3 cm) and odometry's jitter and drift between two of its poses.
POSE_ERROR = 0.05


@dataclass(frozen=True)
class Reality:
    """How far from ideal the robot and its laser are (every field off = ideal).

    Attributes:
        lag: first-order time constants of v and omega (s); 0 = the wheels follow at once.
        acceleration: limits of |dv/dt| (m/s^2) and |domega/dt| (rad/s^2); inf = none.
        latency: seconds from a command's sending to its reaching the motors.
        odom_noise: standard deviations of the white noise on the published odometry pose
            (m, rad).
        odom_drift: odometry's scale error (0.01 = 1 % too far) and heading bias (rad per
            metre travelled): odometry integrates apart from the true pose.
        scan_noise: standard deviation of the laser's range noise (m).
        scan_nan: fraction of beams that read NaN (erroneous readings).
        scan_neg_inf: fraction of beams that read -inf (too close, REP 117).
        scan_loss: fraction of scans that never arrive.
        seed: seed of every random draw (runs are reproducible).

    """

    lag: tuple[float, float] = (0.0, 0.0)
    acceleration: tuple[float, float] = (math.inf, math.inf)
    latency: float = 0.0
    odom_noise: tuple[float, float] = (0.0, 0.0)
    odom_drift: tuple[float, float] = (0.0, 0.0)
    scan_noise: float = 0.0
    scan_nan: float = 0.0
    scan_neg_inf: float = 0.0
    scan_loss: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        """Refuse values a robot cannot have (negative times, fractions outside [0, 1))."""
        for name in ('lag', 'acceleration', 'odom_noise', 'odom_drift'):
            value = tuple(float(v) for v in getattr(self, name))
            if len(value) != 2 or any(math.isnan(v) for v in value):
                msg = f'{name} must be two numbers, got {getattr(self, name)!r}'
                raise ValueError(msg)
            object.__setattr__(self, name, value)
        checks = {
            'lag': all(0.0 <= v < math.inf for v in self.lag),
            'acceleration': all(v > 0.0 for v in self.acceleration),
            'latency': 0.0 <= self.latency < math.inf,
            'odom_noise': all(0.0 <= v < math.inf for v in self.odom_noise),
            'odom_drift': all(math.isfinite(v) for v in self.odom_drift)
            and self.odom_drift[0] > -1.0,
            'scan_noise': 0.0 <= self.scan_noise < math.inf,
            'scan_nan': 0.0 <= self.scan_nan < 1.0,
            'scan_neg_inf': 0.0 <= self.scan_neg_inf < 1.0,
            'scan_loss': 0.0 <= self.scan_loss < 1.0,
        }
        bad = [name for name, ok in checks.items() if not ok]
        if bad:
            values = ', '.join(f'{name}={getattr(self, name)!r}' for name in bad)
            msg = (f'invalid reality: {values} (times and noise >= 0 and finite, '
                   f'accelerations > 0, fractions in [0, 1), scale error > -1)')
            raise ValueError(msg)
        if self.scan_nan + self.scan_neg_inf >= 1.0:
            msg = 'scan_nan + scan_neg_inf must be < 1'
            raise ValueError(msg)

    @property
    def ideal_base(self) -> bool:
        """The base takes commands at once and exactly, and odometry is the true pose."""
        return (self.lag == (0.0, 0.0) and self.acceleration == (math.inf, math.inf)
                and self.latency == 0.0 and self.odom_noise == (0.0, 0.0)
                and self.odom_drift == (0.0, 0.0))

    @property
    def ideal_laser(self) -> bool:
        """Scans arrive, exact and complete."""
        return (self.scan_noise == 0.0 and self.scan_nan == 0.0 and self.scan_neg_inf == 0.0
                and self.scan_loss == 0.0)

    @property
    def acceleration_limits(self) -> tuple[float, float] | None:
        """The acceleration limits when both are finite (what a controller is told), else None."""
        return self.acceleration if all(math.isfinite(a) for a in self.acceleration) \
            else None

    @property
    def ideal(self) -> bool:
        """Nothing differs from the model."""
        return self.ideal_base and self.ideal_laser

    def as_dict(self) -> dict[str, Any]:
        """Return the fields as plain data (lists for pairs), for settings files and logs."""
        return {f.name: (list(v) if isinstance(v := getattr(self, f.name), tuple) else v)
                for f in fields(self)}

    def with_seed(self, seed: int) -> Reality:
        """Return the same reality with another seed (one per run of a suite)."""
        return replace(self, seed=int(seed))


REALITY_PRESETS: dict[str, Reality] = {
    'ideal': Reality(),
    'mild': Reality(lag=(0.05, 0.05), acceleration=(4.0, 12.0), latency=0.02,
                    odom_noise=(0.005, 0.005), odom_drift=(0.002, 0.001),
                    scan_noise=0.01, scan_nan=0.002, scan_neg_inf=0.0005, scan_loss=0.01),
    'real': Reality(lag=(0.1, 0.1), acceleration=(2.0, 6.0), latency=0.05,
                    odom_noise=(0.01, 0.01), odom_drift=(0.01, 0.003),
                    scan_noise=0.015, scan_nan=0.01, scan_neg_inf=0.002, scan_loss=0.02),
    'harsh': Reality(lag=(0.3, 0.3), acceleration=(1.0, 3.0), latency=0.2,
                     odom_noise=(0.03, 0.02), odom_drift=(0.02, 0.01),
                     scan_noise=0.03, scan_nan=0.05, scan_neg_inf=0.01, scan_loss=0.1),
}


def reality_preset(name: str) -> Reality:
    """Return the preset called name.

    Raises:
        ValueError: for an unknown name (the message lists the known ones).

    """
    try:
        return REALITY_PRESETS[name]
    except KeyError:
        msg = f'unknown reality {name!r}; choose one of {", ".join(REALITY_PRESETS)}'
        raise ValueError(msg) from None


@dataclass
class Base:
    """A robot base driven by velocity commands, as `Reality` says a real one behaves.

    Time is the caller's (seconds, from 0 at start). `command` hands a command over at a
    time; `advance` integrates up to a later time in sub-steps of ``dt``: the command in
    force at each sub-step is the last one sent at least ``latency`` earlier (zero before
    any), saturated to the model's bounds; the wheels' velocity follows it through the lag
    and the acceleration limits; the true pose moves on the exact arc of that velocity,
    odometry on its drifted copy. With an ideal reality the base is the model: ``advance``
    by h after ``command(u)`` equals ``model.step(x, u, h)`` (RK4 of the same unicycle, to
    its rounding), so that ideal runs stay what they were.

    Args:
        model: the unicycle (its input bounds are the motor drivers' saturation).
        reality: how far from ideal the base is.
        pose: the start pose (x, y, theta).
        dt: the sub-step (s): the simulator's tick, 0.01 s in the rollout.

    """

    model: Unicycle
    reality: Reality
    pose: np.ndarray
    dt: float = 0.01
    time: float = 0.0
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(2))
    odom_pose: np.ndarray = field(init=False)
    _commands: deque = field(init=False, repr=False)
    _applied: np.ndarray = field(init=False, repr=False)
    _rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Start at rest with odometry at the true pose."""
        if not (math.isfinite(self.dt) and self.dt > 0):
            msg = f'dt must be > 0, got {self.dt}'
            raise ValueError(msg)
        self.pose = np.asarray(self.pose, dtype=float)[:3].copy()
        self.odom_pose = self.pose.copy()
        self._commands = deque()
        self._applied = np.zeros(2)
        self._rng = np.random.default_rng(self.reality.seed)

    def command(self, u: Sequence[float], t: float | None = None) -> None:
        """Send the command u at time t (default: now); it acts from t + latency.

        A non-finite command is a broken sender: it is taken as zero (stop), as the
        simulator node does.
        """
        u = np.asarray(u, dtype=float).reshape(-1)[:2]
        if not np.all(np.isfinite(u)):
            u = np.zeros(2)
        sent = self.time if t is None else float(t)
        self._commands.append((sent + self.reality.latency, self.model.saturate(u)))

    def stop(self, t: float | None = None) -> None:
        """Send a zero command (a command timeout, a dead controller)."""
        self.command(np.zeros(2), t)

    @property
    def target(self) -> np.ndarray:
        """The command reaching the motors now."""
        return self._applied.copy()

    def advance(self, until: float) -> None:
        """Integrate from the base's time up to until (a whole number of sub-steps, at most).

        With an ideal base the velocity is the command (no sub-steps are needed: one exact
        RK4 step of the whole interval, as the model's step).
        """
        span = float(until) - self.time
        if span <= 1e-12:
            return
        if self.reality.ideal_base:
            self._take_commands(until)
            self.velocity = self._applied.copy()
            self.pose = self.model.step(self.pose, self._applied, span)
            self.odom_pose = self.pose.copy()
            self.time = float(until)
            return
        steps = max(int(math.ceil(span / self.dt - 1e-9)), 1)
        dt = span / steps
        for _ in range(steps):
            self._take_commands(self.time)
            self._follow(dt)
            v, omega = (float(u) for u in self.velocity)
            self.pose = unicycle_arc(self.pose, v, omega, dt)
            scale, bias = self.reality.odom_drift
            self.odom_pose = unicycle_arc(self.odom_pose, (1.0 + scale) * v,
                                            omega + bias * abs(v), dt)
            self.time += dt
        self.time = float(until)

    def odometry(self) -> tuple[np.ndarray, np.ndarray]:
        """Return what odometry reports now: (pose with noise and drift, measured twist).

        The twist is the wheels' velocity with the drift's scale error (what the encoders
        count), without the pose's white noise.
        """
        pose = self.odom_pose.copy()
        std_position, std_heading = self.reality.odom_noise
        if std_position > 0.0 or std_heading > 0.0:
            pose += self._rng.normal(0.0, 1.0, 3) * np.array(
                [std_position, std_position, std_heading])
        return pose, self.twist()

    def twist(self) -> np.ndarray:
        """Return the twist odometry reports (as odometry() does, without drawing noise)."""
        scale, bias = self.reality.odom_drift
        v, omega = (float(u) for u in self.velocity)
        return np.array([(1.0 + scale) * v, omega + bias * abs(v)])

    def _take_commands(self, now: float) -> None:
        """Make the latest command that has reached the motors by now the one in force."""
        while self._commands and self._commands[0][0] <= now + 1e-9:
            self._applied = self._commands.popleft()[1]

    def _follow(self, dt: float) -> None:
        """Move the wheels' velocity toward the command over dt: lag, then rate limits."""
        target = self._applied
        wanted = target.copy()
        for i, tau in enumerate(self.reality.lag):
            if tau > 0.0:
                wanted[i] = self.velocity[i] + (target[i] - self.velocity[i]) * (
                    1.0 - math.exp(-dt / tau))
        limit = np.asarray(self.reality.acceleration, dtype=float) * dt
        self.velocity = self.velocity + np.clip(wanted - self.velocity, -limit, limit)


class ScanChannel:
    """The laser's side of reality: noise, NaN and -inf beams, and lost scans.

    Works on the readings (a LaserScan's ``ranges``) so that the simulator node and the
    rollout corrupt their scans the same way; draws come from one seeded generator.
    """

    def __init__(self, reality: Reality) -> None:
        self.reality = reality
        # its own stream: the base's draws do not shift the laser's when either changes
        self._rng = np.random.default_rng([reality.seed, 1])

    def lost(self) -> bool:
        """Draw whether the next scan never arrives."""
        return self.reality.scan_loss > 0.0 and bool(self._rng.random() < self.reality.scan_loss)

    def corrupt(self, ranges: np.ndarray, range_max: float) -> np.ndarray:
        """Return the readings as a real laser reports them (a copy; ideal: unchanged).

        Noise moves finite readings (a reading pushed past range_max becomes +inf: no
        return); then a fraction of the beams read NaN and a fraction -inf, as REP 117 has
        drivers report erroneous and too-close readings.
        """
        ranges = np.array(ranges, dtype=float)
        reality = self.reality
        if reality.ideal_laser:
            return ranges
        if reality.scan_noise > 0.0:
            hit = np.isfinite(ranges)
            noisy = ranges[hit] + self._rng.normal(0.0, reality.scan_noise, int(hit.sum()))
            noisy = np.maximum(noisy, 0.0)
            noisy[noisy > range_max] = np.inf
            ranges[hit] = noisy
        if reality.scan_nan > 0.0 or reality.scan_neg_inf > 0.0:
            draw = self._rng.random(len(ranges))
            ranges[draw < reality.scan_nan] = np.nan
            ranges[(draw >= reality.scan_nan)
                   & (draw < reality.scan_nan + reality.scan_neg_inf)] = -np.inf
        return ranges


class Localizer:
    """A localizer's stand-in (AMCL's ``amcl_pose``): the TRUE pose with noise, at a rate.

    What the unicycle_simulator node publishes with ``localizer.rate`` and
    ``localizer.noise_std`` (closed_loop sets them to LOCALIZER_RATE and LOCALIZER_NOISE):
    Gaussian noise of the same standard deviation on x, y (m) and theta (rad), its own seeded
    stream. Time is the caller's, as a `Base`'s: a pose is due at 0 (the localizer has its
    initial pose before the robot moves) and then every 1 / rate seconds.

    Args:
        rate: poses per second (> 0).
        noise_std: standard deviation of the noise (m, and rad for the heading).
        seed: seed of the noise (a run's reality seed: runs are reproducible).

    """

    def __init__(self, rate: float = LOCALIZER_RATE, noise_std: float = LOCALIZER_NOISE,
                 seed: int = 0) -> None:
        if not (math.isfinite(rate) and rate > 0.0):
            msg = f'rate must be > 0 and finite, got {rate}'
            raise ValueError(msg)
        if not (math.isfinite(noise_std) and noise_std >= 0.0):
            msg = f'noise_std must be >= 0 and finite, got {noise_std}'
            raise ValueError(msg)
        self.rate = float(rate)
        self.noise_std = float(noise_std)
        # its own stream: the base's and the laser's draws do not shift it
        self._rng = np.random.default_rng([int(seed), 2])
        self._next = 0.0

    def measure(self, time: float, pose: Sequence[float]) -> np.ndarray | None:
        """Return the localizer's pose (x, y, theta in map) at time if one is due, else None.

        Args:
            time: now (s); calls come in time order.
            pose: the TRUE pose now.

        """
        if time < self._next - 1e-9:
            return None
        period = 1.0 / self.rate
        while self._next <= time + 1e-9:
            self._next += period
        return np.asarray(pose, dtype=float)[:3] + self._rng.normal(0.0, self.noise_std, 3)


def true_goal_tolerance(arrival_tolerance: float) -> float:
    """Return how close the TRUE robot must end to the goal when it arrives on an estimate.

    ONE definition for closed_loop and the suites. A localized robot (odometry corrected by
    a localizer) declares arrival when its ESTIMATE is within arrival_tolerance of the goal;
    the estimate may be off by POSE_ERROR, so the truth is held to arrival_tolerance +
    POSE_ERROR. closed_loop judges its runs so (the controller's xy_goal_tolerance, the node's
    0.1 m in a localized run, --drift or a real base); the suites judge the truth against the
    task's tolerance (the unknown suite's 0.1 m) and so give their controllers an arrival
    tolerance no larger than the task's minus POSE_ERROR: true_goal_tolerance(arrival) is at
    most the task's tolerance, and a run is judged as closed_loop would judge it.
    """
    return float(arrival_tolerance) + POSE_ERROR
