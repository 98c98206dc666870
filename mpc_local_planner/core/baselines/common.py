# SPDX-License-Identifier: Apache-2.0
"""What the path followers (pure pursuit, DWA) share as local controllers: plan and speed cap."""

from __future__ import annotations

import math

import numpy as np

__all__ = ['limited', 'plan_points', 'speed_limit']


def plan_points(poses: np.ndarray) -> np.ndarray:
    """Return a plan's (M, 2) points, the polyline a path follower follows.

    Raises:
        ValueError: if poses is not (M, >= 2).

    """
    points = np.asarray(poses, dtype=float)
    if points.ndim != 2 or points.shape[1] < 2:
        msg = f'a plan is (M, 3) poses, got shape {points.shape}'
        raise ValueError(msg)
    return points[:, :2]


def speed_limit(v_max: float | None) -> float | None:
    """Return a checked speed limit (None: no limit).

    Raises:
        ValueError: if v_max is not a positive number.

    """
    if v_max is None:
        return None
    if math.isnan(v_max) or v_max <= 0.0:
        msg = f'a speed limit is > 0 m/s, got {v_max}'
        raise ValueError(msg)
    return None if math.isinf(v_max) else float(v_max)


def limited(u: np.ndarray, v_max: float | None) -> np.ndarray:
    """Return the command u = (v, omega) with |v| <= v_max, its arc kept (omega scaled too)."""
    if v_max is None or abs(float(u[0])) <= v_max:
        return u
    return u * (v_max / abs(float(u[0])))
