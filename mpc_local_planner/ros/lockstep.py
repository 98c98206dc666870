# SPDX-License-Identifier: Apache-2.0
"""Lockstep simulation over DDS: participants report their steps, the simulator's clock waits.

A node with ``lockstep: true`` is a participant (`LockstepReporter`): after each of its
callbacks it publishes a `StepStatus` on ``lockstep/status`` saying when its next
simulated-time timer is due and how many messages it has published and taken per topic. A
simulator with ``lockstep: true`` (`LockstepGate`) reads them and moves its clock only when
sim/lockstep.py's rules allow: no participant's step is due, every message is taken. The
nodes themselves are not changed: the reporter counts by wrapping the callbacks of their
subscriptions and timers and the ``publish`` of their publishers, so what runs is the node as
a user runs it.

The status travels as a diagnostic_msgs/DiagnosticStatus (the node's name, and one KeyValue
per figure: ``now``, ``due``, ``pub <topic>``, ``sub <topic>``, ``match <topic>``), which
any ROS tool can echo.
"""

from __future__ import annotations

from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription

from mpc_local_planner.ros.parameters import ParameterSpec
from mpc_local_planner.sim.lockstep import (
    awaited_matches,
    awaited_messages,
    awaited_participants,
    awaited_steps,
    StepStatus,
)

__all__ = ['LOCKSTEP_PARAMETER', 'LOCKSTEP_TOPIC', 'LockstepGate', 'LockstepReporter',
           'STATUS_QOS', 'parse_status', 'status_message']

# Where participants report (relative: a namespaced simulation has its own).
LOCKSTEP_TOPIC = 'lockstep/status'
# A status holds everything its node has done (counts since its start), so each one
# supersedes the one before: a participant keeps its latest for a simulator that starts after
# it (transient local, depth 1); the simulator reads them all, from every participant
# (depth 100: one participant's burst must not push out another's latest).
STATUS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
STATUS_READER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                               reliability=ReliabilityPolicy.RELIABLE,
                               durability=DurabilityPolicy.TRANSIENT_LOCAL)
# Every participating node's switch (simulation and evaluation only: a robot has no
# lockstep clock).
LOCKSTEP_PARAMETER = ParameterSpec(
    'lockstep', False,
    'report each step on lockstep/status so that a lockstep simulator (unicycle_simulator '
    "with lockstep) holds simulated time until this node's due steps are done and its "
    'messages taken; simulation and evaluation only', read_only=True)
# Wall seconds between a participant's looks for changes no callback of its own reports.
RECHECK_PERIOD = 0.1
# Topics that are not the participants' data: the clock itself, ROS's own, the protocol's.
_UNCOUNTED = ('/clock', '/parameter_events', '/rosout')


def counted(topic: str) -> bool:
    """Whether messages on topic are counted (the participants' data, not ROS's own)."""
    return topic not in _UNCOUNTED and not topic.endswith('/' + LOCKSTEP_TOPIC)


def status_message(status: StepStatus) -> DiagnosticStatus:
    """Return the status as a DiagnosticStatus (name: the node; one KeyValue per figure)."""
    values = [KeyValue(key='now', value=str(status.now_ns)),
              KeyValue(key='due', value='' if status.due_ns is None else str(status.due_ns))]
    for prefix, counts in (('pub', status.published), ('sub', status.received),
                           ('match', status.matched)):
        values += [KeyValue(key=f'{prefix} {topic}', value=str(int(count)))
                   for topic, count in sorted(counts.items())]
    return DiagnosticStatus(level=DiagnosticStatus.OK, name=status.node, values=values)


def parse_status(msg: DiagnosticStatus) -> StepStatus:
    """Return the StepStatus a DiagnosticStatus carries.

    Raises:
        ValueError: if it is not one (a figure missing or not an integer).

    """
    found: dict[str, dict[str, int]] = {'pub': {}, 'sub': {}, 'match': {}}
    now: int | None = None
    due: int | None = None
    for value in msg.values:
        key, _, topic = value.key.partition(' ')
        if key == 'now':
            now = int(value.value)
        elif key == 'due':
            due = int(value.value) if value.value else None
        elif key in found and topic:
            found[key][topic] = int(value.value)
    if now is None or not msg.name:
        msg_text = f'not a lockstep status: {msg.name!r} without its time'
        raise ValueError(msg_text)
    return StepStatus(node=msg.name, now_ns=now, due_ns=due, published=found['pub'],
                      received=found['sub'], matched=found['match'])


