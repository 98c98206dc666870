# SPDX-License-Identifier: Apache-2.0
"""unicycle_simulator takes cmd_vel as Twist or, with enable_stamped_cmd_vel, TwistStamped.

Both are handled alike: a valid command moves the robot, a non-finite one stops it with an
error, and silence longer than cmd_timeout (simulated time) stops it too. With ``reality``
the robot is a real one (sim/reality.py): its wheels lag the command, a command arrives late,
its scans have NaN beams and some never come; every check counts in simulated time.
"""

from __future__ import annotations

from dataclasses import replace
import math

from geometry_msgs.msg import PoseWithCovarianceStamped, Twist, TwistStamped
import numpy as np
import pytest
from rcl_interfaces.msg import Log
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan

from mpc_local_planner.ros.conversions import stamp_to_seconds, twist_from_u, twist_stamped_from_u
from mpc_local_planner.ros.qos import CMD_VEL_QOS, LOCALIZER_QOS
from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode
from mpc_local_planner.ros.unicycle_simulator_parameters import (
    LOCALIZER_TOPIC,
    PARAMETERS,
    reality_from_parameters,
    SCAN_TOPIC,
    validate_simulator_parameters,
)
from mpc_local_planner.sim.reality import REALITY_PRESETS

pytestmark = pytest.mark.dds  # topics over DDS

# Wall seconds before a condition counts as never reached.
TIMEOUT = 20.0
CMD_TIMEOUT = 0.5  # s of simulated time
ROSOUT_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)


@pytest.mark.parametrize(('stamped', 'msg_type'), [(False, Twist), (True, TwistStamped)],
                         ids=['Twist', 'TwistStamped'])
def test_the_simulator_takes_cmd_vel_of_the_configured_type_with_the_same_checks(
        ros, stamped, msg_type) -> None:
    sim = ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter('enable_stamped_cmd_vel', value=stamped),
        Parameter('publish_clock', value=True), Parameter('real_time_factor', value=10.0),
        Parameter('cmd_timeout', value=CMD_TIMEOUT)]))
    # not the conftest Probe: its Twist endpoints on cmd_vel would clash (one DDS participant
    # per context) with a TwistStamped publisher
    probe = ros.add(Node('commander', context=ros.context))
    cmd_pub = probe.create_publisher(msg_type, 'cmd_vel', CMD_VEL_QOS)
    errors: list[str] = []

    def rosout(entry: Log) -> None:
        if entry.name == 'unicycle_simulator' and entry.level == Log.ERROR:
            errors.append(entry.msg)

    probe.create_subscription(Log, '/rosout', rosout, ROSOUT_QOS)

    def simulator_type() -> list[str]:
        return [info.topic_type for info in probe.get_subscriptions_info_by_topic('/cmd_vel')
                if info.node_name == 'unicycle_simulator']

    expected = 'geometry_msgs/msg/TwistStamped' if stamped else 'geometry_msgs/msg/Twist'
    assert ros.spin_until(lambda: simulator_type() == [expected]
                          and cmd_pub.get_subscription_count() > 0, timeout=TIMEOUT)

    def command(v: float) -> Twist | TwistStamped:
        if stamped:
            return twist_stamped_from_u([v, 0.0], stamp=probe.get_clock().now().to_msg())
        return twist_from_u([v, 0.0])

    def drive(v: float, distance: float) -> None:
        x0 = sim.state[0]

        def moved() -> bool:
            cmd_pub.publish(command(v))
            return sim.state[0] - x0 >= distance

        assert ros.spin_until(moved, timeout=TIMEOUT)

    def stands_still_for(span: float) -> None:
        x, t = sim.state[0], sim.sim_time
        assert ros.spin_until(lambda: sim.sim_time - t >= span, timeout=TIMEOUT)
        assert sim.state[0] == x

    drive(0.2, 0.05)
    # NaN: stop at once, with an error
    cmd_pub.publish(command(math.nan))
    assert ros.spin_until(lambda: any('invalid cmd_vel' in line for line in errors),
                          timeout=TIMEOUT)
    stands_still_for(0.2)
    # valid again: moves; then silence beyond cmd_timeout: stops
    drive(0.2, 0.05)
    t_last = sim.sim_time
    assert ros.spin_until(lambda: sim.sim_time - t_last > CMD_TIMEOUT + 0.1, timeout=TIMEOUT)
    # a command still in flight when the drive stopped may come late (DDS on a loaded
    # machine) and start the robot again for cmd_timeout: once that has passed, it stands
    x, t = sim.state[0], sim.sim_time
    assert ros.spin_until(lambda: sim.sim_time - t >= CMD_TIMEOUT + 0.2, timeout=TIMEOUT)
    if sim.state[0] != x:
        t_late = sim.sim_time
        assert ros.spin_until(lambda: sim.sim_time - t_late > CMD_TIMEOUT + 0.1,
                              timeout=TIMEOUT)
    stands_still_for(0.2)


