# SPDX-License-Identifier: Apache-2.0
"""What a lockstep clock waits for before simulated time may move (no rclpy).

Run as separate processes over DDS, the nodes of a simulation see time move while they
compute: a control step that takes 80 ms on a busy machine sees the robot 80 ms further on
than on a quiet one, and a scan published just before a clock tick may reach the
controller just after it. A lockstep simulator removes both: simulated time moves only when
every participating node has finished what is due, and every message published so far has
been taken by every participant that subscribes to it. Then a run is the same whatever the
machine's load (as the in-process suites are), and it shows what the nodes compute, not how
fast.

Each participant says, in a `StepStatus`, when its next simulated-time timer is due, how
many messages it has published and taken per topic, and how many readers each of its
publishers has matched. The rules below read those statuses (the simulator's own among them);
they return what is still awaited, one line each, so that a clock that gives up waiting
(its wall-time guard) can say on what.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Mapping

__all__ = ['StepStatus', 'awaited_matches', 'awaited_messages', 'awaited_participants',
           'awaited_steps']


@dataclass(frozen=True)
class StepStatus:
    """What one participant of a lockstep simulation has done, by its own account.

    Attributes:
        node: Its name (without namespace).
        now_ns: Its simulated time when it said so (ns).
        due_ns: When its next simulated-time timer fires (ns); None: it has none.
        published: Messages published per topic (resolved names).
        received: Messages taken per topic (the fewest of its subscriptions to that topic).
        matched: Readers matched per topic it publishes.

    """

    node: str
    now_ns: int
    due_ns: int | None
    published: Mapping[str, int] = field(default_factory=dict)
    received: Mapping[str, int] = field(default_factory=dict)
    matched: Mapping[str, int] = field(default_factory=dict)


def awaited_participants(statuses: Mapping[str, StepStatus],
                         participants: Iterable[str]) -> list[str]:
    """Return the participants that have not reported yet (they may still be starting)."""
    return [f'{name} has not reported' for name in participants if name not in statuses]


def awaited_matches(statuses: Iterable[StepStatus]) -> list[str]:
    """Return the publishers that have not matched every participant reading their topic.

    A message published before its reader is matched is never delivered (volatile
    durability), and that reader would wait forever for it: the clock starts only when each
    publisher of a topic has matched every participant that subscribes to it.
    """
    statuses = list(statuses)
    awaited = []
    for status in statuses:
        for topic, matched in status.matched.items():
            readers = sum(1 for other in statuses
                          if other.node != status.node and topic in other.received)
            if matched < readers:
                awaited.append(f'{status.node} has matched {matched} of the {readers} '
                               f'participants reading {topic}')
    return awaited


def awaited_messages(statuses: Iterable[StepStatus]) -> list[str]:
    """Return the readers that have not yet taken every message published on their topics.

    Counted over the participants only: a topic that no participant publishes (a goal
    from RViz, say) is not waited for.
    """
    statuses = list(statuses)
    totals: dict[str, int] = {}
    for status in statuses:
        for topic, count in status.published.items():
            totals[topic] = totals.get(topic, 0) + int(count)
    awaited = []
    for status in statuses:
        for topic, taken in status.received.items():
            published = totals.get(topic)
            if published is not None and taken < published:
                awaited.append(f'{status.node} has taken {taken} of {published} messages '
                               f'on {topic}')
    return awaited


def awaited_steps(statuses: Iterable[StepStatus], now_ns: int) -> list[str]:
    """Return the participants with a timer due at or before now that has not run yet."""
    return [f'{status.node} has not finished its step due at {status.due_ns * 1e-9:.3f} s'
            for status in statuses
            if status.due_ns is not None and status.due_ns <= now_ns]