class LockstepReporter:
    """Count a node's messages and report its steps to a lockstep simulator.

    `attach` wraps what the node has at that moment (call it again after the node creates
    timers or subscriptions, e.g. after activation: it wraps each entity once); every
    wrapped callback ends with a report. The simulator may also count for itself: `status`
    without publishing.
    """

    def __init__(self, node: Node, *, publish: bool = True,
                 on_report: Callable[[], None] | None = None) -> None:
        """Start counting for node: reports go to LOCKSTEP_TOPIC when publish, else on_report.

        The simulator counts its own messages without publishing them: on_report then
        tells it that a callback of its own ended (a cmd_vel was taken).
        """
        self._node = node
        self._on_report = on_report
        self._published: dict[str, int] = {}
        self._taken: dict[int, tuple[str, int]] = {}  # id(subscription) -> (topic, count)
        self._publishers: dict[str, Any] = {}
        self._pub = node.create_publisher(DiagnosticStatus, LOCKSTEP_TOPIC, STATUS_QOS) \
            if publish else None
        self._reported: StepStatus | None = None
        # what changes without a callback of the node's (a reader matched): said on a
        # steady timer, only when it differs from the last report
        self._recheck = node.create_timer(RECHECK_PERIOD, self._report_changes,
                                          clock=Clock(clock_type=ClockType.STEADY_TIME)) \
            if publish else None

    def attach(self) -> None:
        """Wrap the node's subscriptions, sim-time timers and publishers not yet wrapped."""
        for subscription in self._node.subscriptions:
            topic = subscription.topic_name
            if (counted(topic) and not getattr(subscription.callback, '_lockstep', False)
                    and subscription._callback_type is Subscription.CallbackType.MessageOnly):
                self._taken[id(subscription)] = (topic, 0)
                subscription.callback = self._counting(subscription)
        for timer in self._node.timers:
            if timer.clock.clock_type == ClockType.ROS_TIME and not getattr(
                    timer.callback, '_lockstep', False):
                timer.callback = self._reporting(timer.callback)
        for publisher in self._node.publishers:
            topic = publisher.topic_name
            if counted(topic) and topic not in self._publishers:
                self._publishers[topic] = publisher
                self._published.setdefault(topic, 0)
                publisher.publish = self._publishing(publisher.publish, topic)

    def status(self) -> StepStatus:
        """Return what the node has done so far (its next sim-time timer: due)."""
        now = self._node.get_clock().now().nanoseconds
        due = None
        for timer in self._node.timers:
            if timer.clock.clock_type != ClockType.ROS_TIME or timer.is_canceled():
                continue
            left = timer.time_until_next_call()
            if left is not None:
                due = now + int(left) if due is None else min(due, now + int(left))
        received: dict[str, int] = {}
        alive = {id(subscription) for subscription in self._node.subscriptions}
        for key, (topic, count) in self._taken.items():
            if key in alive:  # a destroyed subscription (a cleanup) takes nothing more
                received[topic] = min(received.get(topic, count), count)
        matched = {topic: publisher.get_subscription_count()
                   for topic, publisher in self._publishers.items()}
        return StepStatus(node=self._node.get_name(), now_ns=now, due_ns=due,
                          published=dict(self._published), received=received,
                          matched=matched)

    def report(self) -> None:
        """Publish the status now (after a callback; at start, to say the node is there)."""
        if self._pub is not None:
            self.attach()
            self._reported = self.status()
            self._pub.publish(status_message(self._reported))
        elif self._on_report is not None:
            self._on_report()

    def _report_changes(self) -> None:
        if self._reported is not None and self.status() != self._reported:
            self.report()

    def _counting(self, subscription: Any) -> Callable[[Any, Any], None]:
        """Wrap a subscription's callback: count what it takes, then report.

        What a reader has taken is the larger of its count and the latest publication
        sequence number it has seen (DDS numbers each writer's messages 1, 2, ...): a reader
        matched late to a latched topic (transient_local, depth 1) gets only the latest
        message, and has then all the same taken everything that matters.
        """
        callback = subscription.callback
        key = id(subscription)

        def counting(msg: Any, info: Any) -> None:
            try:
                callback(msg)
            finally:
                topic, count = self._taken[key]
                sequence = info.get('publication_sequence_number') if isinstance(
                    info, dict) else None
                self._taken[key] = (topic, max(count + 1, int(sequence or 0)))
                self.report()
        counting._lockstep = True  # type: ignore[attr-defined]
        return counting

    def _reporting(self, callback: Callable[[], Any]) -> Callable[[], None]:
        def reporting() -> None:
            try:
                callback()
            finally:
                self.report()
        reporting._lockstep = True  # type: ignore[attr-defined]
        return reporting

    def _publishing(self, publish: Callable[[Any], None], topic: str) -> Callable[[Any], None]:
        publisher = self._publishers[topic]

        def publishing(msg: Any) -> None:
            publish(msg)
            # a lifecycle publisher of an inactive node writes nothing
            if getattr(publisher, '_enabled', True):
                self._published[topic] += 1
        return publishing


