# SPDX-License-Identifier: Apache-2.0
r"""A run among moving obstacles as a strip of frames: who was where, and when.

    python3 -m mpc_local_planner.evaluation.evaluate --suite dynamic --robot jackal \\
        --controllers proposed,dwa,regulated_pure_pursuit --plot 12 --out out/eval/dynamic

A still picture of a world whose obstacles move cannot say whether the robot drove into a
walker or the walker into a robot that had stopped; a strip of frames can. One row per
controller, one column per instant (evenly spaced over the longest run): the static
obstacles grey, each moving one where it is at that instant (filled) with dots where it was
in the second before, the robot's path so far and its footprint at that instant. A run
that has ended shows its last pose from then on, with how it ended in the panel.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle as CirclePatch
from matplotlib.patches import Polygon as PolygonPatch
import numpy as np

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.evaluation.rollout import Rollout
from mpc_local_planner.evaluation.trajectory import TRAJECTORY_INDEX as COL
from mpc_local_planner.worlds.world import Circle, Shape, World

__all__ = ['frame_times', 'plot_dynamic_strip', 'row_at', 'STRIP_FRAMES']

# Frames per row.
STRIP_FRAMES = 6
# Seconds of a moving obstacle's past drawn as dots, and how many dots.
TRAIL_SECONDS = 1.0
TRAIL_DOTS = 5
MOVING_COLOUR = 'tab:purple'
STATIC_COLOUR = '0.6'


def frame_times(runs: Sequence[Rollout], frames: int = STRIP_FRAMES) -> np.ndarray:
    """Return the instants of the strip: frames evenly spaced from 0 to the longest run's end.

    Raises:
        ValueError: for no runs, a run without rows, or fewer than one frame.

    """
    if not runs or frames < 1 or any(len(run.rows) == 0 for run in runs):
        msg = f'a strip needs runs with rows and at least one frame, got {len(runs)} runs'
        raise ValueError(msg)
    end = max(float(run.rows[-1, COL['t']]) for run in runs)
    return np.linspace(0.0, end, frames)


def _patch(shape: Shape, **style: object) -> object:
    if isinstance(shape, Circle):
        return CirclePatch((shape.x, shape.y), shape.radius, **style)
    assert isinstance(shape, ConvexPolygon)
    return PolygonPatch(shape.vertices, closed=True, **style)


def row_at(run: Rollout, t: float) -> np.ndarray:
    """The run's last row at or before t (its last row once it has ended)."""
    times = run.rows[:, COL['t']]
    return run.rows[max(int(np.searchsorted(times, t + 1e-9, side='right')) - 1, 0)]


def plot_dynamic_strip(target: Path, world: World, runs: Sequence[tuple[str, Rollout]], *,
                       footprint: Footprint, frames: int = STRIP_FRAMES,
                       title: str = '') -> Path:
    """Draw runs in a world with moving obstacles as a strip of frames; write target (PNG).

    Args:
        target: The PNG to write (its folder is made).
        world: The world the runs drove in (its moving obstacles are drawn at each instant).
        runs: (label, rollout) per row, e.g. one per controller.
        footprint: The robot's true shape.
        frames: Instants per row (see frame_times).
        title: The figure's title.

    Returns:
        target.

    Raises:
        ValueError: for no runs or a run without rows (see frame_times).

    """
    times = frame_times([run for _, run in runs], frames)
    x0, x1, y0, y1 = world.bounds
    width = 2.6
    height = max(width * (y1 - y0) / (x1 - x0), 1.0)
    fig = Figure(figsize=(width * frames, (height + 0.35) * len(runs) + 0.5))
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(runs), frames, squeeze=False)
    static = world.physical_shapes()
    for r, (label, run) in enumerate(runs):
        end = float(run.rows[-1, COL['t']])
        for c, t in enumerate(times):
            ax = axes[r][c]
            for shape in static:
                ax.add_patch(_patch(shape, facecolor=STATIC_COLOUR, edgecolor='0.3',
                                    linewidth=0.5))
            for moving in world.moving_obstacles:
                past = [moving.position(s)
                        for s in np.linspace(max(t - TRAIL_SECONDS, 0.0), t, TRAIL_DOTS)]
                ax.plot(*np.array(past).T, '.', color=MOVING_COLOUR, markersize=2.0,
                        alpha=0.5)
                ax.add_patch(_patch(moving.shape_at(t), facecolor=MOVING_COLOUR,
                                    edgecolor='black', linewidth=0.5, alpha=0.8))
            row = row_at(run, t)
            so_far = run.rows[run.rows[:, COL['t']] <= t + 1e-9]
            ax.plot(so_far[:, COL['x']], so_far[:, COL['y']], '-', color='tab:blue',
                    linewidth=1.0)
            pose = row[[COL['x'], COL['y'], COL['theta']]]
            robot = (CirclePatch((pose[0], pose[1]), footprint.radius)
                     if footprint.is_circle else
                     PolygonPatch(footprint.at(pose), closed=True))
            robot.set(facecolor='tab:blue', edgecolor='black', linewidth=0.6, alpha=0.9,
                      zorder=5)
            ax.add_patch(robot)
            ax.plot(world.goal[0], world.goal[1], '*', color='black', markersize=7)
            if t > end + 1e-9:
                ax.text(0.02, 0.04, f'ended at {end:.1f} s: {run.outcome.value}',
                        transform=ax.transAxes, fontsize=6)
            ax.set_xlim(x0, x1)
            ax.set_ylim(y0, y1)
            ax.set_aspect('equal')
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(f't = {t:.1f} s', fontsize=8)
            if c == 0:
                ax.set_ylabel(label, fontsize=8)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(target, dpi=110)
    return target