def test_drifting_odometry_and_the_localizer_stand_in(ros) -> None:
    """Drifting odometry and the localizer stand-in.

    5 % and 0.05 rad/m of drift: odometry says 1.05 m and 0.05 rad per true metre, while the
    localizer stand-in publishes the true pose (no noise here) in map at its rate.
    """
    sim = ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter('publish_clock', value=True), Parameter('real_time_factor', value=10.0),
        Parameter('cmd_timeout', value=0.0), Parameter('odom_drift.position', value=0.05),
        Parameter('odom_drift.heading', value=0.05), Parameter('localizer.rate', value=5.0),
        Parameter('localizer.noise_std', value=0.0)]))
    probe = ros.add(Node('commander', context=ros.context))
    cmd_pub = probe.create_publisher(Twist, 'cmd_vel', CMD_VEL_QOS)
    poses: list[PoseWithCovarianceStamped] = []
    probe.create_subscription(PoseWithCovarianceStamped, LOCALIZER_TOPIC, poses.append,
                              LOCALIZER_QOS)
    assert ros.spin_until(lambda: cmd_pub.get_subscription_count() > 0, timeout=TIMEOUT)
    cmd_pub.publish(twist_from_u([0.5, 0.0]))
    start = sim.sim_time
    assert ros.spin_until(lambda: sim.state[0] >= 1.0, timeout=TIMEOUT)
    cmd_pub.publish(twist_from_u([0.0, 0.0]))
    stopped = sim.sim_time

    def localized_standing() -> bool:  # a localizer pose of the robot standing still
        return (sim.sim_time - stopped > 0.5 and bool(poses)
                and poses[-1].pose.pose.position.x == sim.state[0])

    assert ros.spin_until(localized_standing, timeout=TIMEOUT)
    true, odom = sim.state, sim.odometry
    assert true[1] == 0.0 and true[2] == 0.0  # straight in truth
    assert odom[2] == pytest.approx(0.05 * true[0], rel=1e-6)  # 0.05 rad per metre
    # the odometry's path is an arc of length 1.05 x the true distance
    chord = 2 * (1.05 * true[0] / odom[2]) * math.sin(odom[2] / 2)
    assert math.hypot(odom[0], odom[1]) == pytest.approx(chord, rel=1e-3)
    last = poses[-1]
    assert last.header.frame_id == 'map'
    assert last.pose.pose.position.y == 0.0
    seconds = sim.sim_time - start
    assert len(poses) <= 5 * seconds + 2  # at localizer.rate


def real_simulator(ros, **values) -> UnicycleSimulatorNode:
    """A simulator owning the clock (10 x real time), no cmd_timeout, with these values."""
    values = {'publish_clock': True, 'real_time_factor': 10.0, 'rate': 50.0,
              'cmd_timeout': 0.0, **values}
    return ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter(name, value=value) for name, value in values.items()]))


def test_with_reality_real_the_measured_twist_rises_gradually_after_a_step_command(
        ros) -> None:
    """The real preset's wheels lag (0.1 s) and accelerate at most 2 m/s^2: no jump."""
    sim = real_simulator(ros, reality='real')
    assert sim.reality == REALITY_PRESETS['real']
    probe = ros.probe()
    assert ros.spin_until(lambda: probe.cmd_pub.get_subscription_count() > 0, timeout=TIMEOUT)
    v = 0.3
    probe.cmd_pub.publish(twist_from_u([v, 0.0]))
    scale = REALITY_PRESETS['real'].odom_drift[0]  # what the encoders count

    def speeds() -> list[float]:
        return [m.twist.twist.linear.x for m in probe.odoms]

    assert ros.spin_until(lambda: max(speeds(), default=0.0) >= 0.99 * v * (1 + scale),
                          timeout=TIMEOUT)
    rising = [s for s in speeds() if s > 0.0]
    # not at once: the first measured speeds are a fraction of the command, and they grow by
    # at most the acceleration limit per tick (odometry may skip a message: two ticks)
    assert rising[0] < 0.5 * v
    assert sum(0.0 < s < 0.9 * v for s in rising) >= 3
    assert np.all(np.diff(rising) <= 2 * 2.0 * (1 + scale) / 50.0 + 1e-9)
    assert np.all(np.diff(rising) >= -1e-9)  # a step up: never back down


