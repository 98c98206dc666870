# SPDX-License-Identifier: Apache-2.0
"""How real a simulated robot is (`Reality`), its presets, and how its arrival is judged.

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

`REALITY_PRESETS` gives four levels; with `Reality()` (all off, ``ideal``) a `Base`
reproduces the model's own step exactly.

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

from dataclasses import dataclass, fields, replace
import math
from typing import Any

__all__ = [
    'POSE_ERROR',
    'REALITY_PRESETS',
    'Reality',
    'reality_preset',
    'true_goal_tolerance',
]

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
