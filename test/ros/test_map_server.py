# SPDX-License-Identifier: Apache-2.0
"""map_server: serves a map file on ``map`` (latched), refuses bad map files with exit 2."""

from __future__ import annotations

from pathlib import Path
import signal
import subprocess
import sys
from typing import Any

from builtin_interfaces.msg import Time
from nav_msgs.msg import OccupancyGrid
import numpy as np
import pytest
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter

from mpc_local_planner.ros.conversions import quaternion_to_yaw
from mpc_local_planner.ros.map_server_node import MapServerNode, occupancy_grid_msg
from mpc_local_planner.ros.node_main import autostart, EXIT_INVALID_PARAMETERS
from mpc_local_planner.ros.qos import MAP_QOS
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.map_files import FREE, load_map, OccupancyMap, OCCUPIED, save_map

PAPER_MAP = 'maps/paper_obstacle.yaml'
# In the paper world's box [1.0, -1.0, 1.5, 1.0], and the robot's start (0, 0).
INSIDE_THE_BOX, AT_THE_START = (1.25, 0.0), (0.0, 0.0)
TIMEOUT = 20.0


def _cell(grid: OccupancyGrid, occupancy: OccupancyMap, point: tuple[float, float]) -> int:
    """Return the message's value at a map-frame point (row-major from the bottom row)."""
    rows, cols = occupancy.world_to_cell(np.array([point]))
    assert occupancy.contains_cell(rows, cols).all()
    return grid.data[int(rows[0]) * grid.info.width + int(cols[0])]


def _assert_grid_is_the_map(grid: OccupancyGrid, occupancy: OccupancyMap, *,
                            frame_id: str = 'map') -> None:
    assert grid.header.frame_id == frame_id
    assert (grid.info.width, grid.info.height) == (occupancy.width, occupancy.height)
    assert grid.info.resolution == pytest.approx(occupancy.resolution)
    origin = grid.info.origin
    assert (origin.position.x, origin.position.y) == pytest.approx(occupancy.origin[:2])
    assert quaternion_to_yaw(origin.orientation) == pytest.approx(occupancy.origin[2])
    np.testing.assert_array_equal(np.asarray(grid.data, dtype=np.int8),
                                  occupancy.data.ravel())


class _MapListener(Node):
    """A late subscriber to the map (transient_local, like RViz's Map display)."""

    def __init__(self, context: Any, topic: str = 'map') -> None:
        super().__init__('map_listener', context=context)
        self.maps: list[OccupancyGrid] = []
        self.create_subscription(OccupancyGrid, topic, self.maps.append, MAP_QOS)


def test_occupancy_grid_msg_keeps_the_bottom_row_first_and_the_map_yaw() -> None:
    data = np.zeros((2, 3), dtype=np.int8)
    data[0, 2] = OCCUPIED  # bottom row, right column
    occupancy = OccupancyMap(data=data, resolution=0.5, origin=(1.0, -2.0, 0.3))
    grid = occupancy_grid_msg(occupancy, frame_id='world', stamp=Time(sec=7))
    assert list(grid.data) == [0, 0, OCCUPIED, 0, 0, 0]
    assert grid.info.map_load_time.sec == 7
    _assert_grid_is_the_map(grid, occupancy, frame_id='world')


def test_the_shipped_maps_resolve_from_the_source_tree_and_match_their_worlds() -> None:
    occupancy = load_map(resolve_data_file(PAPER_MAP))
    assert occupancy.resolution == pytest.approx(0.05)
    rows, cols = occupancy.world_to_cell(np.array([INSIDE_THE_BOX, AT_THE_START]))
    assert occupancy.data[rows, cols].tolist() == [OCCUPIED, FREE]
    for name in ('corridor_turn', 'rrt_cluttered', 'unknown_box'):
        assert load_map(resolve_data_file(f'maps/{name}.yaml')).resolution == 0.05


@pytest.mark.dds
def test_map_server_publishes_the_map_to_a_late_subscriber(ros: Any) -> None:
    occupancy = load_map(resolve_data_file(PAPER_MAP))
    server = ros.add(MapServerNode(context=ros.context, parameter_overrides=[
        Parameter('yaml_filename', value=PAPER_MAP)]))
    assert autostart(server) is None  # configure, then activate: publishes once
    listener = ros.add(_MapListener(ros.context))  # subscribes after the publication
    assert ros.spin_until(lambda: listener.maps, timeout=TIMEOUT), 'no map received'
    grid = listener.maps[0]
    _assert_grid_is_the_map(grid, occupancy)
    assert _cell(grid, occupancy, INSIDE_THE_BOX) == OCCUPIED
    assert _cell(grid, occupancy, AT_THE_START) == FREE


