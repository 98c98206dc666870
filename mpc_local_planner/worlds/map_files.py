# SPDX-License-Identifier: Apache-2.0
"""Occupancy maps in the nav2 map_server format: read, write, and rasterise a world.

A map is a YAML file (``image``, ``resolution``, ``origin`` [x, y, yaw], ``negate``,
``occupied_thresh``, ``free_thresh``, ``mode``) next to a PGM or PNG image. Pixels are turned
into occupancy exactly as nav2_map_server's ``map_io`` does, so a map that works with Nav2
works here and the other way round:

- shade = grey level / 255 (colour channels averaged); occ = shade if negate else 1 - shade;
- trinary: occ > occupied_thresh -> 100, occ < free_thresh -> 0, else -1 (unknown);
- scale: like trinary, but in between linearly 0..100, and transparent pixels unknown;
- raw: the grey level itself if it is in 0..100, else unknown.

Row 0 of the image is the TOP of the map; `OccupancyMap.data` is stored as
nav_msgs/OccupancyGrid stores it, row 0 at the BOTTOM (``data.ravel()`` is the message's
``data``), so loading and saving flip the rows.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, TYPE_CHECKING

import numpy as np
from PIL import Image, UnidentifiedImageError
import yaml

if TYPE_CHECKING:
    from mpc_local_planner.worlds.world import World

__all__ = [
    'FREE',
    'MapError',
    'OCCUPIED',
    'OccupancyMap',
    'UNKNOWN',
    'load_map',
    'rasterize_world',
    'save_map',
]

#: nav_msgs/OccupancyGrid values.
FREE = 0
OCCUPIED = 100
UNKNOWN = -1
_MODES = ('trinary', 'scale', 'raw')
_REQUIRED = ('image', 'resolution', 'origin', 'negate', 'occupied_thresh', 'free_thresh')
# nav2_map_saver's pixel values for trinary maps, and the thresholds it writes (ROS 1's
# map_saver free_thresh: 205 then reads back as unknown, 254 as free).
_PIXEL_OCCUPIED, _PIXEL_UNKNOWN, _PIXEL_FREE = 0, 205, 254
_SAVE_OCCUPIED_THRESH = 0.65
_SAVE_FREE_THRESH = 0.196


class MapError(ValueError):
    """A map YAML or its image is missing, malformed or inconsistent."""


@dataclass(frozen=True, eq=False)
class OccupancyMap:
    """An occupancy grid as nav_msgs/OccupancyGrid holds it.

    Attributes:
        data: (height, width) int8, -1 unknown, 0..100 occupancy; row 0 is the bottom row
            (smallest y in the map frame), so ``data.ravel()`` is the message's data.
        resolution: Cell side, metres (> 0).
        origin: (x, y, yaw) of the lower-left corner of cell (0, 0) in the map frame.

    """

    data: np.ndarray
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        data = np.asarray(self.data)
        if data.ndim != 2 or data.size == 0:
            msg = f'map data must be a non-empty 2-D array, got shape {data.shape}'
            raise MapError(msg)
        if not (math.isfinite(self.resolution) and self.resolution > 0.0):
            msg = f'map resolution must be > 0, got {self.resolution!r}'
            raise MapError(msg)
        if len(self.origin) != 3 or not all(math.isfinite(v) for v in self.origin):
            msg = f'map origin must be three finite numbers [x, y, yaw], got {self.origin!r}'
            raise MapError(msg)
        object.__setattr__(self, 'data', data.astype(np.int8, copy=False))
        object.__setattr__(self, 'origin', tuple(float(v) for v in self.origin))

    @property
    def height(self) -> int:
        """Number of rows."""
        return int(self.data.shape[0])

    @property
    def width(self) -> int:
        """Number of columns."""
        return int(self.data.shape[1])

    def cell_to_world(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Return the map-frame centres of cells (row from the bottom, column from the left).

        Args:
            rows: Row indices (any shape).
            cols: Column indices (same shape).

        Returns:
            (..., 2) x, y.

        """
        x0, y0, yaw = self.origin
        local_x = (np.asarray(cols, dtype=float) + 0.5) * self.resolution
        local_y = (np.asarray(rows, dtype=float) + 0.5) * self.resolution
        c, s = math.cos(yaw), math.sin(yaw)
        return np.stack([x0 + c * local_x - s * local_y, y0 + s * local_x + c * local_y],
                        axis=-1)

    def world_to_cell(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return (rows, cols) of the cells containing map-frame points (may be outside).

        Args:
            points: (..., 2) x, y.

        Returns:
            Integer rows and columns; use `contains_cell` to see which are in the map.

        """
        pts = np.asarray(points, dtype=float)
        x0, y0, yaw = self.origin
        dx, dy = pts[..., 0] - x0, pts[..., 1] - y0
        c, s = math.cos(yaw), math.sin(yaw)
        cols = np.floor((c * dx + s * dy) / self.resolution).astype(np.int64)
        rows = np.floor((-s * dx + c * dy) / self.resolution).astype(np.int64)
        return rows, cols

    def contains_cell(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Say which (row, col) lie inside the grid."""
        rows, cols = np.asarray(rows), np.asarray(cols)
        return (rows >= 0) & (rows < self.height) & (cols >= 0) & (cols < self.width)


def _fail(where: Path | str, problem: str) -> MapError:
    """Return the MapError for a problem found in where (raise it at the call site)."""
    return MapError(f'{where}: {problem}')


def _finite(value: Any, what: str, where: Path) -> float:
    """Return value as a finite float, refusing bools, strings and None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(where, f'{what} must be a number, got {value!r}')
    if not math.isfinite(value):
        raise _fail(where, f'{what} must be finite, got {value!r}')
    return float(value)


def load_map(yaml_path: str | Path) -> OccupancyMap:
    """Load a map_server map (YAML plus PGM/PNG image) as nav2_map_server would.

    Args:
        yaml_path: The map's YAML file; a relative ``image`` is relative to its folder.

    Returns:
        The map, row 0 at the bottom.

    Raises:
        FileNotFoundError: If the YAML file does not exist.
        MapError: If a key is missing or malformed (resolution <= 0, non-finite origin,
            thresholds outside [0, 1], unknown mode) or the image is missing or unreadable.

    """
    path = Path(yaml_path)
    if not path.is_file():
        msg = f'map file not found: {path}'
        raise FileNotFoundError(msg)
    try:
        doc = yaml.safe_load(path.read_text(encoding='utf-8'))
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise _fail(path, f'not valid YAML: {err}') from None
    if not isinstance(doc, dict):
        raise _fail(path, f'a map YAML must be a mapping, got {type(doc).__name__}')
    missing = [key for key in _REQUIRED if key not in doc]
    if missing:
        raise _fail(path, f'missing required key(s) {missing}')
    resolution = _finite(doc['resolution'], 'resolution', path)
    if resolution <= 0.0:
        raise _fail(path, f'resolution must be > 0, got {resolution:g}')
    origin = doc['origin']
    if not isinstance(origin, list) or len(origin) != 3:
        raise _fail(path, f'origin must be [x, y, yaw], got {origin!r}')
    origin_xyz = tuple(_finite(v, f'origin[{i}]', path) for i, v in enumerate(origin))
    negate = doc['negate']
    if negate not in (0, 1) or (not isinstance(negate, (bool, int))):
        raise _fail(path, f'negate must be 0 or 1, got {negate!r}')
    occupied = _finite(doc['occupied_thresh'], 'occupied_thresh', path)
    free = _finite(doc['free_thresh'], 'free_thresh', path)
    if not (0.0 <= free <= occupied <= 1.0):
        raise _fail(path, f'need 0 <= free_thresh <= occupied_thresh <= 1, got {free}, '
                          f'{occupied}')
    mode = doc.get('mode', 'trinary')
    if mode not in _MODES:
        raise _fail(path, f'mode must be one of {list(_MODES)}, got {mode!r}')
    image = doc['image']
    if not isinstance(image, str) or not image:
        raise _fail(path, f'image must be a file name, got {image!r}')
    image_path = Path(image) if Path(image).is_absolute() else path.parent / image
    if not image_path.is_file():
        raise _fail(path, f'image not found: {image_path}')
    try:
        with Image.open(image_path) as img:
            rgba = np.asarray(img.convert('RGBA'), dtype=float)
    except (UnidentifiedImageError, OSError) as err:
        raise _fail(path, f'image {image_path} is unreadable: {err}') from None
    shade = rgba[..., :3].mean(axis=2) / 255.0
    cells = _occupancy(shade, rgba[..., 3] < 255.0, mode=mode, negate=bool(negate),
                       occupied=occupied, free=free)
    return OccupancyMap(data=cells[::-1].copy(), resolution=resolution, origin=origin_xyz)


def _occupancy(shade: np.ndarray, transparent: np.ndarray, *, mode: str, negate: bool,
               occupied: float, free: float) -> np.ndarray:
    """Convert pixel shades (0 black .. 1 white) to occupancy values, as nav2's map_io."""
    occ = shade if negate else 1.0 - shade
    if mode == 'raw':
        value = np.rint(shade * 255.0)
        return np.where((value >= FREE) & (value <= OCCUPIED), value, UNKNOWN).astype(np.int8)
    cells = np.full(shade.shape, UNKNOWN, dtype=np.int8)
    if mode == 'scale':
        span = max(occupied - free, 1e-12)
        cells[:] = np.rint((occ - free) / span * 100.0).clip(FREE, OCCUPIED)
    cells[occ > occupied] = OCCUPIED
    cells[occ < free] = FREE
    if mode == 'scale':
        cells[transparent] = UNKNOWN
    return cells


def save_map(occupancy: OccupancyMap, out_dir: str | Path, name: str, *,
             mode: str = 'trinary') -> Path:
    """Write a map as ``out_dir/name.yaml`` and ``out_dir/name.pgm`` (map_saver's format).

    Args:
        occupancy: The map.
        out_dir: Folder to write to (created if needed).
        name: Base name of both files.
        mode: ``trinary`` (occupied >= 65 black, free <= 19 white, the rest unknown grey, as
            nav2_map_saver writes) or ``raw`` (the values themselves; exact for any grid).

    Returns:
        The YAML file's path.

    Raises:
        ValueError: If mode is not trinary or raw, or name is not a plain file name.

    """
    if mode not in ('trinary', 'raw'):
        msg = f'save_map writes trinary or raw maps, got mode {mode!r}'
        raise ValueError(msg)
    if not name or Path(name).name != name:
        msg = f'map name must be a plain file name, got {name!r}'
        raise ValueError(msg)
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    data = occupancy.data.astype(np.int16)
    if mode == 'raw':
        pixels = np.where(data < 0, 255, data)
    else:
        pixels = np.full(data.shape, _PIXEL_UNKNOWN)
        pixels[(data >= 0) & (data <= round(_SAVE_FREE_THRESH * 100))] = _PIXEL_FREE
        pixels[data >= round(_SAVE_OCCUPIED_THRESH * 100)] = _PIXEL_OCCUPIED
    image_path = folder / f'{name}.pgm'
    Image.fromarray(pixels[::-1].astype(np.uint8), mode='L').save(image_path)
    doc = {
        'image': image_path.name,
        'mode': mode,
        'resolution': float(occupancy.resolution),
        'origin': [float(v) for v in occupancy.origin],
        'negate': 0,
        'occupied_thresh': _SAVE_OCCUPIED_THRESH,
        'free_thresh': _SAVE_FREE_THRESH,
    }
    yaml_path = folder / f'{name}.yaml'
    yaml_path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding='utf-8')
    return yaml_path


