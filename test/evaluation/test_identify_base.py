# SPDX-License-Identifier: Apache-2.0
"""identify_base on records made with sim/base.py's Base under known Reality values."""

from __future__ import annotations

from dataclasses import replace
import math
from pathlib import Path
from typing import Callable

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores
import yaml

from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.evaluation import sensing_suites
from mpc_local_planner.evaluation.identify_base import (
    CSV_COLUMNS,
    identify,
    main,
    parameters_yaml,
    read_record,
    Record,
    simulate_axis,
)
from mpc_local_planner.ros import unicycle_simulator_parameters
from mpc_local_planner.ros.mpc_controller_parameters import build_settings, DEFAULTS, PARAMETERS
from mpc_local_planner.sim.base import Base
from mpc_local_planner.sim.reality import Reality

# The brief's base: 0.05 s latency, lags (0.1, 0.08) s, limits (2 m/s^2, 6 rad/s^2), with
# the real preset's odometry noise and drift.
BASE = Reality(lag=(0.1, 0.08), acceleration=(2.0, 6.0), latency=0.05,
               odom_noise=(0.01, 0.01), odom_drift=(0.01, 0.003), seed=3)
ODOMETRY_PERIOD = 0.02  # 50 Hz, as the simulator publishes
COMMAND_PERIOD = 0.05  # 20 Hz, the controller's rate
# white noise on the measured twist (m/s, rad/s): what encoder quantisation looks like
TWIST_NOISE = (0.01, 0.02)

Profile = Callable[[float], tuple[float, float]]


def steps_ramps_and_turns(t: float) -> tuple[float, float]:
    """Speed steps up and down, a ramp, turns in place both ways, then an arc (23 s)."""
    v, omega = 0.0, 0.0
    for start, value in ((1.0, 1.0), (3.0, 0.3), (5.0, 1.5), (7.0, 0.0)):
        if t >= start:
            v = value
    if 9.0 <= t < 11.0:
        v = 0.5 * (t - 9.0)
    elif 11.0 <= t < 13.0:
        v = 1.0 - 0.5 * (t - 11.0)
    for start, value in ((14.0, 2.0), (16.0, -2.0), (18.0, 0.0)):
        if t >= start:
            omega = value
    if 19.0 <= t < 21.0:
        v, omega = 0.5, 1.0
    return v, omega


def gentle(t: float) -> tuple[float, float]:
    """Small steps the lag smooths below the limits: 0.1 m/s and 0.3 rad/s at most."""
    v = 0.1 if (t % 4.0) >= 1.0 and (t % 4.0) < 3.0 else 0.0
    omega = 0.3 if (t % 6.0) >= 2.0 and (t % 6.0) < 4.0 else 0.0
    return v, omega


def record_run(reality: Reality, profile: Profile = steps_ramps_and_turns, *,
               duration: float = 23.0, seed: int = 1,
               silent: tuple[float, float] = (math.inf, math.inf)
               ) -> tuple[np.ndarray, np.ndarray]:
    """Drive a Base with profile: commands (t, v, omega) at 20 Hz, its twist at 50 Hz.

    In the silent interval no command is sent, and 0.25 s after the last one the base's
    watchdog stops it at once (as the simulator's cmd_timeout does).
    """
    rng = np.random.default_rng(seed)
    base = Base(Unicycle(v_max=2.0, omega_max=4.0), reality, np.zeros(3))
    commands, measured = [], []
    tick = 0.01
    for k in range(int(round(duration / tick))):
        t = k * tick
        if k % int(round(COMMAND_PERIOD / tick)) == 0 and not silent[0] <= t < silent[1]:
            u = profile(t)
            base.command(u, t)
            commands.append((t, *u))
        elif commands and round(t - commands[-1][0], 6) == 0.25:
            base.stop(t - reality.latency)
        base.advance(t + tick)
        if (k + 1) % int(round(ODOMETRY_PERIOD / tick)) == 0:
            _, twist = base.odometry()
            measured.append((t + tick, *(twist + rng.normal(0.0, 1.0, 2) * TWIST_NOISE)))
    return np.array(commands), np.array(measured)


def write_csv(path: Path, commands: np.ndarray, measured: np.ndarray) -> Path:
    """Write the CSV form: a row per command and a row per measured twist."""
    rows = [(t, v, omega, math.nan, math.nan) for t, v, omega in commands]
    rows += [(t, math.nan, math.nan, v, omega) for t, v, omega in measured]
    rows.sort(key=lambda row: row[0])
    with open(path, 'w', encoding='utf-8') as stream:
        stream.write(','.join(CSV_COLUMNS) + '\n')
        for row in rows:
            stream.write(','.join('' if math.isnan(x) else f'{x:.9g}' for x in row) + '\n')
    return path


