# SPDX-License-Identifier: Apache-2.0
"""The run figure draws the robot's true shape at a few poses: its polygon, or its circle."""

from __future__ import annotations

from pathlib import Path

from matplotlib.patches import Circle, Polygon
import numpy as np

from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.evaluation.plotting import (
    FOOTPRINT_GID,
    FOOTPRINT_INSTANTS,
    footprint_rows,
    plot_runs,
)
from mpc_local_planner.evaluation.trajectory import TRAJECTORY_COLUMNS
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import load_world

NARROW_GAP = load_world(resolve_data_file('narrow_gap'))


def straight_run(count: int = 50) -> np.ndarray:
    """Rows (t, x, y, theta, ...) along y = 0 through the gap, turning a little on the way."""
    rows = np.zeros((count, len(TRAJECTORY_COLUMNS)))
    rows[:, 0] = 0.2 * np.arange(count)
    rows[:, 1] = np.linspace(0.0, 4.0, count)
    rows[:, 3] = np.linspace(0.0, 0.3, count)
    return rows


def footprint_patches(figure) -> list:
    return [p for ax in figure.axes for p in ax.patches if p.get_gid() == FOOTPRINT_GID]


def test_a_polygon_worlds_figure_draws_the_polygon_at_evenly_spaced_poses_and_the_last(
        tmp_path: Path) -> None:
    rows = straight_run()
    figure = plot_runs(tmp_path / 'run.png', world=NARROW_GAP, reference=rows[:, 1:4],
                       runs=[('mpc_controller', rows)], footprint=NARROW_GAP.footprint)
    assert (tmp_path / 'run.png').stat().st_size > 0
    patches = footprint_patches(figure)
    picks = footprint_rows(len(rows))
    assert len(patches) == len(picks) == FOOTPRINT_INSTANTS + 1
    assert picks[0] == 0 and picks[-1] == len(rows) - 1
    for patch, index in zip(patches, picks, strict=True):
        assert isinstance(patch, Polygon)
        # the rectangle turned with the heading at that row, not an axis-aligned box
        np.testing.assert_allclose(patch.get_xy()[:4], JACKAL.at(rows[index, 1:4]))
    # one legend entry for all of them
    assert [p.get_label() for p in patches].count('robot footprint') == 1
    _, labels = figure.axes[0].get_legend_handles_labels()
    assert labels.count('robot footprint') == 1
    # the circumscribed disc is not what the polygon robot's obstacles are grown by
    assert not any(p.get_label() == 'inflated' for p in figure.axes[0].patches)


def test_a_round_robot_is_drawn_as_its_circle_and_a_point_robot_not_at_all(
        tmp_path: Path) -> None:
    rows = straight_run(5)
    round_robot = plot_runs(tmp_path / 'circle.png', world=NARROW_GAP, reference=None,
                            runs=[('a', rows)], footprint=Footprint.circle(0.2))
    circles = footprint_patches(round_robot)
    assert len(circles) == 5 and all(isinstance(c, Circle) for c in circles)
    assert {c.get_radius() for c in circles} == {0.2}
    np.testing.assert_allclose([c.center for c in circles], rows[:, 1:3])
    point = plot_runs(tmp_path / 'point.png', world=NARROW_GAP, reference=None,
                      runs=[('a', rows)], footprint=Footprint.circle(0.0))
    assert footprint_patches(point) == []
    # without a footprint (the experiments' figures), nothing is drawn either
    plain = plot_runs(tmp_path / 'plain.png', world=NARROW_GAP, reference=None,
                      runs=[('a', rows)])
    assert footprint_patches(plain) == []


def test_every_run_of_a_figure_gets_its_footprints_in_its_colour(tmp_path: Path) -> None:
    first, second = straight_run(30), straight_run(30)
    second[:, 2] = 0.5
    figure = plot_runs(tmp_path / 'two.png', world=NARROW_GAP, reference=None,
                       runs=[('a', first), ('b', second)], footprint=JACKAL)
    patches = footprint_patches(figure)
    assert len(patches) == 2 * (FOOTPRINT_INSTANTS + 1)
    colours = {tuple(p.get_edgecolor()) for p in patches}
    assert len(colours) == 2
