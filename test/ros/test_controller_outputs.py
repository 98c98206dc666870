# SPDX-License-Identifier: Apache-2.0
"""ControllerOutputs: the obstacle markers are built only while someone subscribes."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from rclpy.time import Time
from visualization_msgs.msg import Marker

from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.perception.tracking import Track
from mpc_local_planner.ros.mpc_controller_outputs import (
    ControllerOutputs,
    OBSTACLES_TOPIC,
    track_markers,
)


class FakePublisher:
    """Records what is published; says how many subscribe (the test sets it)."""

    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.subscribers = 0
        self.published: list[Any] = []

    def get_subscription_count(self) -> int:
        return self.subscribers

    def publish(self, msg: Any) -> None:
        self.published.append(msg)


class FakeNode:
    """What ControllerOutputs asks of its lifecycle node."""

    def __init__(self) -> None:
        self.publishers: dict[str, FakePublisher] = {}

    def create_lifecycle_publisher(self, kind: Any, topic: str, qos: Any) -> FakePublisher:
        return self.publishers.setdefault(topic, FakePublisher(topic))

    def get_logger(self) -> Any:
        return None

    def get_name(self) -> str:
        return 'mpc_controller'

    def get_fully_qualified_name(self) -> str:
        return '/mpc_controller'


def test_obstacle_markers_are_built_only_while_someone_subscribes() -> None:
    node = FakeNode()
    controller = MpcController(obstacles=[ConvexPolygon.from_box(1.0, -0.5, 1.5, 0.5)])
    outputs = ControllerOutputs(node, controller, stamped=False,  # type: ignore[arg-type]
                                parameter=lambda name: 'map')
    markers = node.publishers[OBSTACLES_TOPIC]
    stop = ControlOutput(np.zeros(2), None, Reason.STOP)
    for _ in range(3):
        outputs._publish_obstacles(stop, 'map', None)
    assert markers.published == []
    markers.subscribers = 1  # RViz opens: the next step sends them, with the obstacle
    outputs._publish_obstacles(stop, 'map', None)
    assert len(markers.published) == 1
    namespaces = {m.ns for m in markers.published[0].markers}
    assert {'raw', 'grown'} <= namespaces


def test_obstacle_markers_follow_a_changing_memory_at_most_every_period() -> None:
    """The laser changes the obstacles at every scan: a change goes out at most at 5 Hz."""
    node = FakeNode()
    controller = MpcController()
    outputs = ControllerOutputs(node, controller, stamped=False,  # type: ignore[arg-type]
                                parameter=lambda name: 'map')
    markers = node.publishers[OBSTACLES_TOPIC]
    markers.subscribers = 1
    stop = ControlOutput(np.zeros(2), None, Reason.STOP)
    sent_at = []
    for k in range(12):  # 20 Hz, a new obstacle at every step
        now = 10.0 + k / 20
        controller.set_obstacles([ConvexPolygon.from_box(1.0 + 0.01 * k, -0.5, 1.5, 0.5)])
        before = len(markers.published)
        outputs._publish_obstacles(stop, 'map', None, now)
        if len(markers.published) > before:
            sent_at.append(round(now, 2))
    assert sent_at == [10.0, 10.2, 10.4]
    raw = [m for m in markers.published[-1].markers if m.ns == 'raw']
    assert raw[0].points[0].x == pytest.approx(1.08)  # the obstacle of the step it went out
    # what stays keeps its marker, renumbered; what is new gets one
    outputs._publish_obstacles(stop, 'map', None, 10.8)  # the last step's obstacle
    raw = [m for m in markers.published[-1].markers if m.ns == 'raw']
    stay = controller.obstacles[0]
    controller.set_obstacles([ConvexPolygon.from_box(5.0, 0.0, 5.5, 0.5), stay])
    outputs._publish_obstacles(stop, 'map', None, 11.0)
    raw_now = [m for m in markers.published[-1].markers if m.ns == 'raw']
    assert raw_now[1] is raw[0] and raw_now[1].id == 1
    assert raw_now[0].id == 0 and raw_now[0].points[0].x == pytest.approx(5.0)
    # a clock that went back (a simulation started again) gets them at once
    controller.set_obstacles([ConvexPolygon.from_box(2.0, -0.5, 2.5, 0.5)])
    outputs._publish_obstacles(stop, 'map', None, 0.0)
    assert len(markers.published) == 6


def test_track_markers_tell_static_suspect_and_moving_tracks_apart() -> None:
    """A suspect is drawn in its own colour, with the arrow of its velocity, as a mover is."""
    def track(track_id: int, *, moving: bool = False, suspect: bool = False) -> Track:
        return Track(track_id, np.array([float(track_id), 0.0, 0.5, 0.0]), np.eye(4) * 0.01,
                     0.0, 0.0, hits=3, size=0.2, moving=moving, suspect=suspect)

    markers = track_markers([track(1), track(2, suspect=True), track(3, moving=True)],
                            frame_id='map', stamp=Time().to_msg()).markers
    discs = {m.id: m.ns for m in markers if m.type == Marker.CYLINDER}
    arrows = sorted(m.id for m in markers
                    if m.type == Marker.ARROW and m.action == Marker.ADD)
    assert discs == {1: 'static', 2: 'suspect', 3: 'moving'}
    assert arrows == [2, 3]