@pytest.mark.dds
def test_map_server_uses_frame_id_topic_name_and_the_map_origin_yaw(
        ros: Any, tmp_path: Path) -> None:
    data = np.full((4, 5), FREE, dtype=np.int8)
    data[1, 3] = OCCUPIED
    yaml_path = save_map(OccupancyMap(data=data, resolution=0.2, origin=(-1.0, 2.0, 0.5)),
                         tmp_path, 'tilted')
    server = ros.add(MapServerNode(context=ros.context, parameter_overrides=[
        Parameter('yaml_filename', value=str(yaml_path)),
        Parameter('frame_id', value='world'), Parameter('topic_name', value='known_map')]))
    assert autostart(server) is None
    listener = ros.add(_MapListener(ros.context, 'known_map'))
    assert ros.spin_until(lambda: listener.maps, timeout=TIMEOUT), 'no map received'
    _assert_grid_is_the_map(listener.maps[0], load_map(yaml_path), frame_id='world')


@pytest.mark.dds
def test_map_server_refuses_a_bad_yaml_filename_and_fails_configure_on_a_vanished_file(
        ros: Any, tmp_path: Path) -> None:
    yaml_path = save_map(OccupancyMap(data=np.zeros((2, 2)), resolution=0.1), tmp_path, 'gone')
    server = ros.add(MapServerNode(context=ros.context, parameter_overrides=[
        Parameter('yaml_filename', value=str(yaml_path))]))
    [result] = server.set_parameters([Parameter('yaml_filename', value=str(tmp_path / 'no'))])
    assert not result.successful and 'not found' in result.reason
    assert server.get_parameter('yaml_filename').value == str(yaml_path)
    yaml_path.unlink()
    assert server.trigger_configure() == TransitionCallbackReturn.FAILURE
    assert server.map_msg is None


def _bad_map(tmp_path: Path, kind: str) -> Path:
    """Write a broken map of the given kind; return its YAML path."""
    good = save_map(OccupancyMap(data=np.zeros((3, 3)), resolution=0.1), tmp_path, 'good')
    text = good.read_text()
    yaml_path = tmp_path / f'{kind}.yaml'
    if kind == 'missing':
        return yaml_path
    if kind == 'malformed_yaml':
        yaml_path.write_text('image: [good.pgm\nresolution: 0.1\n')
    elif kind == 'zero_resolution':
        yaml_path.write_text(text.replace('resolution: 0.1', 'resolution: 0.0'))
    elif kind == 'negative_resolution':
        yaml_path.write_text(text.replace('resolution: 0.1', 'resolution: -0.1'))
    elif kind == 'missing_image':
        yaml_path.write_text(text.replace('good.pgm', 'nowhere.pgm'))
    elif kind == 'unreadable_image':
        (tmp_path / 'garbage.pgm').write_bytes(b'not an image\n')
        yaml_path.write_text(text.replace('good.pgm', 'garbage.pgm'))
    elif kind == 'missing_key':
        yaml_path.write_text(text.replace('origin', 'origins'))
    return yaml_path


@pytest.mark.dds
@pytest.mark.parametrize('kind', ['missing', 'malformed_yaml', 'zero_resolution',
                                  'negative_resolution', 'missing_image',
                                  'unreadable_image', 'missing_key'])
def test_map_server_exits_2_with_one_line_on_a_bad_map_file(tmp_path: Path, kind: str) -> None:
    yaml_path = _bad_map(tmp_path, kind)
    command = [sys.executable, '-m', 'mpc_local_planner.ros.map_server_node',
               '--ros-args', '-p', f'yaml_filename:={yaml_path}']
    done = subprocess.run(command, capture_output=True, text=True, timeout=60)
    assert done.returncode == EXIT_INVALID_PARAMETERS, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith('map_server: refusing to start: ')
    assert str(yaml_path) in lines[0]


@pytest.mark.dds
def test_map_server_without_a_map_refuses_to_start_in_one_line() -> None:
    # no default map: a demo's map served on a real robot would be planned around
    command = [sys.executable, '-m', 'mpc_local_planner.ros.map_server_node']
    done = subprocess.run(command, capture_output=True, text=True, timeout=60)
    assert done.returncode == EXIT_INVALID_PARAMETERS, done.stderr
    assert done.stderr.splitlines() == [
        "map_server: refusing to start: yaml_filename is not set: name the map to serve "
        "(-p yaml_filename:=FILE, a path or a name such as 'maps/unknown_box.yaml')"]


@pytest.mark.dds
def test_map_server_executable_autostarts_and_serves_the_map_until_ctrl_c(ros: Any) -> None:
    occupancy = load_map(resolve_data_file('maps/unknown_box.yaml'))
    command = [sys.executable, '-m', 'mpc_local_planner.ros.map_server_node',
               '--ros-args', '-p', 'yaml_filename:=maps/unknown_box.yaml']
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    try:
        listener = ros.add(_MapListener(ros.context))
        received = ros.spin_until(lambda: listener.maps or process.poll() is not None,
                                  timeout=TIMEOUT)
        assert received and listener.maps, 'no map from the map_server process'
        _assert_grid_is_the_map(listener.maps[0], occupancy)
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=TIMEOUT)
        assert process.returncode == 0, stderr
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
