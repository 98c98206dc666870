# SPDX-License-Identifier: Apache-2.0
"""Figures of closed-loop runs: obstacles, reference path, trajectories, predictions.

Uses matplotlib's object API with the Agg canvas, never pyplot's global state, so plots can
be drawn from worker processes and node threads without a display.

With a footprint, the robot's shape (its polygon, or its circle) is drawn at a few poses of
each run: a line says where the reference point went, not whether the corners of a
rectangular robot cleared an obstacle; the outlines show it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple, Sequence

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Polygon, Rectangle
import numpy as np

from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.evaluation.trajectory import TRAJECTORY_INDEX as COL
from mpc_local_planner.worlds.world import World

__all__ = ['CONTROLLER_COLOURS', 'FOOTPRINT_GID', 'FOOTPRINT_INSTANTS', 'draw_footprints',
           'draw_sensed', 'draw_unknown_obstacles', 'draw_world', 'footprint_rows', 'plot_runs',
           'plot_world_panels', 'WorldPanel']

RUN_COLOURS = ('tab:blue', 'tab:red', 'tab:green', 'tab:purple', 'tab:orange', 'tab:brown',
               'tab:pink', 'tab:olive', 'tab:cyan')
# Cycled with the colours, so runs whose curves coincide still show as distinct strokes.
RUN_LINESTYLES = ('-', '--', ':')
# Many runs: the first is drawn widest, the last narrowest, so coinciding curves stay visible
# as nested strokes.
WIDE_LINE, NARROW_LINE = 3.4, 1.1
# One colour per controller in the suite figures.
CONTROLLER_COLOURS = {'proposed': 'tab:blue', 'tracking': 'tab:red',
                      'pure_pursuit': 'tab:orange'}
# Controllers of the suite figures, drawn in this order from wide to narrow, so coinciding
# runs (the controllers often drive the same route) all stay visible.
CONTROLLER_STYLES = ({'linestyle': '-', 'linewidth': 3.0, 'alpha': 0.85},
                     {'linestyle': '-', 'linewidth': 1.8},
                     {'linestyle': '-.', 'linewidth': 1.2})
# Legends sit right of the axes, never over the obstacles.
LEGEND_OUTSIDE = {'loc': 'upper left', 'bbox_to_anchor': (1.02, 1.0), 'borderaxespad': 0.0}
# Reference paths are drawn over the runs.
REFERENCE_ZORDER = 5
# Obstacles in no map (only the laser finds them): hatched orange, apart from the known grey.
UNKNOWN_STYLE = {'facecolor': (1.0, 0.65, 0.0, 0.25), 'edgecolor': 'tab:orange',
                 'hatch': '///', 'linewidth': 1.2}
# Outlines of what the robot sensed, one colour per instant (early light, late dark).
SENSED_COLOURS = ('tab:cyan', 'tab:green', 'tab:purple', 'tab:brown', 'tab:pink', 'tab:olive')
# The footprint is drawn at this many evenly spaced rows of a run, plus its last row.
FOOTPRINT_INSTANTS = 6
# The gid of every footprint patch (figures and tests find them by it).
FOOTPRINT_GID = 'footprint'


def draw_world(ax: object, world: World) -> None:
    """Draw the obstacles, start and goal; for a round robot, its radius' inflation too.

    A polygon robot's obstacles are not grown by a radius (the MPC separates the polygon
    exactly), so no inflated outline is drawn for it: draw_footprints shows the robot.
    """
    round_robot = world.footprint is None or world.footprint.is_circle
    for i, obstacle in enumerate(world.obstacles):
        ax.add_patch(Polygon(obstacle.vertices, closed=True, facecolor='0.55',
                             edgecolor='0.2', label='obstacle' if i == 0 else None))
        if round_robot and world.robot_radius > 0:
            grown = obstacle.inflate(world.robot_radius)
            ax.add_patch(Polygon(grown.vertices, closed=True, fill=False, linestyle=':',
                                 edgecolor='0.4', label='inflated' if i == 0 else None))
    for pose, marker, label in ((world.start, 'o', 'start'), (world.goal, '*', 'target')):
        ax.plot(pose[0], pose[1], marker, color='black', markersize=9, label=label)
        ax.arrow(pose[0], pose[1], 0.15 * np.cos(pose[2]), 0.15 * np.sin(pose[2]),
                 head_width=0.04, color='black')


def draw_unknown_obstacles(ax: object, world: World) -> None:
    """Draw the world's unknown obstacles (in no map; the laser finds them) hatched orange."""
    for i, obstacle in enumerate(world.unknown_obstacles):
        ax.add_patch(Polygon(obstacle.vertices, closed=True,
                             label='unknown obstacle' if i == 0 else None, **UNKNOWN_STYLE))


