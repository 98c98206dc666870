# SPDX-License-Identifier: Apache-2.0
"""The clearance of the robot's footprint from obstacles along a plan.

A round robot is a point among obstacles inflated by its radius (and the collision margin):
its clearance is the positions' signed distance, which must be at least the Farkas margin.
A polygonal footprint (config.footprint) is checked exactly: the signed distance between the
polygon at each predicted pose and each obstacle (obstacles.polygon_separation) must be at
least the clearance the motion needs, farkas_margin + h/2 (|v| + r_c |omega|) for both steps
next to the pose (exact |.| here; the NLP's smooth one is never smaller).

Clearance answers the step's geometric questions (which obstacles are near a plan, how far
a plan falls short, warm-start multipliers) and memoises the exact distances per plan: a
step asks about the same candidate and the same solutions several times. clear() empties the
memos; the step calls it at its start, so they never hold more than one step's plans.
"""

from __future__ import annotations

from typing import Sequence

import casadi as ca
import numpy as np

from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.models import RobotModel
from mpc_local_planner.core.moving_obstacles import moving, stage_lower_bound, stage_polygons
from mpc_local_planner.core.mpc.formulation import Formulation, ramp_sweep_rate, sweep_rate
from mpc_local_planner.core.mpc.nlp_values import dual_multipliers, feasible_multipliers
from mpc_local_planner.core.obstacles import (
    ConvexPolygon,
    nearest_within,
    ObstacleSet,
    polygon_separation,
)

__all__ = ['Clearance', 'MAX_CACHED_PLANS']

# Plans whose polygon clearances are memoised within a step (the candidate, the solutions).
MAX_CACHED_PLANS = 8


