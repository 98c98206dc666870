# SPDX-License-Identifier: Apache-2.0
"""bag_recorder: record topics into a rosbag2 (mcap) without rosbag2_py or ros2cli.

The messages arrive already serialised (raw subscriptions: the CDR bytes the middleware
received, exactly what ``ros2 bag record`` stores) and go to `rosbags.rosbag2.Writer`. The
connections' message definitions and type hashes come from rosbags' Jazzy typestore, so
``ros2 bag info`` and the rosbags Reader both read the result. Timestamps are the node's
ROS time at reception (simulated time under ``use_sim_time``).

With ``world_file`` set, the bag's metadata (rosbag2 ``custom_data``) records the world: its
path and its contents, under the keys of `BagKey`, so that analyze_bag finds the obstacles
the run had without being told.

The output folder must not exist: the recorder refuses to start (one line on stderr, exit
code 2) rather than overwrite or mix runs. ``bag_recorder --help`` lists the parameters and
creates nothing.
"""

from __future__ import annotations

from importlib import import_module
from pathlib import Path
import sys
from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

from mpc_local_planner.core.diagnostics import (
    BagKey,
    CONTROLLER_DIAGNOSTICS_TOPIC,
    PLANNER_DIAGNOSTICS_TOPIC,
)
from mpc_local_planner.ros.lockstep import LOCKSTEP_PARAMETER, LockstepReporter
from mpc_local_planner.ros.node_main import destroy_on_failure, run_node
from mpc_local_planner.ros.parameters import declare_parameters, ParameterSpec
from mpc_local_planner.ros.qos import recorder_qos
from mpc_local_planner.worlds.data_files import resolve_data_file

__all__ = ['BagRecorderNode', 'DEFAULT_TOPICS', 'DEFAULT_TYPES', 'PARAMETERS', 'SUMMARY', 'main',
           'message_class']

DEFAULT_TOPICS = ['odom', 'cmd_vel', 'plan', 'local_plan', CONTROLLER_DIAGNOSTICS_TOPIC,
                  PLANNER_DIAGNOSTICS_TOPIC]
DEFAULT_TYPES = ['nav_msgs/msg/Odometry', 'geometry_msgs/msg/Twist', 'nav_msgs/msg/Path',
                 'nav_msgs/msg/Path', 'diagnostic_msgs/msg/DiagnosticArray',
                 'diagnostic_msgs/msg/DiagnosticArray']
DEFAULT_LATCHED = ['plan', PLANNER_DIAGNOSTICS_TOPIC]
BAG_VERSION = 9

SUMMARY = ('Record topics into an mcap rosbag2 (no rosbag2_py or ros2cli needed), with the '
           "world in the bag's metadata; the output folder must not exist.")

PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('output', 'bag', 'bag directory to create (must not exist); read once at start',
                  read_only=True),
    ParameterSpec('topics', DEFAULT_TOPICS,
                  'topics to record (relative names resolve in the node namespace)',
                  read_only=True),
    ParameterSpec('types', DEFAULT_TYPES, "their types, 'pkg/msg/Name', one per topic",
                  read_only=True),
    ParameterSpec('transient_local_topics', DEFAULT_LATCHED,
                  'topics subscribed transient_local (latched, such as plan)', read_only=True),
    LOCKSTEP_PARAMETER,
    ParameterSpec('world_file', '',
                  "world file to record in the bag's metadata (a path, or a name in the "
                  "package's config/ or config/worlds/); '' = none", read_only=True),
)


def message_class(type_name: str) -> type:
    """Return the Python class of 'pkg/msg/Name' (also 'pkg/Name').

    Raises:
        ValueError: if the name is malformed or the type cannot be imported.

    """
    parts = type_name.split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3 or not all(parts):
        msg = f'message type must look like pkg/msg/Name, got {type_name!r}'
        raise ValueError(msg)
    try:
        return getattr(import_module(f'{parts[0]}.{parts[1]}'), parts[2])
    except (ImportError, AttributeError):
        msg = f'message type {type_name!r} is not available in this Python environment'
        raise ValueError(msg) from None


