# SPDX-License-Identifier: Apache-2.0
"""Tests of map_server map files: reading, writing, rasterising, and world_to_map."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from conftest import point_in_any
import numpy as np
import pytest
import yaml

from mpc_local_planner.worlds.map_files import (
    load_map,
    MapError,
    OccupancyMap,
    rasterize_world,
    save_map,
)
from mpc_local_planner.worlds.world import load_world, world_from_dict
from mpc_local_planner.worlds.world_to_map import main

ROOT = Path(__file__).resolve().parents[2]
WORLDS = ROOT / 'config' / 'worlds'

# A 4 x 3 image, row 0 at the TOP: black (0), grey (205), white (254) and a mid grey (128).
PIXELS = np.array([
    [0, 205, 254, 128],
    [254, 254, 0, 254],
    [205, 0, 254, 254],
], dtype=np.uint8)


def write_pgm(path: Path, pixels: np.ndarray) -> None:
    height, width = pixels.shape
    path.write_bytes(f'P5\n{width} {height}\n255\n'.encode('ascii') + pixels.tobytes())


def write_map_yaml(folder: Path, **changes: Any) -> Path:
    doc = {'image': 'hand.pgm', 'resolution': 0.5, 'origin': [1.0, -2.0, 0.0], 'negate': 0,
           'occupied_thresh': 0.65, 'free_thresh': 0.196, 'mode': 'trinary'}
    for key, value in changes.items():
        if value is KeyError:
            del doc[key]
        else:
            doc[key] = value
    path = folder / 'hand.yaml'
    path.write_text(yaml.safe_dump(doc), encoding='utf-8')
    return path


def test_hand_made_pgm_reads_with_trinary_thresholds_and_the_row_flip(tmp_path: Path) -> None:
    write_pgm(tmp_path / 'hand.pgm', PIXELS)

    occupancy = load_map(write_map_yaml(tmp_path))

    assert (occupancy.width, occupancy.height) == (4, 3)
    # Row 0 of the grid is the BOTTOM row of the image.
    np.testing.assert_array_equal(occupancy.data, [
        [-1, 100, 0, 0],
        [0, 0, 100, 0],
        [100, -1, 0, -1],  # 128: occ = 0.498, between the thresholds: unknown
    ])
    assert occupancy.resolution == 0.5 and occupancy.origin == (1.0, -2.0, 0.0)
    np.testing.assert_allclose(occupancy.cell_to_world(0, 1), [1.75, -1.75])
    rows, cols = occupancy.world_to_cell(np.array([[1.75, -1.75], [2.9, -0.6]]))
    assert rows.tolist() == [0, 2] and cols.tolist() == [1, 3]


def test_hand_made_pgm_with_negate_swaps_black_and_white(tmp_path: Path) -> None:
    write_pgm(tmp_path / 'hand.pgm', PIXELS)

    occupancy = load_map(write_map_yaml(tmp_path, negate=1))

    # negate: occ = shade; 254 -> 0.996 occupied, 0 -> free, 205 -> 0.804 occupied.
    np.testing.assert_array_equal(occupancy.data, [
        [100, 0, 100, 100],
        [100, 100, 0, 100],
        [0, 100, 100, -1],
    ])


def test_raw_and_scale_modes_follow_map_server(tmp_path: Path) -> None:
    write_pgm(tmp_path / 'hand.pgm', np.array([[0, 50, 100, 101]], dtype=np.uint8))
    raw = load_map(write_map_yaml(tmp_path, mode='raw'))
    assert raw.data.tolist() == [[0, 50, 100, -1]]

    write_pgm(tmp_path / 'hand.pgm', np.array([[0, 255, 153]], dtype=np.uint8))
    scale = load_map(write_map_yaml(tmp_path, mode='scale', free_thresh=0.2,
                                    occupied_thresh=0.8))
    assert scale.data.tolist() == [[100, 0, 33]]  # occ 0.4: (0.4 - 0.2) / 0.6 * 100


def test_rasterised_world_round_trips_through_save_and_load(tmp_path: Path) -> None:
    world = load_world(WORLDS / 'rrt_cluttered.yaml')
    occupancy = rasterize_world(world, 0.05, margin=0.1)

    yaml_path = save_map(occupancy, tmp_path, 'cluttered')
    loaded = load_map(yaml_path)

    assert yaml_path == tmp_path / 'cluttered.yaml' and (tmp_path / 'cluttered.pgm').is_file()
    np.testing.assert_array_equal(loaded.data, occupancy.data)
    assert loaded.origin == pytest.approx(occupancy.origin)
    assert loaded.resolution == occupancy.resolution
    assert occupancy.origin == pytest.approx((-0.6, -0.6, 0.0))


def test_raw_save_round_trips_any_grid(tmp_path: Path) -> None:
    data = np.array([[-1, 0, 37], [100, 65, 19]], dtype=np.int8)
    original = OccupancyMap(data, 0.2, (0.5, 0.25, 0.1))

    loaded = load_map(save_map(original, tmp_path, 'raw', mode='raw'))

    np.testing.assert_array_equal(loaded.data, data)
    assert loaded.origin == pytest.approx(original.origin)


def test_rasterising_never_shrinks_an_obstacle_and_skips_unknown_ones() -> None:
    world = world_from_dict({
        'bounds': [0, 3, 0, 3], 'start': [0.2, 0.2, 0], 'goal': [2.8, 2.8, 0],
        'obstacles': [{'polygon': [[0.53, 0.61], [1.47, 0.88], [0.91, 1.73]]},
                      {'box': [2.0, 0.5, 2.5, 1.0]}],  # aligned with the cells
        'unknown_obstacles': [{'box': [1.0, 2.0, 1.5, 2.5]}],
    }, name='raster')
    occupancy = rasterize_world(world, 0.1)

    rng = np.random.default_rng(3)
    samples = rng.uniform(0, 3, size=(20000, 2))
    inside = point_in_any(list(world.obstacles), samples)
    rows, cols = occupancy.world_to_cell(samples[inside])
    assert np.all(occupancy.data[rows, cols] == 100)  # every obstacle point is occupied
    # The aligned box fills exactly its 5 x 5 cells; cells that only touch it stay free.
    assert np.count_nonzero(occupancy.data[5:10, 20:25] == 100) == 25
    assert np.all(occupancy.data[4, 20:25] == 0) and np.all(occupancy.data[5:10, 25] == 0)
    assert np.all(occupancy.data[20:25, 10:15] == 0)  # the unknown box is in no map


@pytest.mark.parametrize(('changes', 'match'), [
    ({'resolution': KeyError}, r"missing required key\(s\) \['resolution'\]"),
    ({'image': KeyError, 'origin': KeyError}, r"\['image', 'origin'\]"),
    ({'resolution': 0}, 'resolution must be > 0'),
    ({'resolution': -0.05}, 'resolution must be > 0'),
    ({'resolution': 'fine'}, 'resolution must be a number'),
    ({'origin': [0.0, float('nan'), 0.0]}, r'origin\[1\] must be finite'),
    ({'origin': [0.0, 0.0]}, r'origin must be \[x, y, yaw\]'),
    ({'negate': 2}, 'negate must be 0 or 1'),
    ({'free_thresh': 0.9}, 'free_thresh <= occupied_thresh'),
    ({'mode': 'fancy'}, 'mode must be one of'),
    ({'image': 'missing.pgm'}, 'image not found'),
])
def test_malformed_map_yaml_raises_map_error(tmp_path: Path, changes: dict[str, Any],
                                             match: str) -> None:
    write_pgm(tmp_path / 'hand.pgm', PIXELS)

    with pytest.raises(MapError, match=match) as info:
        load_map(write_map_yaml(tmp_path, **changes))

    assert 'hand.yaml' in str(info.value)


def test_unreadable_image_and_non_mapping_yaml_raise_map_error(tmp_path: Path) -> None:
    (tmp_path / 'hand.pgm').write_bytes(b'not an image')
    with pytest.raises(MapError, match='unreadable'):
        load_map(write_map_yaml(tmp_path))
    (tmp_path / 'list.yaml').write_text('[1, 2]')
    with pytest.raises(MapError, match='must be a mapping'):
        load_map(tmp_path / 'list.yaml')
    with pytest.raises(FileNotFoundError):
        load_map(tmp_path / 'nowhere.yaml')
    assert issubclass(MapError, ValueError)


def test_world_to_map_writes_the_named_map_and_refuses_bad_input(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(WORLDS / 'unknown_box.yaml'), '--resolution', '0.1',
                 '--out', str(tmp_path)]) == 0
    occupancy = load_map(tmp_path / 'unknown_box.yaml')
    world = load_world(WORLDS / 'unknown_box.yaml')
    rows, cols = occupancy.world_to_cell(np.array([[2.0, 0.0], [3.05, 0.65]]))
    assert occupancy.data[rows, cols].tolist() == [100, 0]  # the wall, not the unknown box
    assert len(world.unknown_obstacles) == 1
    capsys.readouterr()

    assert main([str(tmp_path / 'nowhere.yaml'), '--resolution', '0.1',
                 '--out', str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith('world_to_map: error:') and err.count('\n') == 1
    with pytest.raises(SystemExit) as info:
        main([str(WORLDS / 'unknown_box.yaml'), '--resolution', '0', '--out', str(tmp_path)])
    assert info.value.code == 2
    assert capsys.readouterr().err.count('\n') == 1
