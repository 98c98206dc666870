# Copyright 2026 mpc_local_planner developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Figures of closed-loop runs: obstacles, reference path, trajectories, predictions.

Uses matplotlib's object API with the Agg canvas, never pyplot's global state, so plots can
be drawn from worker processes and node threads without a display.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Polygon
import numpy as np

from mpc_local_planner.evaluation.trajectory import TRAJECTORY_INDEX as COL
from mpc_local_planner.worlds.world import World

__all__ = ['draw_world', 'plot_runs']

RUN_COLOURS = ('tab:blue', 'tab:red', 'tab:green', 'tab:purple', 'tab:orange', 'tab:brown',
               'tab:pink', 'tab:olive', 'tab:cyan')


def draw_world(ax: object, world: World) -> None:
    """Draw the obstacles (and their robot-radius inflation), start and goal."""
    for i, obstacle in enumerate(world.obstacles):
        ax.add_patch(Polygon(obstacle.vertices, closed=True, facecolor='0.55',
                             edgecolor='0.2', label='obstacle' if i == 0 else None))
        if world.robot_radius > 0:
            grown = obstacle.inflate(world.robot_radius)
            ax.add_patch(Polygon(grown.vertices, closed=True, fill=False, linestyle=':',
                                 edgecolor='0.4', label='inflated' if i == 0 else None))
    for pose, marker, label in ((world.start, 'o', 'start'), (world.goal, '*', 'target')):
        ax.plot(pose[0], pose[1], marker, color='black', markersize=9, label=label)
        ax.arrow(pose[0], pose[1], 0.15 * np.cos(pose[2]), 0.15 * np.sin(pose[2]),
                 head_width=0.04, color='black')


def plot_runs(
    path_png: str | Path,
    *,
    world: World,
    reference: np.ndarray | None,
    runs: Sequence[tuple[str, np.ndarray]],
    predictions: Sequence[np.ndarray] = (),
    extra_paths: Sequence[tuple[str, np.ndarray]] = (),
    title: str = '',
) -> None:
    """Draw one figure of the world with reference path, runs and predicted horizons.

    Args:
        path_png: where to write the PNG.
        world: obstacles, start and goal.
        reference: (M, >=2) sampled reference path, or None.
        runs: (label, trajectory rows) per closed-loop run.
        predictions: (N+1, >=2) predicted state sequences to overlay (a few, thin).
        extra_paths: (label, (M, 2)) further polylines, such as RRT* waypoints.
        title: figure title.

    """
    fig = Figure(figsize=(7.5, 5.5), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    draw_world(ax, world)
    if reference is not None:
        ax.plot(reference[:, 0], reference[:, 1], '--', color='0.3', linewidth=1.2,
                label='reference path p(s)')
    for label, points in extra_paths:
        ax.plot(points[:, 0], points[:, 1], '.-', color='tab:gray', linewidth=0.9,
                markersize=4, label=label)
    for i, prediction in enumerate(predictions):
        ax.plot(prediction[:, 0], prediction[:, 1], '-', color='tab:orange', linewidth=0.8,
                alpha=0.8, label='predicted horizons' if i == 0 else None)
        ax.plot(prediction[-1, 0], prediction[-1, 1], 'x', color='tab:orange', markersize=4)
    for i, (label, rows) in enumerate(runs):
        colour = RUN_COLOURS[i % len(RUN_COLOURS)]
        ax.plot(rows[:, COL['x']], rows[:, COL['y']], '-', color=colour, linewidth=2.0,
                label=label)
        ax.plot(rows[-1, COL['x']], rows[-1, COL['y']], 'o', color=colour, markersize=5)
    xmin, xmax, ymin, ymax = world.bounds
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.grid(True, linewidth=0.3)
    if title:
        ax.set_title(title)
    ax.legend(loc='best', fontsize=7)
    fig.tight_layout()
    fig.savefig(path_png)