class BagRecorderNode(Node):
    """Record the topics named in ``topics`` (types in ``types``) into ``output``."""

    @destroy_on_failure
    def __init__(self, **kwargs: Any) -> None:
        super().__init__('bag_recorder', **kwargs)
        self.add_on_set_parameters_callback(self.parameters_callback)
        declare_parameters(self, PARAMETERS)
        self._typestore = get_typestore(Stores.ROS2_JAZZY)
        self.counts: dict[str, int] = {}
        topics = list(self.get_parameter('topics').value)
        types = list(self.get_parameter('types').value)
        latched = set(self.get_parameter('transient_local_topics').value)
        self.path = Path(str(self.get_parameter('output').value)).expanduser()
        if self.path.exists():
            msg = f'output {str(self.path)!r} exists: remove it or choose another output'
            raise FileExistsError(msg)
        world = self._read_world(str(self.get_parameter('world_file').value))
        self._writer: Writer | None = Writer(self.path, version=BAG_VERSION,
                                             storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        for key, value in world.items():
            self._writer.set_custom_data(key.value, value)
        self._subscriptions_by_topic = {}
        try:
            for topic, type_name in zip(topics, types, strict=True):
                self._add_topic(topic, type_name, latched=topic in latched)
        except Exception:
            self._writer.close()
            self._writer = None
            raise
        self.get_logger().info(f'recording {len(topics)} topics into {self.path}')
        # a lockstep clock then waits for every message to be recorded: no gap at the start
        # (the recorder may match later than the nodes), none when the clock runs fast
        if self.get_parameter('lockstep').value:
            LockstepReporter(self).report()

    @staticmethod
    def _read_world(world_file: str) -> dict[BagKey, str]:
        """Return the metadata that records world_file ({} for '').

        Raises:
            FileNotFoundError: if the file is not found.

        """
        if not world_file:
            return {}
        path = resolve_data_file(world_file)
        return {BagKey.WORLD_FILE: str(path), BagKey.WORLD: path.read_text(encoding='utf-8')}

    def parameters_callback(self, parameters: list[Parameter]) -> SetParametersResult:
        """Refuse types that do not import and topic/type lists of different lengths."""
        values = {p.name: p.value for p in parameters}
        topics = values.get('topics')
        types = values.get('types')
        if types is not None:
            for type_name in types:
                try:
                    message_class(type_name)
                except ValueError as err:
                    return SetParametersResult(successful=False, reason=str(err))
        if topics is None and self.has_parameter('topics'):
            topics = self.get_parameter('topics').value
        if types is None and self.has_parameter('types'):
            types = self.get_parameter('types').value
        if topics is not None and types is not None and len(topics) != len(types):
            reason = f'{len(topics)} topics but {len(types)} types: give one type per topic'
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _add_topic(self, topic: str, type_name: str, *, latched: bool) -> None:
        cls = message_class(type_name)
        subscription = self.create_subscription(
            cls, topic, lambda data, name=topic: self._on_message(name, data),
            recorder_qos(latched=latched), raw=True)
        resolved = subscription.topic_name
        canonical = type_name if type_name.count('/') == 2 else type_name.replace('/', '/msg/')
        assert self._writer is not None
        connection = self._writer.add_connection(resolved, canonical, typestore=self._typestore)
        self._subscriptions_by_topic[topic] = (subscription, connection, resolved)
        self.counts[resolved] = 0

    def _on_message(self, topic: str, data: bytes) -> None:
        try:
            _, connection, resolved = self._subscriptions_by_topic[topic]
            stamp = self.get_clock().now().nanoseconds
            if self._writer is None:
                return
            self._writer.write(connection, stamp, data)
            self.counts[resolved] += 1
        except Exception as err:  # never let a callback kill the executor
            self.get_logger().error(f'could not record {topic}: {err}', throttle_duration_sec=1.0)

    def close(self) -> None:
        """Finish the bag (writes its metadata); later messages are dropped."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    def destroy_node(self) -> None:
        """Close the bag, then destroy the node."""
        self.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Run the node until Ctrl-C (exit code 2, with the reason, on invalid parameters).

    ``--help`` prints the parameters and their defaults and starts nothing (creates no bag).
    """
    return run_node(BagRecorderNode, 'bag_recorder', args, summary=SUMMARY,
                    parameters=PARAMETERS)


if __name__ == '__main__':
    sys.exit(main())
