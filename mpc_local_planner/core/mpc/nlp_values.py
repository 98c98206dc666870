# SPDX-License-Identifier: Apache-2.0
"""The numbers a formulation of problem (6) is given: its parameters, and a plan's multipliers.

formulation.py writes the NLP once, with symbols; a control step fills in numbers: the
parameter vector (measured state, weights, obstacles, terminal parameters), inputs moved into
the rate rows, and multipliers that make a plan's collision rows hold wherever it is clear.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from mpc_local_planner.core.config import CostWeights
from mpc_local_planner.core.moving_obstacles import motion_of, MOTION_SIZE, offsets_by_stage
from mpc_local_planner.core.obstacles import (
    ConvexPolygon,
    face_weights,
    ObstacleSet,
    polygon_separation,
)

__all__ = ['dual_multipliers', 'feasible_multipliers', 'obstacle_parameters',
           'parameter_vector', 'rate_limited_inputs']


def rate_limited_inputs(u: np.ndarray, u_before: np.ndarray, rate: np.ndarray, *,
                        first_order: bool = False) -> np.ndarray:
    """Return inputs moved into the rate rows of (6g) (max_accel) as far as they can be.

    Forwards from u_before (|u_0 - u_before| <= rate, |u_{l+1} - u_l| <= rate), then
    backwards from u_N = 0 (|u_{N-1}| <= rate): each input clipped into its neighbour's band.
    The result keeps every row whenever a stop from u_before fits in the horizon
    (|u_before| <= N rate); a start that jumps (from rest to half speed at once, or that
    ends moving) breaks them, and the solver begins its restoration there instead of near
    the motion the base can make.

    Args:
        u: (N, nu) inputs.
        u_before: (nu,) the input the bounds start from (the NLP's u_prev).
        rate: (nu,) max_accel h.
        first_order: the inputs are first-order-hold knots: the last one, u_{N-1}, is the
            velocity at x_N and must be 0 itself (instead of within rate of u_N = 0).

    """
    out = np.array(u, dtype=float)
    rate = np.asarray(rate, dtype=float)
    before = np.asarray(u_before, dtype=float).reshape(-1)
    for k in range(len(out)):
        out[k] = np.clip(out[k], before - rate, before + rate)
        before = out[k]
    after = np.zeros_like(rate)  # u_N = 0
    last = len(out)
    if first_order and last:
        out[-1] = 0.0  # u_{N-1} = 0
        last -= 1
    for k in reversed(range(last)):
        out[k] = np.clip(out[k], after - rate, after + rate)
        after = out[k]
    return out


def parameter_vector(x0: np.ndarray, weights: CostWeights, obstacles: np.ndarray,
                     terminal_params: np.ndarray, u_prev: np.ndarray | None = None
                     ) -> np.ndarray:
    """Return the NLP's parameters (x(k), weights, obstacles, path or target, u_prev).

    u_prev, the input commanded before, only for an NLP built with max_accel.
    """
    tail = [] if u_prev is None else [np.asarray(u_prev, dtype=float).reshape(-1)]
    return np.concatenate([x0, np.array(weights.as_vector()), obstacles, terminal_params,
                           *tail])


def obstacle_parameters(selected: Sequence[ConvexPolygon], slots: int,
                        faces: int) -> np.ndarray:
    """Return the (A, b, motion) of each obstacle slot, padded to the NLP's slots and faces.

    motion is (vx, vy, growth, |v|) of a moving obstacle (core/moving_obstacles.py), zeros for a
    static one and an empty slot.
    """
    values = []
    for j in range(slots):
        if j < len(selected):
            # pad by repeating a real face: a padding face with a huge offset would let a
            # multiplier of -1e-9 (within the solver's bound tolerance) buy a fake
            # separation of 1e6 * 1e-9
            o = selected[j]
            rows = np.minimum(np.arange(faces), o.num_faces - 1)
            A, b = o.A[rows], o.b[rows]
            motion = motion_of(o)
        else:
            A = np.zeros((faces, 2))
            b = np.full(faces, -1.0)  # an empty slot: (0 p + 1)^T mu = 1 >= margin
            motion = np.zeros(MOTION_SIZE)
        values.append(np.concatenate([A.reshape(-1, order='F'), b, motion]))
    return np.concatenate(values) if values else np.zeros(0)


def feasible_multipliers(x: np.ndarray, selected: Sequence[ConvexPolygon], slots: int,
                         faces: int, step: float = 0.0) -> np.ndarray:
    """Put each multiplier on the most separating face: a feasible mu for clear points.

    Args:
        x: (N+1, nx) states; the positions of steps 1..N get multipliers.
        selected: the obstacles of the slots (the rest are empty).
        slots: obstacle slots of the NLP.
        faces: half-planes per slot.
        step: the stage length h: a moving obstacle is taken where it is at each stage's
            time (core/moving_obstacles.py); a static one does not need it.

    Returns:
        The flat multipliers in the order of Layout.mu.

    """
    n = x.shape[0] - 1
    mu = np.zeros((n, slots, faces))
    for j in range(slots):
        if j < len(selected):
            # the padded rows repeat the last face (see obstacle_parameters)
            faces_j = min(selected[j].num_faces, faces)
            A = selected[j].A[:faces_j]
            b = offsets_by_stage(selected[j], n + 1, step)[1:, :faces_j]
            face = np.argmax(x[1:, :2] @ A.T - b, axis=1)
        else:
            face = np.zeros(n, dtype=int)
        mu[np.arange(n), j, face] = 1.0
    return mu.reshape(-1)


def dual_multipliers(x: np.ndarray, body: ConvexPolygon, selected: Sequence[ConvexPolygon],
                     slots: int, faces: int, angle: int = 2,
                     directions: np.ndarray | None = None) -> np.ndarray:
    """Return the polygon's multipliers at which each dual bound is the exact distance.

    With w the unit direction from the obstacle to the robot of their closest points
    (obstacles.polygon_separation), lambda writes w = A^T lambda with the (at most two)
    obstacle faces at its support point in direction w, and mu writes -R^T w = G^T mu with the
    robot's faces at its support point in direction -w (obstacles.face_weights). Then
    G^T mu + R^T A^T lambda = 0, |A^T lambda| = 1, and the bound (A p - b)^T lambda - g^T mu
    equals w . (q* - o*) for the two support points: the distance when they are disjoint, and
    minus the penetration depth (w a separating axis) when they overlap, the least violation.

    Args:
        x: (N+1, nx) states; the poses of steps 1..N get multipliers.
        body: the footprint in the robot frame (Footprint.body).
        selected: the obstacles of the slots (the rest are empty: lambda_0 = 1 clears them).
        slots: obstacle slots of the NLP.
        faces: half-planes per slot (an obstacle's padded faces, copies of its last one,
            get 0).
        angle: index of the heading in the state.
        directions: (N, len(selected), 2) the directions of polygon_separation for the poses
            x_1..x_N, when the caller has them already (computed here otherwise).

    Returns:
        The flat multipliers in the order of Layout.mu: per stage and slot, lambda then mu.

    """
    x = np.asarray(x, dtype=float)
    n = x.shape[0] - 1
    robot_faces = body.num_faces
    values = np.zeros((n, slots, faces + robot_faces))
    cos, sin = np.cos(x[1:, angle]), np.sin(x[1:, angle])
    real = list(selected[:slots])
    if directions is None:
        local = body.vertices
        corners = np.stack([cos[:, None] * local[None, :, 0] - sin[:, None] * local[None, :, 1],
                            sin[:, None] * local[None, :, 0] + cos[:, None] * local[None, :, 1]],
                           axis=-1) + x[1:, None, :2]
        _, directions = polygon_separation(corners, ObstacleSet(real))
    for j in range(slots):
        if j < len(real):
            w = directions[:, j]
            values[:, j, :real[j].num_faces] = face_weights(real[j].A, w)
            # -R(theta)^T w, the robot's side of the same separating direction
            turned = -np.column_stack([cos * w[:, 0] + sin * w[:, 1],
                                       -sin * w[:, 0] + cos * w[:, 1]])
            values[:, j, faces:] = face_weights(body.A, turned)
        else:
            values[:, j, 0] = 1.0
    return values.reshape(-1)