def draw_sensed(ax: object, snapshots: Sequence[tuple[float, Sequence[np.ndarray]]]) -> None:
    """Draw obstacle outlines the robot knew at a few instants, one colour per instant.

    Args:
        ax: the axes.
        snapshots: (simulated time, (K, 2) outlines) per instant, in time order.

    """
    for i, (when, polygons) in enumerate(snapshots):
        colour = SENSED_COLOURS[i % len(SENSED_COLOURS)]
        for j, vertices in enumerate(polygons):
            ax.add_patch(Polygon(np.asarray(vertices)[:, :2], closed=True, fill=False,
                                 edgecolor=colour, linewidth=1.0, linestyle='--',
                                 label=f'sensed at {when:.1f} s' if j == 0 else None))


def footprint_rows(count: int, instants: int = FOOTPRINT_INSTANTS) -> list[int]:
    """Return the row indices the footprint is drawn at: instants evenly spaced, and the last.

    Evenly spaced from the first row, so the start is shown; the last row is always added
    (where the run ended: at the target, or stopped in front of an obstacle).
    """
    if count <= 0:
        return []
    spaced = np.linspace(0, count - 1, max(instants, 0), endpoint=False)
    return sorted({int(round(i)) for i in spaced} | {count - 1})


def draw_footprints(ax: object, footprint: Footprint, rows: np.ndarray, *,
                    colour: object = 'tab:blue', label: str | None = 'robot footprint',
                    instants: int = FOOTPRINT_INSTANTS) -> list[object]:
    """Draw the robot's shape at a few poses of a run (see footprint_rows); return the patches.

    A polygon is placed at each row's x, y, theta; a circle at its x, y. A circle of radius
    0 (a point robot) draws nothing. Every patch has gid FOOTPRINT_GID.

    Args:
        ax: the axes.
        footprint: the robot's true shape.
        rows: (n, 9) trajectory rows (t, x, y, theta, ...).
        colour: edge colour (the run's).
        label: legend label of the first patch (None: no legend entry).
        instants: evenly spaced poses drawn, besides the last.

    """
    rows = np.atleast_2d(np.asarray(rows, dtype=float))
    if footprint.radius <= 0 or rows.size == 0:
        return []
    style = {'facecolor': (0.5, 0.5, 0.5, 0.12), 'edgecolor': colour, 'linewidth': 1.0,
             'zorder': REFERENCE_ZORDER - 1}
    patches = []
    for k, index in enumerate(footprint_rows(len(rows), instants)):
        pose = rows[index, [COL['x'], COL['y'], COL['theta']]]
        name = label if k == 0 else None
        if footprint.is_circle:
            patch = Circle((pose[0], pose[1]), footprint.radius, label=name, **style)
        else:
            patch = Polygon(footprint.at(pose), closed=True, label=name, **style)
        patch.set_gid(FOOTPRINT_GID)
        ax.add_patch(patch)
        patches.append(patch)
    return patches


def _run_styles(count: int) -> list[dict[str, object]]:
    """Return a distinct (colour, linestyle, linewidth) per run."""
    styles = []
    for i in range(count):
        width = 2.0 if count <= 3 else WIDE_LINE - (WIDE_LINE - NARROW_LINE) * i / (count - 1)
        styles.append({'color': RUN_COLOURS[i % len(RUN_COLOURS)],
                       'linestyle': RUN_LINESTYLES[i % len(RUN_LINESTYLES)],
                       'linewidth': width})
    return styles


