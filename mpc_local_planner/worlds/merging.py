# SPDX-License-Identifier: Apache-2.0
"""Merge rows of touching cylinders (BARN's walls) into thin rectangles: fewer, larger obstacles.

Cylinders whose centres are within `link` of each other form groups (no passable gap lies
between two linked cylinders when link - 2 r is below the robot's diameter). A group whose
cylinders lie on a line (within `tolerance` of the principal axis) becomes one rectangle that
contains every cylinder; other groups are split in two across their principal axis until the
pieces are straight, or single cylinders (kept as circumscribed polygons).
"""

from __future__ import annotations

import numpy as np

from mpc_local_planner.core.obstacles import ConvexPolygon

__all__ = ['merge_cylinders']


def _groups(centres: np.ndarray, link: float) -> list[np.ndarray]:
    n = len(centres)
    parent = list(range(n))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    d = np.linalg.norm(centres[:, None, :] - centres[None, :, :], axis=2)
    for i, j in zip(*np.nonzero(np.triu(d <= link, k=1)), strict=True):
        parent[find(int(i))] = find(int(j))
    roots: dict[int, list[int]] = {}
    for i in range(n):
        roots.setdefault(find(i), []).append(i)
    return [np.array(v) for v in roots.values()]


def _pieces(points: np.ndarray, radius: float, tolerance: float, sides: int,
            out: list[ConvexPolygon]) -> None:
    if len(points) == 1:
        out.append(ConvexPolygon.from_circle(float(points[0, 0]), float(points[0, 1]), radius,
                                             sides=sides))
        return
    mean = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - mean)
    axis, normal = vt[0], np.array([-vt[0][1], vt[0][0]])
    along = (points - mean) @ axis
    across = (points - mean) @ normal
    if np.ptp(across) <= tolerance:
        pad = radius + 1e-6
        lo, hi = along.min() - pad, along.max() + pad
        wlo, whi = across.min() - pad, across.max() + pad
        corners = [mean + a * axis + w * normal
                   for a, w in ((lo, wlo), (hi, wlo), (hi, whi), (lo, whi))]
        out.append(ConvexPolygon.from_vertices(np.array(corners)))
        return
    # Split across the principal axis at the largest gap between consecutive projections
    # (an L-shaped wall splits at its corner more often than at its middle).
    order = np.argsort(along)
    gaps = np.diff(along[order])
    cut = int(np.argmax(gaps)) + 1 if np.max(gaps) > 1e-9 else len(order) // 2
    cut = min(max(cut, 1), len(order) - 1)
    _pieces(points[order[:cut]], radius, tolerance, sides, out)
    _pieces(points[order[cut:]], radius, tolerance, sides, out)


def merge_cylinders(centres: np.ndarray, radius: float, *, link: float = 0.3,
                    tolerance: float = 0.03, sides: int = 8) -> list[ConvexPolygon]:
    """Return convex polygons that together contain every cylinder.

    Args:
        centres: (n, 2) cylinder centres.
        radius: cylinder radius.
        link: centres closer than this belong to one group (keep link - 2 radius below any
            gap the robot could pass).
        tolerance: a group is straight when its centres lie within this band (metres).
        sides: sides of the polygon circumscribed about a lone cylinder.

    """
    centres = np.asarray(centres, dtype=float).reshape(-1, 2)
    out: list[ConvexPolygon] = []
    for group in _groups(centres, link):
        _pieces(centres[group], radius, tolerance, sides, out)
    return out