class LockstepGate:
    """The simulator's side: what the participants said, and when its clock may move.

    It keeps each participant's latest status (from LOCKSTEP_TOPIC) and counts the
    simulator's own messages with a reporter of its own; `awaited` says what is still
    missing before the next move, `passes` decides, giving up after ``timeout`` wall seconds
    of waiting for one move (a participant that died or hangs: the simulation goes on, the
    stall is counted and logged with what was awaited).
    """

    def __init__(self, node: Node, participants: list[str], timeout: float,
                 on_status: Callable[[], None]) -> None:
        """Subscribe to the statuses; on_status runs after each one (to try the next move)."""
        self._node = node
        self.participants = list(participants)
        self.timeout = float(timeout)
        self.own = LockstepReporter(node, publish=False, on_report=on_status)
        self.statuses: dict[str, StepStatus] = {}
        self.stalls = 0
        self._on_status = on_status
        self._waiting_since: float | None = None
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._sub = node.create_subscription(DiagnosticStatus, LOCKSTEP_TOPIC,
                                             self._status_callback, STATUS_READER_QOS)

    def _status_callback(self, msg: DiagnosticStatus) -> None:
        try:
            status = parse_status(msg)
        except ValueError as err:
            self._node.get_logger().warning(f'lockstep: {err}', throttle_duration_sec=5.0)
            return
        if status.node in self.participants:
            self.statuses[status.node] = status
        self._on_status()

    def _all(self) -> list[StepStatus]:
        self.own.attach()
        return [*self.statuses.values(), self.own.status()]

    def awaited_start(self) -> list[str]:
        """What keeps the clock from starting: a participant not there, a reader unmatched."""
        return (awaited_participants(self.statuses, self.participants)
                or awaited_matches(self._all()))

    def awaited_messages(self) -> list[str]:
        """The messages published and not yet taken by a participant."""
        return awaited_messages(self._all())

    def awaited_steps(self, now_ns: int) -> list[str]:
        """The participants' steps due by now_ns and not done, and untaken messages."""
        statuses = self._all()
        return awaited_steps(statuses, now_ns) + awaited_messages(statuses)

    def due(self, now_ns: int) -> bool:
        """Whether a participant's step is due by now_ns (by its latest status)."""
        return any(status.due_ns is not None and status.due_ns <= now_ns
                   for status in self.statuses.values())

    def passes(self, awaited: list[str], what: str) -> bool:
        """Say whether the move may happen now: nothing awaited, or waited timeout already."""
        now = self._steady.now().nanoseconds * 1e-9
        if not awaited:
            self._waiting_since = None
            return True
        if self._waiting_since is None:
            self._waiting_since = now
            return False
        if now - self._waiting_since < self.timeout:
            return False
        self._waiting_since = None
        self.stalls += 1
        self._node.get_logger().warning(
            f'lockstep: waited {self.timeout:g} s (wall) to {what}; going on without: '
            + '; '.join(awaited[:5]) + (f' (and {len(awaited) - 5} more)'
                                        if len(awaited) > 5 else ''))
        return True