def _draw_runs(
    ax: object,
    world: World,
    reference: np.ndarray | None,
    runs: Sequence[tuple[str, np.ndarray]],
    predictions: Sequence[np.ndarray],
    extra_paths: Sequence[tuple[str, np.ndarray]],
    footprint: Footprint | None = None,
) -> None:
    draw_world(ax, world)
    for label, points in extra_paths:
        ax.plot(points[:, 0], points[:, 1], '.-', color='tab:gray', linewidth=0.9,
                markersize=4, label=label)
    for i, prediction in enumerate(predictions):
        ax.plot(prediction[:, 0], prediction[:, 1], '-', color='tab:orange', linewidth=0.8,
                alpha=0.8, label='predicted horizons' if i == 0 else None)
        ax.plot(prediction[-1, 0], prediction[-1, 1], 'x', color='tab:orange', markersize=4)
    for i, (style, (label, rows)) in enumerate(zip(_run_styles(len(runs)), runs,
                                                   strict=True)):
        ax.plot(rows[:, COL['x']], rows[:, COL['y']], label=label, **style)
        ax.plot(rows[-1, COL['x']], rows[-1, COL['y']], 'o', color=style['color'],
                markersize=5)
        if footprint is not None:
            draw_footprints(ax, footprint, rows, colour=style['color'],
                            label='robot footprint' if i == 0 else None)
    if reference is not None:
        ax.plot(reference[:, 0], reference[:, 1], '--', color='black', linewidth=1.0,
                zorder=REFERENCE_ZORDER, label='reference path p(s)')
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.grid(True, linewidth=0.3)


def plot_runs(
    path_png: str | Path,
    *,
    world: World,
    reference: np.ndarray | None,
    runs: Sequence[tuple[str, np.ndarray]],
    predictions: Sequence[np.ndarray] = (),
    extra_paths: Sequence[tuple[str, np.ndarray]] = (),
    title: str = '',
    zoom: tuple[float, float, float, float] | None = None,
    show_unknown: bool = False,
    sensed: Sequence[tuple[float, Sequence[np.ndarray]]] = (),
    footprint: Footprint | None = None,
) -> Figure:
    """Draw one figure of the world with reference path, runs and predicted horizons.

    Each run gets its own colour, linestyle and (with many runs) width; the reference path
    is drawn dashed over the runs; the legend sits right of the axes.

    Args:
        path_png: where to write the PNG.
        world: obstacles, start and goal.
        reference: (M, >=2) sampled reference path, or None.
        runs: (label, trajectory rows) per closed-loop run.
        predictions: (N+1, >=2) predicted state sequences to overlay (a few, thin).
        extra_paths: (label, (M, 2)) further polylines, such as RRT* waypoints.
        title: figure title.
        zoom: (xmin, xmax, ymin, ymax) of a second panel that enlarges where runs differ;
            the first panel marks it with a rectangle.
        show_unknown: also draw the world's unknown obstacles, hatched orange.
        sensed: (simulated time, (K, 2) outlines) of what the robot knew at a few instants,
            drawn dashed, one colour per instant.
        footprint: the robot's shape, drawn at FOOTPRINT_INSTANTS poses of each run and at
            its last (e.g. ``world.footprint``); None draws none.

    Returns:
        The figure (already written), so that callers and tests can inspect its artists.

    """
    panels = 1 if zoom is None else 2
    fig = Figure(figsize=(5.5 * panels + 2.5, 5.5), dpi=120)
    FigureCanvasAgg(fig)
    axes = [fig.add_subplot(1, panels, i + 1) for i in range(panels)]
    for ax in axes:
        _draw_runs(ax, world, reference, runs, predictions, extra_paths, footprint)
        if show_unknown:
            draw_unknown_obstacles(ax, world)
        draw_sensed(ax, sensed)
    xmin, xmax, ymin, ymax = world.bounds
    axes[0].set_xlim(xmin, xmax)
    axes[0].set_ylim(ymin, ymax)
    if zoom is not None:
        zx0, zx1, zy0, zy1 = zoom
        axes[1].set_xlim(zx0, zx1)
        axes[1].set_ylim(zy0, zy1)
        axes[1].set_title('enlarged', fontsize=9)
        axes[0].add_patch(Rectangle((zx0, zy0), zx1 - zx0, zy1 - zy0, fill=False,
                                    edgecolor='0.3', linewidth=0.8, linestyle='-.'))
    if title:
        fig.suptitle(title)
    axes[-1].legend(fontsize=7, **LEGEND_OUTSIDE)
    fig.tight_layout()
    fig.savefig(path_png, bbox_inches='tight')
    return fig


class WorldPanel(NamedTuple):
    """One world of a suite figure: its obstacles, reference path and each controller's run.

    Attributes:
        title: the panel's title (world name and outcomes).
        polygons: (k, 2) vertex arrays of convex obstacles.
        circles: (n, 2) centres of circular obstacles (BARN's cylinders), or None.
        circle_radius: their radius.
        start: start pose (x, y[, theta]).
        goal: goal position (x, y[, theta]).
        goal_tolerance: radius of the goal region drawn around the goal.
        reference: (M, 2) reference polyline, or None.
        runs: (controller name, trajectory rows, reached) per run.
        bounds: (xmin, xmax, ymin, ymax) to show, or None for the data's extent.

    """

    title: str
    polygons: Sequence[np.ndarray]
    circles: np.ndarray | None
    circle_radius: float
    start: np.ndarray
    goal: np.ndarray
    goal_tolerance: float
    reference: np.ndarray | None
    runs: Sequence[tuple[str, np.ndarray, bool]]
    bounds: tuple[float, float, float, float] | None = None