def stamp(t: float) -> Time:
    nanoseconds = int(round(t * 1e9))
    return Time(sec=nanoseconds // 10**9, nanosec=nanoseconds % 10**9)


def write_bag(bag: Path, commands: np.ndarray, measured: np.ndarray, *,
              stamped: bool = False, offset: float = 100.0, stamp_offset: float = 0.0,
              topics: tuple[str, ...] = ('/cmd_vel', '/odom')) -> Path:
    """Write cmd_vel (Twist, or TwistStamped with zero stamps as teleop sends) and odom.

    The recorder's clock reads offset at t = 0; odometry's stamps are stamp_offset ahead.
    """
    typestore = get_typestore(Stores.ROS2_JAZZY)
    cmd_type = 'geometry_msgs/msg/TwistStamped' if stamped else 'geometry_msgs/msg/Twist'
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {}
        if '/cmd_vel' in topics:
            connections['/cmd_vel'] = writer.add_connection('/cmd_vel', cmd_type,
                                                            typestore=typestore)
        if '/odom' in topics:
            connections['/odom'] = writer.add_connection('/odom', 'nav_msgs/msg/Odometry',
                                                         typestore=typestore)
        messages = []
        for t, v, omega in commands:
            twist = Twist()
            twist.linear.x, twist.angular.z = float(v), float(omega)
            message = TwistStamped(twist=twist) if stamped else twist
            messages.append((t, '/cmd_vel', message))
        for t, v, omega in measured:
            odom = Odometry()
            odom.header.stamp = stamp(offset + stamp_offset + t)
            odom.pose.pose.orientation.w = 1.0
            odom.twist.twist.linear.x, odom.twist.twist.angular.z = float(v), float(omega)
            # received a few milliseconds after its stamp
            messages.append((t + 0.003, '/odom', odom))
        for t, topic, message in sorted(messages, key=lambda m: m[0]):
            if topic in connections:
                writer.write(connections[topic], int(round((offset + t) * 1e9)),
                             serialize_message(message))
    return bag


def check_recovered(result, reality: Reality) -> None:
    """Latency within an odometry period, lag within 20 %, the limits within 10 %."""
    for fit, lag, acceleration in zip(result.axes, reality.lag, reality.acceleration,
                                      strict=True):
        assert fit.latency == pytest.approx(reality.latency, abs=ODOMETRY_PERIOD), fit
        assert fit.lag == pytest.approx(lag, rel=0.2), fit
        assert fit.acceleration == pytest.approx(acceleration, rel=0.1), fit
        assert fit.saturated > 0.1 and fit.rms < 1.1 * max(TWIST_NOISE), fit


def test_the_model_fitted_is_the_bases_own_step_for_step() -> None:
    # one axis of Base (no latency) and simulate_axis on the same commands, the same ticks
    reality = Reality(lag=(0.1, 0.08), acceleration=(2.0, 6.0))
    base = Base(Unicycle(v_max=2.0, omega_max=4.0), reality, np.zeros(3))
    targets, speeds = [], []
    for k in range(300):
        u = steps_ramps_and_turns(14.0 + 0.01 * k)
        u = (1.5 if k < 100 else u[0], u[1])
        base.command(u, 0.01 * k)
        base.advance(0.01 * (k + 1))
        targets.append(u)
        speeds.append(base.velocity.copy())
    targets, speeds = np.array(targets), np.array(speeds)
    for i in range(2):
        response, bound = simulate_axis(targets[:, i], 0.0, reality.lag[i],
                                        reality.acceleration[i], 0.01)
        assert np.allclose(response[0, 1:], speeds[:, i], atol=1e-12)
        assert bound[0].any() and not bound[0].all()


def test_a_lagging_late_rate_limited_base_is_recovered_from_its_record() -> None:
    commands, measured = record_run(BASE)
    result = identify(Record(commands, measured, 'generated', 'test'))
    check_recovered(result, BASE)
    assert result.latency == pytest.approx(BASE.latency, abs=ODOMETRY_PERIOD)
    # the controller's lead is the suites' rule on the identified base
    assert result.actuation_delay == pytest.approx(
        sensing_suites.actuation_delay(result.reality()))
    assert result.actuation_delay == pytest.approx(
        sensing_suites.actuation_delay(BASE), abs=0.03)


def test_an_ideal_base_has_no_lag_no_latency_and_no_limit_to_tell() -> None:
    commands, measured = record_run(Reality())
    result = identify(Record(commands, measured, 'generated', 'test'))
    for fit in result.axes:
        assert fit.latency < ODOMETRY_PERIOD and fit.lag < 0.01, fit
        assert fit.acceleration is None and fit.saturated == 0.0, fit
    assert result.acceleration_limits is None


def test_a_record_without_saturation_says_the_limit_is_not_identifiable(
        tmp_path: Path) -> None:
    # the base has its limits, but gentle steps never reach them: the fit must not invent
    # one, yet still finds the lag and the latency
    commands, measured = record_run(BASE, gentle, duration=24.0)
    csv = write_csv(tmp_path / 'gentle.csv', commands, measured)
    result = identify(read_record(csv))
    for fit, lag in zip(result.axes, BASE.lag, strict=True):
        assert fit.acceleration is None, fit
        assert fit.latency == pytest.approx(BASE.latency, abs=ODOMETRY_PERIOD), fit
        assert fit.lag == pytest.approx(lag, rel=0.25), fit
    text = parameters_yaml(result)
    written = yaml.safe_load(text)
    assert 'max_accel' not in written['mpc_controller']['ros__parameters']
    assert 'input_hold' not in written['mpc_controller']['ros__parameters']
    assert 'does not\n    # tell the acceleration limit of v' in text
    # the simulator keeps its preset's limits where none was identified
    overrides = written['unicycle_simulator']['ros__parameters']
    assert overrides['acceleration_limits'] == [-1.0, -1.0]


def test_a_base_stopped_by_its_own_timeout_in_a_silent_gap_is_left_out_of_the_fit() -> None:
    # the sender goes silent for 2 s at full speed: the base's watchdog stops it, which the
    # model does not know; those samples and the catching up after them are not fitted
    commands, measured = record_run(BASE, silent=(5.5, 7.5))
    result = identify(Record(commands, measured, 'generated', 'test'))
    check_recovered(result, BASE)
    assert result.v.left_out == pytest.approx(2.0 - 0.25 + 1.0, abs=0.1)


def test_the_written_file_gives_the_controller_and_the_simulator_the_base(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    commands, measured = record_run(BASE)
    csv = write_csv(tmp_path / 'run.csv', commands, measured)
    out = tmp_path / 'robot.yaml'
    assert main([str(csv), '--write', str(out)]) == 0
    printed = capsys.readouterr().out
    assert 'the limit binds' in printed and f'wrote {out}' in printed
    text = out.read_text(encoding='utf-8')
    assert text.startswith(f'# Identified by identify_base from {csv}')
    assert 'Residual RMS: v 0.01' in text
    written = yaml.safe_load(text)
    controller = written['mpc_controller']['ros__parameters']
    simulator = written['unicycle_simulator']['ros__parameters']
    # only names the nodes declare (a misspelt one would be refused at start)
    assert set(controller) <= {spec.name for spec in PARAMETERS}
    assert set(simulator) <= {spec.name for spec in unicycle_simulator_parameters.PARAMETERS}
    assert controller['input_hold'] == 'first_order'
    config, _, settings = build_settings({**DEFAULTS, **controller})
    assert config.max_accel == pytest.approx(BASE.acceleration, rel=0.1)
    assert settings.max_decel == pytest.approx(BASE.acceleration, rel=0.1)
    assert settings.actuation_delay == pytest.approx(sensing_suites.actuation_delay(BASE),
                                                     abs=0.03)
    # on the ideal preset the overrides alone are the identified base
    reality = unicycle_simulator_parameters.reality_from_parameters(simulator)
    assert reality.latency == pytest.approx(BASE.latency, abs=ODOMETRY_PERIOD)
    assert reality.lag == pytest.approx(BASE.lag, rel=0.2)
    assert reality.acceleration == pytest.approx(BASE.acceleration, rel=0.1)


@pytest.mark.parametrize('stamped', [False, True], ids=['Twist', 'TwistStamped'])
def test_a_bag_of_cmd_vel_and_odom_is_identified(tmp_path: Path, stamped: bool) -> None:
    commands, measured = record_run(BASE)
    bag = write_bag(tmp_path / 'bag', commands, measured, stamped=stamped)
    record = read_record(bag)
    assert len(record.commands) == len(commands) and len(record.measured) == len(measured)
    # odometry at its stamps; a command at its receive time (a Twist has no stamp, and
    # teleop leaves a TwistStamped's zero)
    kind = 'TwistStamped' if stamped else 'Twist'
    assert f'/cmd_vel ({kind}, at their receive times' in record.description
    assert '/odom (at their header stamps, received 3 ms after them)' in record.description
    assert record.measured[0, 0] == pytest.approx(100.0 + measured[0, 0])
    check_recovered(identify(record), BASE)
    # topics named as in ros2 topic, without the leading slash
    assert len(read_record(bag, cmd_vel_topic='cmd_vel', odom_topic='odom').commands) == len(
        commands)


def test_a_broken_command_counts_as_a_stop_and_a_missing_twist_as_no_sample() -> None:
    # the base stops for a non-finite command (as Base and the simulator do): the record
    # is fitted with zero there, and a NaN twist is left out
    reality = replace(BASE, odom_drift=(0.0, 0.0))
    profile = steps_ramps_and_turns

    def broken(t: float) -> tuple[float, float]:
        return (math.nan, 0.5) if 6.0 <= t < 6.5 else profile(t)

    commands, measured = record_run(reality, broken)
    measured[100:110, 1] = math.nan
    result = identify(Record(commands, measured, 'generated', 'test'))
    check_recovered(result, reality)


@pytest.mark.parametrize('clock_offset', [1000.0, 0.1])
def test_odometry_stamped_on_another_clock_falls_back_to_receive_times(
        tmp_path: Path, clock_offset: float) -> None:
    # stamps of a clock 1000 s away (sim time), or 0.1 s (an unsynchronised robot), would
    # shift the latency by the offset: the times the recorder received them are used
    commands, measured = record_run(BASE)
    bag = write_bag(tmp_path / 'bag', commands, measured, stamp_offset=clock_offset)
    record = read_record(bag)
    assert (f'/odom (at their receive times: the stamps were {clock_offset - 0.003:.3f} s '
            "ahead of the recorder's clock") in record.description
    assert record.measured[0, 0] == pytest.approx(100.0 + measured[0, 0] + 0.003)
    assert identify(record).latency == pytest.approx(BASE.latency + 0.003,
                                                     abs=ODOMETRY_PERIOD)


def run_main(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    """Run identify_base, expect exit code 2, return what it said (one line, no traceback)."""
    assert main(list(argv)) == 2
    captured = capsys.readouterr()
    assert captured.out == '' and 'Traceback' not in captured.err
    assert captured.err.startswith('identify_base: ') and captured.err.count('\n') == 1
    return captured.err


def test_bad_records_are_refused_with_the_reason(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    commands, measured = record_run(BASE)
    assert 'record not found' in run_main(capsys, str(tmp_path / 'missing'))
    # a bag without the commands
    bag = write_bag(tmp_path / 'bag', commands, measured, topics=('/odom',))
    assert 'no /cmd_vel in the bag (it has /odom)' in run_main(capsys, str(bag))
    assert 'no /cmd in the bag' in run_main(capsys, str(bag), '--cmd-vel-topic', '/cmd')
    # a folder that is no bag, a file that is neither
    (tmp_path / 'empty').mkdir()
    assert 'not a readable rosbag2' in run_main(capsys, str(tmp_path / 'empty'))
    (tmp_path / 'notes.txt').write_text('hello\n')
    assert 'neither a rosbag2 folder nor a .csv' in run_main(capsys,
                                                             str(tmp_path / 'notes.txt'))
    # a CSV without a column
    (tmp_path / 'columns.csv').write_text('t,v_cmd,v,omega\n0,0,0,0\n')
    assert 'lacks the column(s) omega_cmd' in run_main(capsys, str(tmp_path / 'columns.csv'))
    # too short: one second
    short = write_csv(tmp_path / 'short.csv', commands[commands[:, 0] < 1.5],
                      measured[measured[:, 0] < 1.5])
    assert 'too short a record' in run_main(capsys, str(short))
    # no motion: the robot stood (noise only)
    still = commands.copy()
    still[:, 1:] = 0.0
    _, resting = record_run(BASE, lambda t: (0.0, 0.0))
    idle = write_csv(tmp_path / 'idle.csv', still, resting)
    assert 'no motion to identify v from' in run_main(capsys, str(idle))
    # straight driving only: no turn to identify omega from
    straight = write_csv(tmp_path / 'straight.csv',
                         *record_run(BASE, lambda t: (steps_ramps_and_turns(t)[0], 0.0)))
    assert 'no motion to identify omega from' in run_main(capsys, str(straight))
    # commands the base never followed (motors off): the twist stays at the noise
    stopped = write_csv(tmp_path / 'stopped.csv', commands, resting)
    assert 'did not follow the commands on v' in run_main(capsys, str(stopped))
    assert 'max latency must be in' in run_main(capsys, str(stopped), '--max-latency', '0')