def rasterize_world(world: World, resolution: float, *, margin: float = 0.0) -> OccupancyMap:
    """Draw a world's KNOWN obstacles into an occupancy grid covering its bounds.

    A cell is occupied when it overlaps an obstacle with positive area (separating axis test
    with the cell's axes and the polygon's face normals), so the occupied cells cover every
    obstacle entirely: the map never shrinks an obstacle. Cells that only touch an obstacle's
    boundary stay free. ``unknown_obstacles`` are not drawn: they are in no map by definition.

    Args:
        world: The world.
        resolution: Cell side, metres (> 0).
        margin: Free border added around the world's bounds, metres (>= 0).

    Returns:
        The map (0 free, 100 occupied), origin at the lower-left corner of the grown bounds,
        yaw 0.

    Raises:
        ValueError: If resolution or margin is out of range.

    """
    if not (math.isfinite(resolution) and resolution > 0.0):
        msg = f'resolution must be > 0, got {resolution!r}'
        raise ValueError(msg)
    if not (math.isfinite(margin) and margin >= 0.0):
        msg = f'margin must be >= 0, got {margin!r}'
        raise ValueError(msg)
    xmin, xmax, ymin, ymax = world.bounds
    x0, y0 = xmin - margin, ymin - margin
    width = max(1, math.ceil(round((xmax + margin - x0) / resolution, 9)))
    height = max(1, math.ceil(round((ymax + margin - y0) / resolution, 9)))
    data = np.zeros((height, width), dtype=np.int8)
    half = 0.5 * resolution
    eps = 1e-9 * max(1.0, resolution)
    for obstacle in world.obstacles:
        lo = np.floor((obstacle.vertices.min(axis=0) - (x0, y0)) / resolution).astype(int)
        hi = np.ceil((obstacle.vertices.max(axis=0) - (x0, y0)) / resolution).astype(int)
        c0, r0 = np.maximum(lo, 0)
        c1, r1 = np.minimum(hi, (width, height))
        if c0 >= c1 or r0 >= r1:
            continue
        cols, rows = np.meshgrid(np.arange(c0, c1), np.arange(r0, r1))
        cx = x0 + (cols + 0.5) * resolution
        cy = y0 + (rows + 0.5) * resolution
        # Cell [cx +- h] x [cy +- h] overlaps {A p <= b} iff no face separates them (the
        # cell's own axes are covered by the bounding-box window, up to touching).
        reach = half * (np.abs(obstacle.A[:, 0]) + np.abs(obstacle.A[:, 1]))
        lowest = (obstacle.A[:, 0] * cx[..., None] + obstacle.A[:, 1] * cy[..., None]
                  - reach)
        overlap = np.all(lowest < obstacle.b - eps, axis=-1)
        vmin, vmax = obstacle.vertices.min(axis=0), obstacle.vertices.max(axis=0)
        overlap &= (cx + half > vmin[0] + eps) & (cx - half < vmax[0] - eps)
        overlap &= (cy + half > vmin[1] + eps) & (cy - half < vmax[1] - eps)
        block = data[r0:r1, c0:c1]
        block[overlap] = OCCUPIED
    return OccupancyMap(data=data, resolution=float(resolution), origin=(x0, y0, 0.0))

