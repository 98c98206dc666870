# SPDX-License-Identifier: Apache-2.0
"""identify_base: a robot base's latency, lag and acceleration limits from a recorded run.

How a user brings their own robot: record the velocity commands and the odometry while
driving a few steps and turns (``ros2 bag record /cmd_vel /odom``, docs/real_robot.md), then

    identify_base RECORD [--write config/<robot>.yaml]

The model is the one `sim.base.Base` simulates, per axis (v and omega): a command reaches
the motors ``latency`` seconds after it was sent, the wheels' velocity follows it as a
first-order system with time constant ``lag``, and its rate of change is at most
``acceleration`` (also when braking). For each axis the tool simulates that model on the
recorded commands, from the first measured twist, and fits the three numbers to the measured
twist (odometry's, what the wheels report) by least squares: a grid over (lag,
acceleration) simulated at once, every latency of a grid compared by shifting the response
in time (the model is time-invariant), then a bounded refinement (scipy.optimize). The
residual (RMS) says how well the model explains the record.

An acceleration limit shows only where the base was asked for more than it can do. The tool
says how long the fitted limit binds; where it never binds, or fitting it hardly improves
the residual, the limit is reported as not identifiable (with the fastest change the record
shows, a lower bound) instead of being made up.

RECORD is a rosbag2 folder (``cmd_vel`` as geometry_msgs Twist or TwistStamped, ``odom`` as
nav_msgs/Odometry, read with rosbags: no ROS needed) or a CSV with the columns
``t, v_cmd, omega_cmd, v, omega``: one row per sample, the command sent at t (empty when
none was) and the twist measured at t (empty when none was). Times in a bag are the
messages' header stamps when the recorder received them within 0.05 s of them (its clock
and the sender's agree), else the times the recorder received them (a Twist has no stamp).

``--write FILE`` writes ros__parameters for ``mpc_controller`` (``max_accel``,
``max_decel``, ``input_hold: first_order``, ``actuation_delay`` = latency + lag, as
config/jackal.yaml explains) and the matching ``unicycle_simulator`` reality overrides
(``actuator_lag``, ``acceleration_limits``, ``command_latency``), with a header comment
naming the record and the residual.

A record the tool cannot use (missing topics, too short, no motion on an axis, a base that
did not follow) is refused with the reason, exit code 2.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
import sys
from typing import Any, NamedTuple, Sequence

import numpy as np
from scipy.optimize import minimize

from mpc_local_planner.sim.reality import Reality

__all__ = [
    'AXES',
    'AxisFit',
    'Identification',
    'Record',
    'identify',
    'main',
    'parameters_yaml',
    'read_bag',
    'read_csv',
    'read_record',
    'simulate_axis',
]

AXES = ('v', 'omega')
# (velocity, acceleration) units per axis
UNITS = {'v': ('m/s', 'm/s^2'), 'omega': ('rad/s', 'rad/s^2')}
CSV_COLUMNS = ('t', 'v_cmd', 'omega_cmd', 'v', 'omega')
# The model's sub-step (s): finer than any odometry period, as Base's 0.01 s tick.
SIM_STEP = 0.005
# Search bounds: latency (s), lag (s), acceleration (m/s^2 or rad/s^2).
MAX_LATENCY = 0.5
MAX_LAG = 2.0
ACCELERATION_BOUNDS = (0.05, 100.0)
# The coarse grid the refinement starts from.
_LAG_GRID = (0.0, 0.01, 0.02, 0.03, 0.05, 0.07, 0.1, 0.14, 0.2, 0.3, 0.45, 0.7, 1.0, 1.5, 2.0)
_ACCELERATION_GRID = (*np.geomspace(*ACCELERATION_BOUNDS, 21).tolist(), math.inf)
_LATENCY_GRID_STEP = 0.01
# Sub-steps of the grid stage at most (a long record is gridded coarser: it only seeds the
# refinement, and the grid's responses are held in memory at once).
_GRID_STAGE_STEPS = 20_000
# A base stops by itself when its sender goes silent (the Jackal's driver after 0.25 s);
# the model does not, so samples from that long after a non-zero command until this long
# after the next command (the model has caught up with the stopped base) are not fitted.
COMMAND_GAP = 0.25
RESUME_SETTLE = 1.0
# What a record must have to be fitted.
MIN_DURATION = 2.0  # s of fitted samples
MIN_SAMPLES = 20
MIN_MOTION = {'v': 0.05, 'omega': 0.1}  # the commands' range on each axis
MIN_FOLLOWED = 0.2  # the measured range as a fraction of the commands'
# An acceleration limit is identified when the fitted limit binds this long (s: two
# odometry periods at 50 Hz) and cuts the residual RMS of the best fit without a limit by
# this factor.
MIN_SATURATED = 0.04
MIN_LIMIT_GAIN = 1.1
# How large a command change (fraction of the axis' command range) counts as one, and how
# far from the command (same fraction) the base counts as in a transient.
_CHANGE = 0.05
# Window (s) of the fastest change a record shows (a lower bound on an unbound limit).
_RATE_WINDOW = 0.1
# Header stamps are used when they are received within this of them (s, the median): a
# stamp on a clock further off the recorder's would shift the latency by the offset.
_STAMP_AGREEMENT = 0.05
# Residual RMS above this fraction of the command range: the model does not fit.
_POOR_FIT = 0.2


class Record(NamedTuple):
    """A recorded run: commands sent and twists measured, on one clock.

    Attributes:
        commands: (n, 3) rows t, v, omega of the commands, by time.
        measured: (m, 3) rows t, v, omega of the measured twist (odometry), by time.
        source: the record's path.
        description: what was read, for the report (topics, counts, which times).

    """

    commands: np.ndarray
    measured: np.ndarray
    source: str
    description: str


class AxisFit(NamedTuple):
    """The identified response of one axis (v or omega).

    Attributes:
        axis: 'v' or 'omega'.
        latency: seconds from sending a command to its reaching the motors.
        lag: the first-order time constant (s).
        acceleration: the rate limit (m/s^2 or rad/s^2); None when the record does not
            tell it (the limit never bound, or fitting it did not improve the residual).
        fastest_change: the fastest change of the measured twist over _RATE_WINDOW: about
            a lower bound on the limit when it is not identified.
        rms: residual RMS of the fit (m/s or rad/s).
        rms_unlimited: residual RMS of the best fit without an acceleration limit.
        command_range: max - min of the commands on this axis.
        command_changes: commands that differ from the one before by more than 5 % of the
            range: what excites latency and lag.
        transient: seconds the fitted base was more than 5 % of the range away from the
            command reaching it (latency and lag shape these samples).
        saturated: seconds the fitted acceleration limit binds (they tell the limit).
        fitted: seconds of the record fitted.
        left_out: seconds left out after the sender went silent (the base's own timeout).

    """

    axis: str
    latency: float
    lag: float
    acceleration: float | None
    fastest_change: float
    rms: float
    rms_unlimited: float
    command_range: float
    command_changes: int
    transient: float
    saturated: float
    fitted: float
    left_out: float = 0.0


class Identification(NamedTuple):
    """Both axes' fits and what they give a controller and a simulator."""

    record: Record
    v: AxisFit
    omega: AxisFit

    @property
    def axes(self) -> tuple[AxisFit, AxisFit]:
        """The fits in AXES order."""
        return (self.v, self.omega)

    @property
    def latency(self) -> float:
        """The base's one command latency: the mean of the axes' (one command path)."""
        return 0.5 * (self.v.latency + self.omega.latency)

    @property
    def actuation_delay(self) -> float:
        """The controller's lead: the latency plus the slower axis' lag.

        The suites' rule (sensing_suites.actuation_delay): a command acts a latency late, and
        a first-order lag follows a ramp its time constant behind.
        """
        return self.latency + max(self.v.lag, self.omega.lag)

    @property
    def acceleration_limits(self) -> tuple[float, float] | None:
        """Both axes' identified limits, or None when either is not identified."""
        if self.v.acceleration is None or self.omega.acceleration is None:
            return None
        return (self.v.acceleration, self.omega.acceleration)

    def reality(self) -> Reality:
        """Return the identified base as a `Reality` (no limit where none was identified)."""
        return Reality(lag=(self.v.lag, self.omega.lag), latency=self.latency,
                       acceleration=tuple(math.inf if fit.acceleration is None
                                          else fit.acceleration for fit in self.axes))


# ---------------------------------------------------------------------------------------
# Reading a record


def read_record(path: str | Path, *, cmd_vel_topic: str = '/cmd_vel',
                odom_topic: str = '/odom') -> Record:
    """Read a rosbag2 folder or a CSV (by what path is).

    Raises:
        FileNotFoundError: if path does not exist.
        ValueError: if it is neither a bag nor a CSV, or cannot be read (the reason).

    """
    path = Path(path)
    if not path.exists():
        msg = f'record not found: {path}'
        raise FileNotFoundError(msg)
    if path.is_dir():
        return read_bag(path, cmd_vel_topic=cmd_vel_topic, odom_topic=odom_topic)
    if path.suffix.lower() == '.csv':
        return read_csv(path)
    msg = f'{path}: neither a rosbag2 folder nor a .csv file'
    raise ValueError(msg)


def read_csv(path: str | Path) -> Record:
    """Read a CSV with the columns t, v_cmd, omega_cmd, v, omega (any order, more allowed).

    Raises:
        ValueError: if a column is missing or no row has a number where it should.

    """
    path = Path(path)
    with open(path, encoding='utf-8') as stream:
        header = [name.strip() for name in stream.readline().strip().split(',')]
    missing = [name for name in CSV_COLUMNS if name not in header]
    if missing:
        msg = (f'{path}: the CSV lacks the column(s) {", ".join(missing)} (it needs '
               f'{", ".join(CSV_COLUMNS)}; its header: {",".join(header)})')
        raise ValueError(msg)
    data = np.genfromtxt(path, delimiter=',', skip_header=1, ndmin=2, dtype=float,
                         invalid_raise=False)
    if data.size == 0 or data.shape[1] != len(header):
        msg = f'{path}: no rows of {len(header)} values under the header'
        raise ValueError(msg)
    column = {name: data[:, header.index(name)] for name in CSV_COLUMNS}
    t = column['t']
    sent = np.isfinite(t) & np.isfinite(column['v_cmd']) & np.isfinite(column['omega_cmd'])
    seen = np.isfinite(t) & np.isfinite(column['v']) & np.isfinite(column['omega'])
    commands = np.column_stack([t[sent], column['v_cmd'][sent], column['omega_cmd'][sent]])
    measured = np.column_stack([t[seen], column['v'][seen], column['omega'][seen]])
    description = f'CSV: {len(commands)} commands, {len(measured)} measured twists'
    return Record(_by_time(commands), _by_time(measured), str(path), description)


def read_bag(bag: str | Path, *, cmd_vel_topic: str = '/cmd_vel',
             odom_topic: str = '/odom') -> Record:
    """Read the commands and the odometry's twist of a rosbag2 folder (rosbags, no ROS).

    Raises:
        ValueError: if the bag cannot be read, lacks a topic or has it with another type.

    """
    from rosbags.rosbag2 import Reader, ReaderError
    from rosbags.typesys import get_typestore, Stores

    # a bag stores absolute names; 'cmd_vel' is the user's '/cmd_vel'
    cmd_vel_topic, odom_topic = ('/' + name.lstrip('/') for name in (cmd_vel_topic, odom_topic))
    typestore = get_typestore(Stores.ROS2_JAZZY)
    cmd_types = ('geometry_msgs/msg/Twist', 'geometry_msgs/msg/TwistStamped')
    wanted = {cmd_vel_topic: cmd_types, odom_topic: ('nav_msgs/msg/Odometry',)}
    # per topic: (received, stamp or nan, v, omega)
    rows: dict[str, list[tuple[float, float, float, float]]] = {cmd_vel_topic: [],
                                                                 odom_topic: []}
    kinds: dict[str, str] = {}
    try:
        with Reader(bag) as reader:
            topics = {c.topic: c.msgtype for c in reader.connections}
            for topic, types in wanted.items():
                if topic not in topics:
                    msg = (f'{bag}: no {topic} in the bag (it has '
                           f'{", ".join(sorted(topics)) or "no topics"}); record '
                           f'{cmd_vel_topic} and {odom_topic}, or name them with '
                           '--cmd-vel-topic / --odom-topic')
                    raise ValueError(msg)
                if topics[topic] not in types:
                    msg = f'{bag}: {topic} is {topics[topic]}, not {" or ".join(types)}'
                    raise ValueError(msg)
                kinds[topic] = topics[topic].rsplit('/', 1)[-1]
            connections = [c for c in reader.connections if c.topic in wanted]
            for connection, received, data in reader.messages(connections=connections):
                message = typestore.deserialize_cdr(data, connection.msgtype)
                stamp = math.nan
                if hasattr(message, 'header'):
                    stamp = (float(message.header.stamp.sec)
                             + 1e-9 * float(message.header.stamp.nanosec))
                twist = message.twist.twist if connection.topic == odom_topic else (
                    message.twist if hasattr(message, 'twist') else message)
                rows[connection.topic].append((1e-9 * received, stamp, float(twist.linear.x),
                                               float(twist.angular.z)))
    except (ReaderError, OSError) as err:
        msg = f'{bag}: not a readable rosbag2 ({err})'
        raise ValueError(msg) from None
    arrays = {}
    clocks = {}
    for topic, found in rows.items():
        if not found:
            msg = f'{bag}: {topic} has no messages'
            raise ValueError(msg)
        table = np.array(found, dtype=float)
        times, clocks[topic] = _times(table[:, 1], table[:, 0])
        arrays[topic] = _by_time(np.column_stack([times, table[:, 2:]]))
    description = (f'rosbag2: {len(arrays[cmd_vel_topic])} {cmd_vel_topic} '
                   f'({kinds[cmd_vel_topic]}, at their {clocks[cmd_vel_topic]}), '
                   f'{len(arrays[odom_topic])} {odom_topic} (at their {clocks[odom_topic]})')
    return Record(arrays[cmd_vel_topic], arrays[odom_topic], str(bag), description)


def _times(stamps: np.ndarray, received: np.ndarray) -> tuple[np.ndarray, str]:
    """Return the header stamps when they are on the recorder's clock, else receive times.

    A stamp says when the measurement was taken; a sender that leaves stamps zero, or a
    clock other than the recorder's (sim time against wall time, an unsynchronised robot),
    cannot be compared with the other topic's times. The label says which, and how far
    apart the two clocks were.
    """
    if not (np.all(np.isfinite(stamps)) and np.all(stamps > 0.0)):
        return received, 'receive times (no stamps)'
    offset = float(np.median(received - stamps))
    if abs(offset) < _STAMP_AGREEMENT:
        return stamps, f'header stamps, received {1000 * offset:.0f} ms after them'
    side = 'ahead of' if offset < 0.0 else 'behind'
    return received, (f"receive times: the stamps were {abs(offset):.3f} s {side} the "
                      "recorder's clock")


def _usable(commands: np.ndarray, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the rows a fit can use, by time.

    A non-finite command is a broken sender, which a base takes as zero (as `Base` does); a
    non-finite twist is a measurement that did not happen.
    """
    commands = _by_time(commands)
    commands = commands[np.isfinite(commands[:, 0])].copy()
    broken = ~np.all(np.isfinite(commands[:, 1:]), axis=1)
    commands[broken, 1:] = 0.0
    measured = _by_time(measured)
    return commands, measured[np.all(np.isfinite(measured), axis=1)]


def _by_time(rows: np.ndarray) -> np.ndarray:
    rows = np.asarray(rows, dtype=float).reshape(-1, 3)
    return rows[np.argsort(rows[:, 0], kind='stable')]


# ---------------------------------------------------------------------------------------
# The model


def simulate_axis(targets: np.ndarray, initial: float, lag: Any, acceleration: Any,
                  step: float) -> tuple[np.ndarray, np.ndarray]:
    """Simulate one axis of `sim.base.Base` for one or many (lag, acceleration) at once.

    Each sub-step of length step moves the velocity toward the target in force at its
    start, as Base._follow does: the first-order lag's exact step, then the rate limit.

    Args:
        targets: (K,) the command reaching the motors at the start of each sub-step.
        initial: the velocity at the start.
        lag: time constant(s) (s), scalar or (C,); 0 = none.
        acceleration: limit(s), scalar or (C,); inf = none.
        step: the sub-step (s).

    Returns:
        (C, K + 1) velocities at the sub-steps' ends (column 0: the start) and (C, K)
        whether the rate limit bound in each sub-step.

    """
    lag, acceleration = np.broadcast_arrays(np.atleast_1d(np.asarray(lag, dtype=float)),
                                            np.atleast_1d(np.asarray(acceleration,
                                                                     dtype=float)))
    alpha = np.where(lag > 0.0, -np.expm1(-step / np.maximum(lag, 1e-300)), 1.0)
    limit = acceleration * step
    velocity = np.full(lag.shape, float(initial))
    out = np.empty((len(lag), len(targets) + 1))
    bound = np.empty((len(lag), len(targets)), dtype=bool)
    out[:, 0] = velocity
    for k, target in enumerate(np.asarray(targets, dtype=float)):
        change = (target - velocity) * alpha
        bound[:, k] = np.abs(change) > limit
        velocity = velocity + np.clip(change, -limit, limit)
        out[:, k + 1] = velocity
    return out, bound


def _simulate_one(targets: list[float], initial: float, lag: float, acceleration: float,
                  step: float) -> np.ndarray:
    """simulate_axis for one (lag, acceleration), in plain floats (the refinement's speed)."""
    alpha = -math.expm1(-step / lag) if lag > 0.0 else 1.0
    limit = acceleration * step
    velocity = float(initial)
    out = [velocity]
    append = out.append
    for target in targets:
        change = (target - velocity) * alpha
        if change > limit:
            change = limit
        elif change < -limit:
            change = -limit
        velocity += change
        append(velocity)
    return np.array(out)


class _Axis:
    """One axis' data on the model's grid, and the residual of a response at a latency."""

    def __init__(self, record: Record, column: int, step: float, max_latency: float) -> None:
        commands, measured = record.commands, record.measured
        self.step = step
        self.command_t = commands[:, 0]
        self.command_u = commands[:, column]
        self.measured_t = measured[:, 0]
        self.measured_y = measured[:, column]
        self.initial = float(self.measured_y[0])
        # the grid covers every shifted sample time t - latency
        self.start = min(self.command_t[0], self.measured_t[0]) - max_latency - step
        count = int(math.ceil((self.measured_t[-1] - self.start) / step)) + 1
        self.grid = self.start + step * np.arange(count)
        # the command in force at each sub-step's start with no latency (a command acts
        # from its sending on); before the first, the base keeps its first measured twist
        index = np.searchsorted(self.command_t, self.grid + 1e-9, side='right') - 1
        self.targets = np.where(index >= 0, self.command_u[np.maximum(index, 0)], self.initial)
        self.target_list = self.targets.tolist()
        self.range = float(np.ptp(self.command_u))
        # the base may have stopped by its own timeout in a silent gap after a non-zero
        # command: those samples, and the model's catching up after it, are not fitted
        self.mask = self.measured_t >= self.command_t[0]
        gaps = np.flatnonzero((np.diff(self.command_t, append=math.inf) > COMMAND_GAP)
                              & (np.abs(self.command_u) > 1e-9))
        for i in gaps:
            end = (self.command_t[i + 1] + RESUME_SETTLE if i + 1 < len(self.command_t)
                   else math.inf)
            self.mask &= ~((self.measured_t > self.command_t[i] + COMMAND_GAP)
                           & (self.measured_t < end))
        self.left_out = int(np.sum(~self.mask & (self.measured_t >= self.command_t[0])))

    def shifted(self, responses: np.ndarray, latency: float) -> np.ndarray:
        """Return responses (C, K + 1) at the fitted sample times delayed by latency."""
        position = (self.measured_t[self.mask] - latency - self.start) / self.step
        index = np.clip(np.floor(position).astype(int), 0, responses.shape[1] - 2)
        fraction = np.clip(position - index, 0.0, 1.0)
        return responses[:, index] * (1.0 - fraction) + responses[:, index + 1] * fraction

    def rms(self, responses: np.ndarray, latency: float) -> np.ndarray:
        """Return the residual RMS of each response at latency."""
        error = self.shifted(responses, latency) - self.measured_y[self.mask]
        return np.sqrt(np.mean(error * error, axis=1))

    def refined_rms(self, latency: float, lag: float, acceleration: float) -> float:
        """Return the residual RMS of one (latency, lag, acceleration)."""
        response = _simulate_one(self.target_list, self.initial, lag, acceleration, self.step)
        return float(self.rms(response[None, :], latency)[0])


def _fit_axis(data: _Axis, grid: _Axis, axis: str, max_latency: float) -> AxisFit:
    """Fit latency, lag and acceleration of one axis (see the module docstring).

    grid is the same axis on the grid stage's sub-step, data on the model's.
    """
    lags, accelerations = (values.ravel()
                           for values in np.meshgrid(_LAG_GRID, _ACCELERATION_GRID))
    responses, _ = simulate_axis(grid.targets, grid.initial, lags, accelerations, grid.step)
    latencies = np.arange(0.0, max_latency + 1e-9, _LATENCY_GRID_STEP)
    table = np.array([grid.rms(responses, latency) for latency in latencies])  # (L, C)
    del responses
    unlimited = ~np.isfinite(accelerations)

    def best(columns: np.ndarray) -> tuple[float, float, float]:
        sub = np.where(columns[None, :], table, np.inf)
        i, j = np.unravel_index(int(np.argmin(sub)), sub.shape)
        return float(latencies[i]), float(lags[j]), float(accelerations[j])

    lo, hi = math.log(ACCELERATION_BOUNDS[0]), math.log(ACCELERATION_BOUNDS[1])
    latency0, lag0, accel0 = best(~unlimited)
    limited = minimize(lambda x: data.refined_rms(x[0], x[1], math.exp(x[2])),
                       np.array([latency0, lag0, math.log(accel0)]), method='Powell',
                       bounds=[(0.0, max_latency), (0.0, MAX_LAG), (lo, hi)],
                       options={'xtol': 1e-4, 'ftol': 1e-6})
    latency0, lag0, _ = best(unlimited)
    free = minimize(lambda x: data.refined_rms(x[0], x[1], math.inf),
                    np.array([latency0, lag0]), method='Powell',
                    bounds=[(0.0, max_latency), (0.0, MAX_LAG)],
                    options={'xtol': 1e-4, 'ftol': 1e-6})
    rms_limited, rms_free = float(limited.fun), float(free.fun)
    latency, lag, acceleration = (float(limited.x[0]), float(limited.x[1]),
                                  math.exp(float(limited.x[2])))
    response, bound = simulate_axis(data.targets, data.initial, lag, acceleration, data.step)
    saturated = _fitted_seconds(data, bound[0], latency)
    identified = saturated >= MIN_SATURATED and rms_free >= MIN_LIMIT_GAIN * rms_limited
    if not identified:
        latency, lag = float(free.x[0]), float(free.x[1])
        response, bound = simulate_axis(data.targets, data.initial, lag, math.inf, data.step)
        saturated = 0.0
    fastest = _fastest_change(data.measured_t[data.mask], data.measured_y[data.mask])
    shifted_targets = data.shifted(data.targets[None, :], latency)[0]
    away = np.abs(shifted_targets - data.shifted(response, latency)[0]) > _CHANGE * data.range
    changes = int(np.sum(np.abs(np.diff(data.command_u)) > _CHANGE * data.range))
    return AxisFit(
        axis=axis, latency=latency, lag=lag,
        acceleration=acceleration if identified else None, fastest_change=fastest,
        rms=rms_limited if identified else rms_free, rms_unlimited=rms_free,
        command_range=data.range, command_changes=changes,
        transient=_sample_seconds(data) * float(np.mean(away)), saturated=saturated,
        fitted=_sample_seconds(data), left_out=_sample_seconds(data, data.left_out))


def _fastest_change(t: np.ndarray, y: np.ndarray) -> float:
    """Return the fastest change of y over _RATE_WINDOW or more (a window damps noise)."""
    later = np.searchsorted(t, t + _RATE_WINDOW - 1e-9)
    first = np.flatnonzero(later < len(t))
    if not len(first):
        return 0.0
    return float(np.max(np.abs(y[later[first]] - y[first]) / (t[later[first]] - t[first])))


def _sample_seconds(data: _Axis, count: int | None = None) -> float:
    """Seconds count samples (default: the fitted ones) span at the median sample period."""
    period = float(np.median(np.diff(data.measured_t))) if len(data.measured_t) > 1 else 0.0
    return period * (int(np.sum(data.mask)) if count is None else count)


def _fitted_seconds(data: _Axis, bound: np.ndarray, latency: float) -> float:
    """Seconds within the fitted samples' span that a sub-step's flag (bound) holds."""
    times = data.grid + latency
    fitted_t = data.measured_t[data.mask]
    inside = (times >= fitted_t[0]) & (times <= fitted_t[-1])
    return float(np.sum(bound & inside)) * data.step


def identify(record: Record, *, max_latency: float = MAX_LATENCY,
             step: float = SIM_STEP) -> Identification:
    """Fit both axes of the base to a record.

    Raises:
        ValueError: if the record is too short, has no motion on an axis, or shows a base
            that did not follow its commands (the reason, and what to record instead).

    """
    if not (math.isfinite(max_latency) and 0.0 < max_latency <= 5.0):
        msg = f'max latency must be in (0, 5] s, got {max_latency}'
        raise ValueError(msg)
    commands, measured = _usable(record.commands, record.measured)
    if len(commands) < 2 or len(measured) < MIN_SAMPLES:
        msg = (f'{record.source}: too short a record ({len(commands)} commands, '
               f'{len(measured)} measured twists; at least 2 and {MIN_SAMPLES})')
        raise ValueError(msg)
    if measured[-1, 0] <= commands[0, 0] or commands[-1, 0] <= measured[0, 0]:
        msg = (f'{record.source}: the commands ({commands[0, 0]:.2f}-{commands[-1, 0]:.2f} s) '
               f'and the measured twists ({measured[0, 0]:.2f}-{measured[-1, 0]:.2f} s) do '
               'not overlap in time (are they on one clock?)')
        raise ValueError(msg)
    record = record._replace(commands=commands, measured=measured)
    fits = []
    for column, axis in enumerate(AXES, start=1):
        data = _Axis(record, column, step, max_latency)
        speed, _ = UNITS[axis]
        if int(np.sum(data.mask)) < MIN_SAMPLES or _sample_seconds(data) < MIN_DURATION:
            msg = (f'{record.source}: too short a record: {_sample_seconds(data):.1f} s of '
                   f'measured twist while commands were sent (at least {MIN_DURATION:g} s; '
                   'drive for half a minute)')
            raise ValueError(msg)
        if data.range < MIN_MOTION[axis]:
            msg = (f'{record.source}: no motion to identify {axis} from: the commanded '
                   f'{axis} spans {data.range:.3g} {speed} (at least {MIN_MOTION[axis]:g}); '
                   'drive a few steps and turns')
            raise ValueError(msg)
        followed = float(np.ptp(data.measured_y[data.mask]))
        if followed < MIN_FOLLOWED * data.range:
            msg = (f'{record.source}: the base did not follow the commands on {axis}: they '
                   f'span {data.range:.3g} {speed}, the measured twist {followed:.3g} '
                   "(is the odometry this base's, and were its motors on?)")
            raise ValueError(msg)
        span = measured[-1, 0] - data.start
        grid = data if span / step <= _GRID_STAGE_STEPS else _Axis(
            record, column, span / _GRID_STAGE_STEPS, max_latency)
        fits.append(_fit_axis(data, grid, axis, max_latency))
    return Identification(record, *fits)


# ---------------------------------------------------------------------------------------
# Reporting


def _number(value: float) -> str:
    """Return a float for YAML with 3 significant digits and a decimal point."""
    text = f'{value:.3g}'
    return text if any(c in text for c in '.en') else text + '.0'


def report(result: Identification, *, max_latency: float = MAX_LATENCY) -> str:
    """Return the fit, its residual and what the record excited, for a terminal."""
    record = result.record
    lines = [f'record: {record.source} ({record.description})',
             f'{"axis":<7}{"latency":>10}{"lag":>10}  {"acceleration":<22}residual RMS']
    for fit in result.axes:
        speed, rate = UNITS[fit.axis]
        accel = (f'{fit.acceleration:.3g} {rate}' if fit.acceleration is not None
                 else 'not identified')
        share = fit.rms / fit.command_range if fit.command_range > 0 else math.inf
        lines.append(f'{fit.axis:<7}{fit.latency:>8.3f} s{fit.lag:>8.3f} s  {accel:<22}'
                     f"{fit.rms:.3g} {speed} ({100 * share:.1f} % of the commands' range)")
    lines.append('what the record excited:')
    for fit in result.axes:
        speed, rate = UNITS[fit.axis]
        fitted = max(fit.fitted, 1e-9)
        gaps = (f' ({fit.left_out:.1f} s left out: the sender was silent for more than '
                f'{COMMAND_GAP:g} s, the base may have stopped by itself)'
                if fit.left_out > 0 else '')
        text = (f'  {fit.axis}: {fit.fitted:.1f} s fitted{gaps}; {fit.command_changes} command '
                f'changes, {fit.transient:.1f} s ({100 * fit.transient / fitted:.0f} %) in '
                'transients (latency, lag); ')
        if fit.acceleration is not None:
            text += (f'the limit binds {fit.saturated:.2f} s '
                     f'({100 * fit.saturated / fitted:.1f} %): acceleration (without a '
                     f'limit the residual is {fit.rms_unlimited:.3g} {speed})')
        else:
            text += (f'no saturation that tells an acceleration limit: not identifiable '
                     f'from this record (the measured twist changed at up to '
                     f'{fit.fastest_change:.3g} {rate} over {_RATE_WINDOW:g} s: a limit, if '
                     'the base has one, is about that or higher); record harder steps')
        lines.append(text)
    for fit in result.axes:
        share = fit.rms / fit.command_range if fit.command_range > 0 else math.inf
        if share > _POOR_FIT:
            lines.append(f'warning: {fit.axis} fits poorly ({100 * share:.0f} % of the range): '
                         'the base does not behave like the model (a velocity smoother, '
                         'a command timeout, slip?)')
        if fit.latency > 0.98 * max_latency:
            lines.append(f'warning: the {fit.axis} latency is at the search bound: raise '
                         '--max-latency')
        if fit.lag > 0.98 * MAX_LAG:
            lines.append(f'warning: the {fit.axis} lag is at the search bound ({MAX_LAG:g} s)')
    spread = abs(result.v.latency - result.omega.latency)
    if spread > 0.02:
        lines.append(f"note: the axes' latencies differ by {spread:.3f} s; one command path "
                     f'has one latency: their mean, {result.latency:.3f} s, is written')
    return '\n'.join(lines)


def parameters_yaml(result: Identification) -> str:
    """Return the ros__parameters for config/<robot>.yaml, with a header naming the record.

    mpc_controller gets the rate limits (when both axes tell theirs), the first-order hold
    and actuation_delay = latency + lag; unicycle_simulator the same base as overrides of
    its reality preset.
    """
    record = result.record
    v, omega = result.v, result.omega
    limits = result.acceleration_limits
    lines = [
        f'# Identified by identify_base from {record.source}',
        f'#   ({record.description}).',
        f'# Residual RMS: v {v.rms:.3g} m/s, omega {omega.rms:.3g} rad/s; per axis: latency '
        f'{v.latency:.3f} / {omega.latency:.3f} s,',
        f'#   lag {v.lag:.3f} / {omega.lag:.3f} s, acceleration '
        + ' / '.join(f'{fit.acceleration:.3g}' if fit.acceleration is not None
                     else 'not identified' for fit in result.axes) + '.',
        '# On top of the defaults, as config/jackal.yaml:',
        '#   ros2 run mpc_local_planner mpc_controller --ros-args \\',
        '#     --params-file config/mpc_controller.yaml --params-file THIS_FILE',
        'mpc_controller:',
        '  ros__parameters:',
    ]
    pair = (f'[{_number(limits[0])}, {_number(limits[1])}]' if limits is not None else None)
    if pair is not None:
        lines += [
            f"    max_accel: {pair}  # the base's acceleration limits [v, omega]",
            f'    max_decel: {pair}  # the base brakes at the same limits',
            '    input_hold: first_order',
        ]
    else:
        missing = ', '.join(f'{fit.axis} (at least {fit.fastest_change:.3g})'
                            for fit in result.axes if fit.acceleration is None)
        lines += [
            '    # max_accel, max_decel, input_hold: first_order: not written: the record '
            'does not',
            f'    # tell the acceleration limit of {missing}; record harder steps',
        ]
    lines += [
        f'    actuation_delay: {_number(result.actuation_delay)}  # s: latency '
        f'{result.latency:.3f} + the slower lag',
        'unicycle_simulator:',
        '  ros__parameters:',
        f'    actuator_lag: [{_number(v.lag)}, {_number(omega.lag)}]',
        '    acceleration_limits: ['
        + ', '.join(_number(fit.acceleration) if fit.acceleration is not None else '-1.0'
                    for fit in result.axes)
        + ']' + ('' if limits is not None else "  # -1: not identified, the preset's"),
        f'    command_latency: {_number(result.latency)}',
    ]
    return '\n'.join(lines) + '\n'


def main(argv: Sequence[str] | None = None) -> int:
    """Identify a base from a record on the command line; 0 on success, 2 on bad input."""
    parser = argparse.ArgumentParser(prog='identify_base', description=__doc__.splitlines()[0])
    parser.add_argument('record', help='a rosbag2 folder (cmd_vel and odom) or a CSV with '
                                       'the columns ' + ', '.join(CSV_COLUMNS))
    parser.add_argument('--write', default=None, metavar='FILE',
                        help='write the ros__parameters for config/<robot>.yaml to FILE')
    parser.add_argument('--cmd-vel-topic', default='/cmd_vel',
                        help='the commands in a bag (Twist or TwistStamped)')
    parser.add_argument('--odom-topic', default='/odom',
                        help='the odometry in a bag (nav_msgs/Odometry; its twist is fitted)')
    parser.add_argument('--max-latency', type=float, default=MAX_LATENCY,
                        help='the largest latency searched (s)')
    args = parser.parse_args(argv)
    try:
        record = read_record(args.record, cmd_vel_topic=args.cmd_vel_topic,
                             odom_topic=args.odom_topic)
        result = identify(record, max_latency=args.max_latency)
        text = parameters_yaml(result)
        if args.write is not None:
            Path(args.write).write_text(text, encoding='utf-8')
    except (FileNotFoundError, ValueError, OSError) as err:
        print(f'identify_base: {err}', file=sys.stderr)
        return 2
    print(report(result, max_latency=args.max_latency))
    if args.write is not None:
        print(f'wrote {args.write}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