def test_with_command_latency_the_robot_stands_until_the_latency_has_passed(ros) -> None:
    latency = 0.3
    sim = real_simulator(ros, command_latency=latency)
    assert sim.reality.latency == latency and sim.reality.lag == (0.0, 0.0)
    probe = ros.probe()
    assert ros.spin_until(lambda: probe.cmd_pub.get_subscription_count() > 0, timeout=TIMEOUT)
    sent = sim.sim_time  # the command arrives at this simulated time or later
    probe.cmd_pub.publish(twist_from_u([0.2, 0.0]))
    assert ros.spin_until(lambda: sim.state[0] > 0.02, timeout=TIMEOUT)
    moving = [m for m in probe.odoms if m.pose.pose.position.x > 0.0]
    standing = [m for m in probe.odoms if m.pose.pose.position.x == 0.0]
    assert moving and standing
    started = stamp_to_seconds(moving[0].header.stamp)
    # the first moved pose is one tick after the command reached the motors
    assert started >= sent + latency + 1.0 / 50.0 - 1e-6
    assert all(m.twist.twist.linear.x == 0.0 for m in standing)
    assert all(stamp_to_seconds(m.header.stamp) < started for m in standing)


def test_an_unknown_reality_is_refused_with_the_known_ones(ros) -> None:
    with pytest.raises(ParameterException, match='reality must be one of ideal|mild'):
        UnicycleSimulatorNode(context=ros.context,
                              parameter_overrides=[Parameter('reality', value='realistic')])
    sim = ros.add(UnicycleSimulatorNode(context=ros.context))
    [result] = sim.set_parameters([Parameter('reality', value='realistic')])
    assert not result.successful and 'ideal|mild|real|harsh' in result.reason
    assert sim.get_parameter('reality').value == 'ideal' and sim.reality.ideal
    # a combination only Reality can judge: NaN and -inf beams together at least 1
    [result] = sim.set_parameters([Parameter('scan.nan_fraction', value=0.6)])
    assert result.successful and sim.reality.scan_nan == 0.6
    [result] = sim.set_parameters([Parameter('scan.neg_inf_fraction', value=0.5)])
    assert not result.successful and 'scan.neg_inf_fraction' in result.reason
    assert sim.reality.scan_neg_inf == 0.0
    # a valid preset at run time replaces the reality; the override set stays
    [result] = sim.set_parameters([Parameter('reality', value='harsh')])
    assert result.successful
    assert sim.reality == replace(REALITY_PRESETS['harsh'], scan_nan=0.6)


def test_scans_have_nan_beams_and_some_are_lost_counted_in_simulated_time(ros) -> None:
    rate = 50.0  # one scan per tick: every tick is a scan's slot
    sim = real_simulator(ros, **{'scan.rate': rate, 'scan.beams': 200,
                                 'scan.nan_fraction': 0.2, 'scan.neg_inf_fraction': 0.05,
                                 'scan.loss_fraction': 0.3, 'seed': 7})
    probe = ros.probe()
    scans: list[LaserScan] = []
    reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
    probe.create_subscription(LaserScan, SCAN_TOPIC, scans.append, reliable)
    assert ros.spin_until(lambda: len(scans) >= 100, timeout=TIMEOUT)
    assert sim.sim_time < 10.0
    stamps = np.array([stamp_to_seconds(m.header.stamp) for m in scans])
    slots = int(round((stamps[-1] - stamps[0]) * rate)) + 1
    lost = 1.0 - len(scans) / slots
    assert 0.15 < lost < 0.45  # 0.3 of the scans never come
    # the gaps are whole ticks: a lost scan is a missing slot, not a shifted one
    np.testing.assert_allclose(stamps * rate, np.round(stamps * rate), atol=1e-6)
    ranges = np.concatenate([np.array(m.ranges) for m in scans])
    assert 0.15 < np.isnan(ranges).mean() < 0.25
    assert 0.03 < np.isneginf(ranges).mean() < 0.07
    assert np.all(np.isposinf(ranges[~np.isnan(ranges) & ~np.isneginf(ranges)]))  # empty world


