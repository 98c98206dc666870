# SPDX-License-Identifier: Apache-2.0
"""map_server: serve a map_server map (YAML + PGM/PNG) on ``map``, as nav2_map_server does.

A lifecycle node with nav2_map_server's parameters (``yaml_filename``, ``frame_id``,
``topic_name``): configure loads the map, activate publishes it once as a
nav_msgs/OccupancyGrid (reliable, transient_local, depth 1, so late subscribers such as RViz
still get it), deactivate stops publishing and cleanup forgets the map. With ``autostart``
(the default) ``ros2 run`` alone configures and activates it; with ``autostart:=false`` it
waits for a lifecycle manager, as nav2's does.

``yaml_filename`` has no default (a map served by mistake is a robot planning around walls
that are not there): without it the node refuses to start, in one line on stderr with exit
code 2. It is checked whenever it is set: a value that does not name a readable map
(missing file, bad YAML, bad image, resolution <= 0, ...) is refused with the reason, so
``map_server`` with a bad map exits with code 2 and one line on stderr. A new value is loaded
at the next configure (``ros2 lifecycle set /map_server cleanup``, then ``configure``).
"""

from __future__ import annotations

import array
import sys
from typing import Any

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose
from nav_msgs.msg import OccupancyGrid
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.exceptions import ParameterUninitializedException
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter

from mpc_local_planner.ros.conversions import yaw_to_quaternion
from mpc_local_planner.ros.lifecycle import ManagedNode
from mpc_local_planner.ros.lockstep import LOCKSTEP_PARAMETER
from mpc_local_planner.ros.node_main import destroy_on_failure, run_node
from mpc_local_planner.ros.parameters import declare_parameters, ParameterSpec
from mpc_local_planner.ros.qos import MAP_QOS
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.map_files import load_map, OccupancyMap

__all__ = ['MapServerNode', 'PARAMETERS', 'main', 'occupancy_grid_msg', 'read_map']

SUMMARY = ('Serve a map_server map (YAML + PGM/PNG) on `map` as nav_msgs/OccupancyGrid '
           '(reliable, transient_local), as nav2_map_server does.')

PARAMETERS = (
    ParameterSpec('yaml_filename', Parameter.Type.STRING,
                  'the map YAML (map_server format): a path, or a name under the package '
                  "config/ such as 'maps/unknown_box.yaml'; required; a value that names no "
                  'readable map is refused; a new value is loaded at the next configure'),
    ParameterSpec('frame_id', 'map', 'frame of the published map; read at configure'),
    ParameterSpec('topic_name', 'map',
                  'topic the map is published on (relative names follow the namespace and '
                  'remaps); read at configure'),
    LOCKSTEP_PARAMETER,
    ParameterSpec('autostart', True,
                  'configure and activate at start (false: wait for a lifecycle manager)',
                  read_only=True),
)


def _one_line(err: BaseException) -> str:
    """Return the error's message on one line (YAML errors span several)."""
    return ' '.join(str(err).split())


def read_map(name: str) -> tuple[str, OccupancyMap]:
    """Find and load the map a ``yaml_filename`` names.

    Args:
        name: A path, or a name resolved under the package's config/ (``maps/NAME.yaml``).

    Returns:
        The map YAML's resolved path and the map.

    Raises:
        FileNotFoundError: If no such file exists (the message says where it looked).
        ValueError: If the name is empty, or the YAML or its image is malformed (MapError).

    """
    if not name:
        msg = 'yaml_filename is empty: name a map YAML'
        raise ValueError(msg)
    path = resolve_data_file(name)
    return str(path), load_map(path)


def occupancy_grid_msg(occupancy: OccupancyMap, *, frame_id: str, stamp: Time) -> OccupancyGrid:
    """Return the map as nav_msgs/OccupancyGrid (data row-major from the bottom row).

    Args:
        occupancy: The map.
        frame_id: The header's frame.
        stamp: The header's stamp and the map's load time.

    Returns:
        The message.

    """
    msg = OccupancyGrid()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    msg.info.map_load_time = stamp
    msg.info.resolution = float(occupancy.resolution)
    msg.info.width = occupancy.width
    msg.info.height = occupancy.height
    x0, y0, yaw = occupancy.origin
    origin = Pose()
    origin.position.x, origin.position.y = float(x0), float(y0)
    origin.orientation = yaw_to_quaternion(yaw)
    msg.info.origin = origin
    msg.data = array.array('b', np.ascontiguousarray(occupancy.data, dtype=np.int8).tobytes())
    return msg


class MapServerNode(ManagedNode):
    """Load a map at configure and publish it (latched) at activate."""

    @destroy_on_failure
    def __init__(self, **kwargs: Any) -> None:
        super().__init__('map_server', **kwargs)
        self.add_on_set_parameters_callback(self.parameters_callback)
        declare_parameters(self, PARAMETERS)
        try:
            self.get_parameter('yaml_filename')
        except ParameterUninitializedException:
            msg = ("yaml_filename is not set: name the map to serve (-p yaml_filename:=FILE, a "
                   "path or a name such as 'maps/unknown_box.yaml')")
            raise ValueError(msg) from None
        self._map_msg: OccupancyGrid | None = None
        self._map_pub = None

    # ------------------------------------------------------------------ parameters
    def parameters_callback(self, parameters: list[Parameter]) -> SetParametersResult:
        """Refuse a yaml_filename that names no readable map, and empty names.

        Unset (the declaration without a value) is not judged here: __init__ refuses it.
        """
        for parameter in parameters:
            if parameter.name == 'yaml_filename' and parameter.value is not None:
                try:
                    read_map(str(parameter.value))
                except (OSError, ValueError) as err:
                    return SetParametersResult(successful=False, reason=_one_line(err))
            elif parameter.name in ('frame_id', 'topic_name') and not parameter.value:
                return SetParametersResult(successful=False,
                                           reason=f'{parameter.name} must not be empty')
        return SetParametersResult(successful=True)

    @property
    def map_msg(self) -> OccupancyGrid | None:
        """The map the node serves (None unless configured)."""
        return self._map_msg

    # ------------------------------------------------------------------ lifecycle
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the map named by yaml_filename and create the publisher."""
        try:
            path, occupancy = read_map(str(self.get_parameter('yaml_filename').value))
        except (OSError, ValueError) as err:
            self.get_logger().error(f'cannot load the map: {_one_line(err)}')
            return TransitionCallbackReturn.FAILURE
        self._map_msg = occupancy_grid_msg(
            occupancy, frame_id=str(self.get_parameter('frame_id').value),
            stamp=self.get_clock().now().to_msg())
        self._map_pub = self.create_lifecycle_publisher(
            OccupancyGrid, str(self.get_parameter('topic_name').value), MAP_QOS)
        self.get_logger().info(
            f'loaded {path}: {occupancy.width} x {occupancy.height} cells of '
            f'{occupancy.resolution:g} m, origin {list(occupancy.origin)}')
        return super().on_configure(state)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Activate the publisher and publish the map once (transient_local keeps it)."""
        result = super().on_activate(state)
        if result == TransitionCallbackReturn.SUCCESS:
            self._map_pub.publish(self._map_msg)
        return result

    def release(self) -> None:
        """Forget the map and destroy the publisher."""
        self.destroy_entities(self._map_pub)
        self._map_pub = None
        self._map_msg = None


def main(args: list[str] | None = None) -> int:
    """Run the map server (``map_server --help`` lists its parameters)."""
    return run_node(MapServerNode, 'map_server', args, summary=SUMMARY, parameters=PARAMETERS)


if __name__ == '__main__':
    sys.exit(main())