def _controller_colour(name: str, index: int) -> str:
    return CONTROLLER_COLOURS.get(name, RUN_COLOURS[index % len(RUN_COLOURS)])


def plot_world_panels(
    path_png: str | Path,
    panels: Sequence[WorldPanel],
    *,
    title: str = '',
    columns: int = 5,
    panel_size: tuple[float, float] = (3.2, 7.0),
) -> None:
    """Draw several worlds side by side, each with its obstacles, reference and runs.

    A run ends in a dot where it reached the goal and in a cross where it did not. One legend
    (controllers, reference, obstacles) sits right of the panels.

    Args:
        path_png: where to write the PNG.
        panels: the worlds.
        title: the figure's title.
        columns: panels per row at most.
        panel_size: (width, height) of one panel, inches.

    """
    count = max(1, len(panels))
    cols = min(columns, count)
    rows = math.ceil(count / cols)
    fig = Figure(figsize=(panel_size[0] * cols + 2.0, panel_size[1] * rows + 0.8), dpi=120,
                 layout='constrained')
    FigureCanvasAgg(fig)
    names: list[str] = []
    for panel in panels:
        for name, _, _ in panel.runs:
            if name not in names:
                names.append(name)

    def style(name: str) -> dict[str, object]:
        i = names.index(name)
        return {'color': _controller_colour(name, i),
                **CONTROLLER_STYLES[min(i, len(CONTROLLER_STYLES) - 1)]}

    for i, panel in enumerate(panels):
        ax = fig.add_subplot(rows, cols, i + 1)
        for vertices in panel.polygons:
            ax.add_patch(Polygon(vertices, closed=True, facecolor='0.45', edgecolor='0.2'))
        if panel.circles is not None:
            for cx, cy in panel.circles:
                ax.add_patch(Circle((cx, cy), panel.circle_radius, color='0.3'))
        if panel.reference is not None:
            ax.plot(panel.reference[:, 0], panel.reference[:, 1], '--', color='black',
                    linewidth=0.8, zorder=REFERENCE_ZORDER)
        for name, rows_, reached in sorted(panel.runs, key=lambda run: names.index(run[0])):
            run_style = style(name)
            ax.plot(rows_[:, COL['x']], rows_[:, COL['y']], **run_style)
            ax.plot(rows_[-1, COL['x']], rows_[-1, COL['y']], 'o' if reached else 'X',
                    color=run_style['color'], markersize=6, markeredgecolor='black',
                    markeredgewidth=0.5, zorder=REFERENCE_ZORDER + 1)
        ax.plot(panel.start[0], panel.start[1], 'o', color='green', markersize=7)
        ax.add_patch(Circle((panel.goal[0], panel.goal[1]), panel.goal_tolerance, fill=False,
                            color='green', linestyle=':'))
        ax.plot(panel.goal[0], panel.goal[1], '*', color='green', markersize=9)
        if panel.bounds is not None:
            ax.set_xlim(panel.bounds[0], panel.bounds[1])
            ax.set_ylim(panel.bounds[2], panel.bounds[3])
        ax.set_aspect('equal')
        ax.set_xlabel('x [m]')
        ax.set_ylabel('y [m]')
        ax.set_title(panel.title, fontsize=8)
        ax.tick_params(labelsize=7)
    handles = [Line2D([], [], label=n, **style(n)) for n in names]
    handles += [
        Line2D([], [], linestyle='--', color='black', linewidth=0.9, label='reference path'),
        Line2D([], [], linestyle='', marker='o', color='0.5', label='run end: reached'),
        Line2D([], [], linestyle='', marker='X', color='0.5', label='run end: not reached'),
        Line2D([], [], linestyle='', marker='o', color='green', label='start'),
        Line2D([], [], linestyle=':', color='green', label='goal region'),
        Line2D([], [], linestyle='', marker='s', color='0.4', label='obstacle'),
    ]
    if title:
        fig.suptitle(title)
    fig.legend(handles=handles, loc='outside right upper', fontsize=8)
    fig.savefig(path_png, bbox_inches='tight')