class Clearance:
    """The footprint of config against obstacles along plans (x, u), memoised per step.

    Args:
        model: the robot model (its heading index, its sweep rate).
        config: the settings whose footprint, step and Farkas margin apply.

    """

    def __init__(self, model: RobotModel, config: MpcConfig) -> None:
        footprint = config.robot_footprint
        self._model = model
        self._config = config
        self.body: ConvexPolygon | None = None if footprint.is_circle else footprint.body
        # r_c: no point of the body is further from the robot's origin
        self.body_radius = 0.0 if footprint.is_circle else footprint.radius
        # a first-order hold (MpcConfig.input_hold): the velocity of step l ramps from the
        # input before it; the first step's, before, is the step's u_prev (clear())
        self._first_order = config.first_order_hold
        self._sweep_exact = (ramp_sweep_rate if self._first_order else sweep_rate)(
            model, self.body_radius)
        self._sweep_maps: dict[int, ca.Function] = {}
        self._before = np.zeros(model.nu)
        self._geometry: dict[bytes, dict[int, tuple[ConvexPolygon, np.ndarray, np.ndarray]]] = {}
        self._clearance_memo: dict[bytes, np.ndarray] = {}
        # a moving obstacle's polygons at the stages (stage_polygons), per obstacle and count
        self._stages: dict[tuple[int, int], tuple[ConvexPolygon, ObstacleSet]] = {}

    def clear(self, before: np.ndarray | None = None) -> None:
        """Forget the memoised plans (a step starts: they hold that step's plans only).

        before: with a first-order hold, the velocity the step's plans start from (u_prev):
        the first ramp runs from it.
        """
        self._geometry.clear()
        self._clearance_memo.clear()
        self._stages.clear()
        if before is not None:
            self._before = np.asarray(before, dtype=float).reshape(-1).copy()

    def separation(self, x: np.ndarray, obstacles: Sequence[ConvexPolygon]
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Return polygon_separation of the polygon at every pose of x, (N+1, K) and (N+1, K, 2).

        Only for a polygonal footprint. Memoised per plan and obstacle, so each pair is
        computed once per step; an entry holds its obstacle, so that no other object can take
        over its id() meanwhile.
        """
        body = self.body
        assert body is not None  # only called for a polygonal footprint
        x = np.asarray(x, dtype=float)
        key = x.tobytes()
        if key not in self._geometry and len(self._geometry) >= MAX_CACHED_PLANS:
            self._geometry.pop(next(iter(self._geometry)))  # the oldest
        entry = self._geometry.setdefault(key, {})
        missing = list({id(o): o for o in obstacles if id(o) not in entry}.values())
        if missing:
            corners = self._corners(x)
            still = [o for o in missing if not moving(o)]
            signed, direction = polygon_separation(corners, ObstacleSet(still))
            for j, o in enumerate(still):
                entry[id(o)] = (o, signed[:, j], direction[:, j])
            stages = np.arange(len(x))
            for o in missing:
                if moving(o):
                    # pose k against the obstacle at stage k's time: the diagonal
                    signed, direction = polygon_separation(corners,
                                                           self._stage_set(o, len(x)))
                    entry[id(o)] = (o, signed[stages, stages], direction[stages, stages])
        if not obstacles:
            return np.zeros((len(x), 0)), np.zeros((len(x), 0, 2))
        columns = [entry[id(o)] for o in obstacles]
        return (np.stack([c[1] for c in columns], axis=1),
                np.stack([c[2] for c in columns], axis=1))

    def _corners(self, x: np.ndarray) -> np.ndarray:
        """Return (len(x), V, 2): the polygonal footprint's vertices at the poses of x."""
        body = self.body
        assert body is not None  # only called for a polygonal footprint
        angle = x[:, self._model.angle_index]
        cos, sin = np.cos(angle)[:, None], np.sin(angle)[:, None]
        local = body.vertices
        return np.stack([cos * local[:, 0] - sin * local[:, 1] + x[:, :1],
                         sin * local[:, 0] + cos * local[:, 1] + x[:, 1:2]], axis=-1)

    def _stage_set(self, obstacle: ConvexPolygon, stages: int) -> ObstacleSet:
        """Return the moving obstacle at stages 0..stages-1, built once per step.

        Every plan a step checks (the candidate, the solutions, an evasion's moves) meets the
        obstacle at the same stage times; an entry holds its obstacle, so that no other object
        can take over its id() meanwhile.
        """
        key = (id(obstacle), stages)
        entry = self._stages.get(key)
        if entry is None:
            entry = self._stages[key] = (obstacle, ObstacleSet(
                stage_polygons(obstacle, stages, self._config.step)))
        return entry[1]

    def required(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Return the clearance x_1..x_N need: farkas_margin + h/2 of the faster adjacent step.

        Over a step every point of the body moves at most h sweep_rate(x_l, u_l) (exact |.|
        here); a pose at least half of that from an obstacle on both of its steps keeps the
        continuous motion between the samples clear. After x_N, u_N = 0: no motion. With a
        first-order hold, the rate of the faster end of each ramp (ramp_sweep_rate), the
        first ramp from the step's u_prev (clear()).
        """
        x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
        key = x.tobytes() + u.tobytes()
        required = self._clearance_memo.get(key)
        if required is not None:
            return required
        n = len(u)
        rate_map = self._sweep_maps.get(n)
        if rate_map is None:
            rate_map = self._sweep_maps[n] = self._sweep_exact.map(n)
        if self._first_order:
            before = np.vstack([self._before.reshape(1, -1), u[:-1]])
            rates = np.asarray(rate_map(x[:-1].T, before.T, u.T)).reshape(-1)
        else:
            rates = np.asarray(rate_map(x[:-1].T, u.T)).reshape(-1)
        after = np.append(rates[1:], 0.0)
        c = self._config
        required = c.farkas_margin + c.step / 2 * np.maximum(rates, after)
        if len(self._clearance_memo) >= MAX_CACHED_PLANS:
            self._clearance_memo.pop(next(iter(self._clearance_memo)))  # the oldest
        self._clearance_memo[key] = required
        return required

    def violation(self, form: Formulation, w: np.ndarray, params: np.ndarray,
                  obstacles: ObstacleSet) -> float:
        """Return the largest violation of form's rows and bounds at w, collisions geometric.

        The geometric check does not trust the multipliers: whatever the solver did with
        them, every predicted position l = 1..N must clear every given obstacle (those of the
        NLP, or every reachable one).
        """
        g = np.asarray(form.g_fn(w, params)).reshape(-1)
        viol = np.maximum(form.lbg - g, 0) + np.maximum(g - form.ubg, 0)
        viol_w = np.maximum(form.lbw - w, 0) + np.maximum(w - form.ubw, 0)
        worst = max(np.max(viol, initial=0.0), np.max(viol_w, initial=0.0))
        return max(float(worst),
                   self.penetration(w[form.layout.x], w[form.layout.u], obstacles))

    def first_round(self, candidate_x: np.ndarray, candidate_u: np.ndarray,
                    guided: tuple[np.ndarray, np.ndarray] | None, reachable: ObstacleSet,
                    distance: float) -> list[ConvexPolygon]:
        """Return the obstacles a step's first constraint-generation round holds.

        Those within distance of the candidate, and, when guided (states, inputs) is given,
        of that motion too: a robot that cannot stop at once (max_accel) whose candidate stands
        still, or one whose first-order-hold solution leaves its spot along the path, comes
        near obstacles the candidate does not, and the rounds that add them spend the step's
        budget (docs/real_robot.md; laser-only BARN world 55, real base).
        """
        active = self.near_trajectory(candidate_x, candidate_u, reachable, distance)
        if guided is not None:
            active = active + [o for o in self.near_trajectory(*guided, reachable, distance)
                               if not any(o is a for a in active)]
        return active

    def near_trajectory(self, x: np.ndarray, u: np.ndarray, reachable: ObstacleSet,
                        distance: float) -> list[ConvexPolygon]:
        """Return the reachable obstacles within distance of the plan (x, u), nearest first.

        A circle: of the positions x. A polygon: whose clearance from the polygon at some
        pose x_l exceeds what the motion needs there by at most distance (exact distances,
        after a cheap bound has left out those further than r_c + distance + that).
        """
        if not len(reachable):
            return []
        if self.body is None:
            bound = np.min(self.lower_bounds(x, reachable), axis=0)
            return [reachable.obstacles[i] for i in nearest_within(bound, distance)]
        # x_0 is not constrained: only its Farkas margin, as for a circle
        required = np.concatenate([[self._config.farkas_margin], self.required(x, u)])
        bound = self.lower_bounds(x, reachable) - self.body_radius - required[:, None]
        near = [reachable.obstacles[i]
                for i in np.flatnonzero(np.min(bound, axis=0) <= distance)]
        signed, _ = self.separation(x, near)
        slack = np.min(signed - required[:, None], axis=0, initial=np.inf)
        return [near[i] for i in nearest_within(slack, distance)]

    def penetration(self, x: np.ndarray, u: np.ndarray, obstacles: ObstacleSet) -> float:
        """Return how far the plan's poses x_1..x_N fall short of their clearance (0: clear).

        The worst stage against the worst obstacle of margins(), as a depth.
        """
        return float(np.max(-self.margins(x, u, obstacles), initial=0.0))

    def margins(self, x: np.ndarray, u: np.ndarray, obstacles: ObstacleSet) -> np.ndarray:
        """Return (N,): each pose x_1..x_N's clearance beyond what it needs (< 0: short).

        A circle: the positions against the inflated obstacles, less the Farkas margin. A
        polygon: the exact distance of the polygon at each pose less the clearance its
        motion needs (required()); the exact distances are computed only for the obstacles
        a cheap bound (r_c around the positions) cannot clear, and the others count with
        that bound (a margin never above the true one, and never below 0). A moving obstacle
        is taken where it is at each stage's time, so the stage of a first negative margin
        says when a plan would meet it (core/evasion.py).
        """
        stages = len(x) - 1
        if not len(obstacles):
            return np.full(stages, np.inf)
        if self.body is None:
            return np.min(self.lower_bounds(x[1:], obstacles, first=1)
                          - self._config.farkas_margin, axis=1)
        required = self.required(x, u)[:, None]
        margin = self.lower_bounds(x[1:], obstacles, first=1) - self.body_radius - required
        unclear = np.flatnonzero(np.any(margin < 0.0, axis=0))
        if len(unclear):
            margin[:, unclear] = (self.separation(x, [obstacles.obstacles[i] for i in unclear])
                                  [0][1:] - required)
        return np.min(margin, axis=1)

    def margins_of_many(self, xs: np.ndarray, us: np.ndarray, obstacles: ObstacleSet
                        ) -> np.ndarray:
        """Return (P, N): margins() of P plans at once (states (P, N+1, nx), inputs (P, N, nu)).

        The same shortfalls as margins() plan by plan, in one pass per obstacle: exact
        distances only for the poses a cheap bound cannot clear, each against the obstacle
        where it is at that pose's stage (a clear pose's margin may be the bound here where
        margins() has the exact one: both >= 0). For the many short plans of an evasion
        (core/evasion.py), where plan by plan would cost a call per plan and obstacle.
        """
        xs, us = np.asarray(xs, dtype=float), np.asarray(us, dtype=float)
        count, stages = xs.shape[0], xs.shape[1] - 1
        if not len(obstacles) or count == 0:
            return np.full((count, stages), np.inf)
        stage_of_row = np.tile(np.arange(1, stages + 1), count)
        bounds = self.lower_bounds(xs[:, 1:].reshape(count * stages, -1), obstacles,
                                   stages=stage_of_row).reshape(count, stages, -1)
        if self.body is None:
            return np.min(bounds - self._config.farkas_margin, axis=2)
        required = np.stack([self.required(x, u) for x, u in zip(xs, us, strict=True)])
        margin = bounds - self.body_radius - required[..., None]
        for j in np.flatnonzero(np.any(margin < 0.0, axis=(0, 1))):
            plan, stage = np.nonzero(margin[:, :, j] < 0.0)
            corners = self._corners(xs[plan, stage + 1])
            obstacle = obstacles.obstacles[j]
            if moving(obstacle):
                polygons = self._stage_set(obstacle, stages + 1).obstacles
                signed = np.empty(len(stage))
                for k in np.unique(stage):
                    at = stage == k
                    signed[at] = polygon_separation(corners[at],
                                                    ObstacleSet([polygons[k + 1]]))[0][:, 0]
            else:
                signed = polygon_separation(corners, ObstacleSet([obstacle]))[0][:, 0]
            margin[plan, stage, j] = signed - required[plan, stage]
        return np.min(margin, axis=2)

    def lower_bounds(self, x: np.ndarray, obstacles: ObstacleSet, *, first: int = 0,
                     stages: np.ndarray | None = None) -> np.ndarray:
        """Return (len(x), K): each position's signed-distance lower bound to each obstacle.

        Row k of x is stage first + k of a plan (or stage stages[k], for the poses of many
        plans): a moving obstacle is taken where it is at that stage's time
        (core/moving_obstacles.py), a static one where it is.
        """
        x = np.asarray(x, dtype=float)
        bounds = obstacles.signed_distance_lower_bound(x[:, :2])
        for j, o in enumerate(obstacles.obstacles):
            if moving(o):
                bounds[:, j] = stage_lower_bound(o, x[:, :2], self._config.step, first=first,
                                                 stages=stages)
        return bounds

    def multipliers(self, x: np.ndarray, selected: list[ConvexPolygon],
                    form: Formulation) -> np.ndarray:
        """Return multipliers of form that are feasible for the states x wherever x is clear."""
        if self.body is not None:
            _, directions = self.separation(x, selected[:form.slots])
            return dual_multipliers(x, self.body, selected, form.slots, form.faces,
                                    self._model.angle_index, directions[1:])
        return feasible_multipliers(x, selected, form.slots, form.faces, self._config.step)
