# SPDX-License-Identifier: Apache-2.0
"""The trajectory.csv format shared by the experiments, closed_loop and analyze_bag.

One row per control step, the columns of TRAJECTORY_COLUMNS; NaN where a value does not
exist (s for the tracking baseline). One reader and one writer keep the three producers and
every consumer in agreement.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

__all__ = ['read_trajectory_csv', 'TRAJECTORY_COLUMNS', 'TRAJECTORY_INDEX', 'trajectory_row',
           'write_trajectory_csv']

TRAJECTORY_COLUMNS = ('t', 'x', 'y', 'theta', 'v', 'omega', 's', 'V_N', 'solve_ms')
# Column index by name, for the readers of rows.
TRAJECTORY_INDEX = {name: i for i, name in enumerate(TRAJECTORY_COLUMNS)}


def trajectory_row(
    t: float,
    x: Sequence[float] | np.ndarray,
    u: Sequence[float] | np.ndarray | None = None,
    *,
    s: float = math.nan,
    value: float = math.nan,
    solve_ms: float = math.nan,
) -> np.ndarray:
    """Return one row of the trajectory.csv format, each value in its named column.

    Args:
        t: time of the row, seconds.
        x: the state; its first three entries are the pose (x, y, theta).
        u: the input (v, omega) commanded at t; None for a zero input.
        s: path progress, NaN where it does not exist (the tracking baseline).
        value: the controller's cost V_N, NaN where it does not exist.
        solve_ms: the controller's solve time in milliseconds, NaN where none ran.

    Returns:
        A (len(TRAJECTORY_COLUMNS),) float array.

    """
    row = np.full(len(TRAJECTORY_COLUMNS), math.nan)
    pose = np.asarray(x, dtype=float).reshape(-1)[:3]
    command = np.zeros(2) if u is None else np.asarray(u, dtype=float).reshape(-1)[:2]
    row[TRAJECTORY_INDEX['t']] = t
    row[[TRAJECTORY_INDEX['x'], TRAJECTORY_INDEX['y'], TRAJECTORY_INDEX['theta']]] = pose
    row[[TRAJECTORY_INDEX['v'], TRAJECTORY_INDEX['omega']]] = command
    row[TRAJECTORY_INDEX['s']] = s
    row[TRAJECTORY_INDEX['V_N']] = value
    row[TRAJECTORY_INDEX['solve_ms']] = solve_ms
    return row


def write_trajectory_csv(path: str | Path, rows: np.ndarray) -> None:
    """Write rows (n, 9) with a header row."""
    data = np.asarray(rows, dtype=float).reshape(-1, len(TRAJECTORY_COLUMNS))
    np.savetxt(path, data, delimiter=',', header=','.join(TRAJECTORY_COLUMNS), comments='',
               fmt='%.9g')


def read_trajectory_csv(path: str | Path) -> np.ndarray:
    """Read a trajectory.csv back into an (n, 9) array.

    Raises:
        ValueError: if the header is not the expected one.

    """
    with open(path, encoding='utf-8') as stream:
        header = stream.readline().strip()
    if header != ','.join(TRAJECTORY_COLUMNS):
        msg = f'{path}: expected header {",".join(TRAJECTORY_COLUMNS)!r}, got {header!r}'
        raise ValueError(msg)
    data = np.loadtxt(path, delimiter=',', skiprows=1, ndmin=2)
    return data.reshape(-1, len(TRAJECTORY_COLUMNS))