def test_validate_simulator_parameters_gives_a_reason_for_each_bad_reality_value() -> None:
    assert validate_simulator_parameters({
        'reality': 'harsh', 'actuator_lag': [0.2, -1.0], 'acceleration_limits': [math.inf, 2.0],
        'command_latency': 0.0, 'odom_noise_std': [0.0, 0.01], 'scan.nan_fraction': -1.0,
        'scan.neg_inf_fraction': 0.0, 'scan.loss_fraction': 0.5}) is None
    bad = {'reality': 'realistic', 'actuator_lag': [0.1], 'acceleration_limits': [0.0, 1.0],
           'odom_noise_std': [math.inf, 0.0], 'command_latency': math.inf,
           'scan.nan_fraction': 1.0, 'scan.neg_inf_fraction': math.nan,
           'scan.loss_fraction': 'half'}
    for name, value in bad.items():
        reason = validate_simulator_parameters({name: value})
        assert reason is not None and reason.startswith(name), (name, reason)


def test_zero_switches_an_imperfection_off_and_only_minus_one_takes_the_presets(ros) -> None:
    real = REALITY_PRESETS['real']
    zeros = {'scan.noise_std': 0.0, 'odom_drift.position': 0.0, 'odom_drift.heading': 0.0,
             'command_latency': 0.0, 'actuator_lag': [0.0, 0.0], 'odom_noise_std': [0.0, 0.0],
             'scan.nan_fraction': 0.0, 'scan.neg_inf_fraction': 0.0, 'scan.loss_fraction': 0.0}
    off = reality_from_parameters({'reality': 'real', **zeros})
    assert off.scan_noise == 0.0 and off.odom_drift == (0.0, 0.0) and off.latency == 0.0
    assert off.ideal_laser and off.odom_noise == (0.0, 0.0) and off.lag == (0.0, 0.0)
    assert off.acceleration == real.acceleration  # not overridden: the preset's
    # the node alike: a real base with an exact laser
    sim = ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter('reality', value='real'), Parameter('scan.noise_std', value=0.0)]))
    assert sim.reality.scan_noise == 0.0 and sim.reality.odom_drift == real.odom_drift
    # one marker: any other negative value is refused, not taken for "the preset's"
    # and every override is held to the range docs/parameters.md shows, arrays too
    for name, value in [('scan.noise_std', -0.5), ('command_latency', -2.0),
                        ('odom_drift.heading', -0.7), ('actuator_lag', [-0.5, 0.0]),
                        ('actuator_lag', [20.0, 0.0]), ('odom_noise_std', [0.0, 11.0])]:
        reason = validate_simulator_parameters({name: value})
        assert reason is not None and reason.startswith(name) and '-1, or' in reason, reason
        [result] = sim.set_parameters([Parameter(name, value=value)])
        assert not result.successful and name in result.reason


def test_one_seed_named_for_what_it_seeds_the_odometry_noise_and_the_laser(ros) -> None:
    sim = ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter('reality', value='real'), Parameter('seed', value=5)]))
    # it seeds the odometry's noise too, so it is not the laser's (scan.*) alone
    assert not sim.has_parameter('scan.seed')
    assert sim.reality.seed == 5 and sim.reality.odom_noise == REALITY_PRESETS['real'].odom_noise
    assert sim.set_parameters([Parameter('seed', value=6)])[0].successful
    assert sim.reality.seed == 6


def test_reality_parameters_override_the_preset_field_by_field() -> None:
    real = REALITY_PRESETS['real']
    assert reality_from_parameters({}) == REALITY_PRESETS['ideal']
    # the defaults, -1 each, are the preset's
    defaults = {'actuator_lag': [-1.0, -1.0], 'acceleration_limits': [-1.0, -1.0],
                'command_latency': -1.0, 'odom_noise_std': [-1.0, -1.0],
                'scan.nan_fraction': -1.0, 'scan.neg_inf_fraction': -1.0,
                'scan.loss_fraction': -1.0, 'scan.noise_std': -1.0,
                'odom_drift.position': -1.0, 'odom_drift.heading': -1.0, 'seed': 0}
    assert defaults == {spec.name: spec.default for spec in PARAMETERS
                        if spec.name in defaults}
    assert reality_from_parameters({'reality': 'real', **defaults}) == real
    mixed = reality_from_parameters({'reality': 'real', **defaults, 'actuator_lag': [0.0, -1.0],
                                     'command_latency': 0.0, 'odom_drift.position': 0.05,
                                     'scan.noise_std': 0.05, 'seed': 3})
    assert mixed.lag == (0.0, real.lag[1]) and mixed.latency == 0.0
    assert mixed.odom_drift == (0.05, real.odom_drift[1]) and mixed.scan_noise == 0.05
    assert mixed.seed == 3 and mixed.acceleration == real.acceleration
    with pytest.raises(ValueError, match='reality must be one of'):
        reality_from_parameters({'reality': 'Real'})
