# SPDX-License-Identifier: Apache-2.0
"""The lockstep clock over DDS: simulated time waits for every participant.

A participant here is a node of a second context whose executor the test spins by hand:
while it is not spun, it takes no message and runs no step, and the simulator (spun all
along) must hold its clock however long it is given; once the participant is spun again,
time moves on and its steps come at their exact instants. A participant that never reports
does not hang the simulation: the clock starts after lockstep.timeout and counts the stall.
"""

from __future__ import annotations

from conftest import RosHarness
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from nav_msgs.msg import Odometry
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import UInt32

from mpc_local_planner.ros.lockstep import LockstepReporter, parse_status, status_message
from mpc_local_planner.ros.qos import CONTACTS_QOS, ODOM_QOS
from mpc_local_planner.ros.unicycle_simulator_node import UnicycleSimulatorNode
from mpc_local_planner.ros.unicycle_simulator_parameters import LOCKSTEP_STALLS_TOPIC
from mpc_local_planner.sim.lockstep import awaited_messages, StepStatus

pytestmark = pytest.mark.dds

TIMEOUT = 20.0  # wall seconds before a condition counts as never reached
PERIOD = 0.1  # the participant's step (s of simulated time)


def test_a_status_survives_its_message_and_a_foreign_one_is_refused() -> None:
    status = StepStatus('mpc_controller', 150_000_000, 200_000_000,
                        published={'/cmd_vel': 3}, received={'/odom': 8, '/plan': 1},
                        matched={'/cmd_vel': 1})
    assert parse_status(status_message(status)) == status
    idle = StepStatus('map_server', 0, None, published={'/map': 1})
    assert parse_status(status_message(idle)) == idle
    with pytest.raises(ValueError, match='not a lockstep status'):
        parse_status(DiagnosticStatus(name='x', values=[KeyValue(key='due', value='1')]))


class Stepper(Node):
    """A participant: a step every PERIOD of simulated time, odometry taken, all counted."""

    def __init__(self, context) -> None:
        super().__init__('stepper', context=context,
                         parameter_overrides=[Parameter('use_sim_time', value=True)])
        self.steps: list[int] = []
        self.odometry = 0
        self.create_subscription(Odometry, 'odom', self._odom, ODOM_QOS)
        self.create_timer(PERIOD, self._step)
        self.reporter = LockstepReporter(self)
        self.reporter.attach()
        self.reporter.report()

    def _odom(self, msg: Odometry) -> None:
        self.odometry += 1

    def _step(self) -> None:
        self.steps.append(self.get_clock().now().nanoseconds)


def _simulator(ros: RosHarness, **overrides) -> UnicycleSimulatorNode:
    return ros.add(UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
        Parameter('publish_clock', value=True), Parameter('lockstep', value=True),
        Parameter('lockstep.participants', value=['stepper']),
        *(Parameter(name, value=value) for name, value in overrides.items())]))


def test_the_clock_holds_at_a_due_step_until_the_participant_has_run_it(ros) -> None:
    sim = _simulator(ros)
    other = RosHarness()
    try:
        stepper = other.add(Stepper(other.context))
        # both spun: the clock starts and reaches the first step
        assert ros.tick_until(lambda: (ros.settle(), other.settle()),
                              lambda: stepper.steps == [100_000_000], timeout=TIMEOUT)
        # the participant is not spun: it takes no odometry and runs no step, and the
        # simulator, spun alone however long, moves no further than the tick it published
        held = sim.sim_time
        for _ in range(200):
            ros.executor.spin_once(timeout_sec=0.002)
        assert sim.sim_time <= held + 0.02 + 1e-9 < 0.2
        # spun again, it takes what waited and time moves on, step by step
        assert ros.tick_until(lambda: (ros.settle(), other.settle()),
                              lambda: len(stepper.steps) >= 3, timeout=TIMEOUT)
        assert stepper.steps[:3] == [100_000_000, 200_000_000, 300_000_000]
        assert sim.lockstep_stalls == 0
        # every tick's odometry was taken before time moved past it: one per tick since 0
        assert stepper.odometry >= round(sim.sim_time / 0.02)
    finally:
        other.close()


def test_a_participant_that_never_reports_costs_a_counted_stall_not_a_hang(ros) -> None:
    sim = _simulator(ros, **{'lockstep.timeout': 0.2})
    probe = ros.add(Node('stall_watcher', context=ros.context))
    stalls: list[int] = []
    probe.create_subscription(UInt32, LOCKSTEP_STALLS_TOPIC,
                              lambda msg: stalls.append(msg.data), CONTACTS_QOS)
    assert ros.spin_until(lambda: sim.sim_time > 0.1, timeout=TIMEOUT)
    assert sim.lockstep_stalls == 1
    assert ros.spin_until(lambda: stalls and stalls[-1] == 1, timeout=TIMEOUT)


def test_lockstep_without_publish_clock_is_refused(ros) -> None:
    with pytest.raises(ValueError, match='lockstep needs publish_clock'):
        UnicycleSimulatorNode(context=ros.context, parameter_overrides=[
            Parameter('lockstep', value=True)])


def test_a_reader_matched_late_to_a_latched_topic_has_taken_all_that_matters(ros) -> None:
    # a latched topic (transient_local, depth 1: a plan, a planner's diagnostics) gives a
    # reader that comes late only the latest message; the clock must not wait for the ones
    # before it forever (seen: a recorder matched late under load held every tick 30 s)
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         reliability=ReliabilityPolicy.RELIABLE)
    writer = ros.add(Node('writer', context=ros.context))
    publisher = writer.create_publisher(UInt32, 'latched', latched)
    writer_counts = LockstepReporter(writer, publish=False)
    writer_counts.attach()
    for value in range(3):
        publisher.publish(UInt32(data=value))
    reader = ros.add(Node('reader', context=ros.context))
    taken: list[int] = []
    reader.create_subscription(UInt32, 'latched', lambda msg: taken.append(msg.data), latched)
    reader_counts = LockstepReporter(reader, publish=False)
    reader_counts.attach()
    assert ros.spin_until(lambda: taken == [2], timeout=TIMEOUT)
    statuses = [writer_counts.status(), reader_counts.status()]
    assert statuses[0].published == {'/latched': 3}
    assert awaited_messages(statuses) == []
    publisher.publish(UInt32(data=3))
    assert ros.spin_until(lambda: taken == [2, 3], timeout=TIMEOUT)
    assert awaited_messages([writer_counts.status(), reader_counts.status()]) == []
