# SPDX-License-Identifier: Apache-2.0
"""Problem (6) of the paper with cost (5), written once as a CasADi NLP.

This file is the paper's optimisation problem and nothing else: which solver runs it lives in
backends.py, what is done with its answer in step.py. Each constraint below cites its line of
problem (6) (`eq:mpcOpt`, lines (6a) to (6h)):

    (6a)  min  J_N = sum_{l=0}^{N-1} l(x_l - x_s, u_l - u_s) + V_o(1 - s)        cost (5)
    (6b)  x_0 = x(k)
    (6c)  x_{l+1} = f(x_l, u_l),  l = 0..N-1
    (6d)  x_s = x_N, u_s = u_N
    (6e)  x_s = f(x_s, u_s)                       (a steady state: g_p gives one, with u_s = 0)
    (6f)  g(x_s) = p(s),  s in [0, 1]             (together: x_N = g_p(s))
    (6g)  (x_l, u_l) in Z                         (box bounds on states and inputs)
    (6h)  B(x_l) and O_i disjoint, l = 1..N       a circle: via Farkas, (8): mu >= 0,
                                                  sum(mu) = 1, (A p_l - b)^T mu >= farkas_margin
                                                  on obstacles inflated by the radius;
                                                  a polygon: the exact dual condition below

A polygonal footprint B = {y : G y <= g} (robot frame, unit rows) placed at x_l is
R(theta_l) B + p_l; it keeps the distance d from the obstacle {q : A q <= b} iff there are
lambda >= 0 (obstacle faces) and mu >= 0 (robot faces) with (Zhang, Liniger and Borrelli,
"Optimization-based collision avoidance", IEEE TCST 2021):

    (A p_l - b)^T lambda - g^T mu >= d,   G^T mu + R(theta_l)^T A^T lambda = 0,
    ||A^T lambda||_2^2 <= 1.

For any feasible multipliers the left side is at most the distance (weak duality), and at the
best ones it is the distance; nlp_values.dual_multipliers() builds those from the closest
points. The clearance d follows the motion: over a step with inputs u every point of the body
moves at most (|p'| + r_c |theta'|) h (r_c the farthest vertex), so a sample at least half
that away from an obstacle on both its steps keeps the continuous motion clear (see
sweep_rate()). x_0 is measured, not constrained (as for the circle): the first half of the
first step relies on the clearance the previous plan gave x_0 as its x_1, sized for that
plan's inputs.

The measured state, the weights, the obstacles and the path are solver *parameters*, so the
NLP is built once per obstacle shape and a control step only fills in numbers.

The terminal condition (6d)-(6f) and the offset cost are what the paper changes with respect
to the tracking MPC of Limon et al.; they are a TerminalCondition: path_terminal() here is
the paper's, the baseline's is in core/baselines/tracking_mpc.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple

import casadi as ca
import numpy as np

from mpc_local_planner.core.config import CostWeights, MpcConfig
from mpc_local_planner.core.models import RobotModel
from mpc_local_planner.core.moving_obstacles import MOTION_SIZE
from mpc_local_planner.core.paths import ReferencePath

__all__ = [
    'Formulation', 'Layout', 'Row', 'SWEEP_SMOOTHING', 'TerminalCondition',
    'disc_collision_rows', 'formulate', 'gap_closing_rows', 'initial_state_rows',
    'obstacle_halfplanes', 'path_terminal', 'polygon_collision_rows', 'ramp_sweep_rate',
    'rate_rows', 'stage_cost', 'stage_offsets', 'sweep_rate', 'symbolic_weights', 'terminal_rows',
    'variable_bounds',
]

# eps of the smooth |z| ~ sqrt(z^2 + eps^2) in the NLP's motion-dependent clearance (m/s and
# rad/s). It is never below |z|, so the NLP is never less careful than the exact check; it is
# at most eps above it, h/2 eps (1 + r_c) = 1.3 mm of clearance for the Jackal at h = 0.2 s;
# and its minimum is at z = 0, so stopping (u_N = 0) never asks for more clearance than
# moving (the shifted candidate stays feasible). Its curvature 1 / eps at z = 0 is what the
# solver pays for: with 1e-3 fatrop and IPOPT both ran out of iterations driving straight
# (omega near 0) through a gap with the clearance active; 1e-2 solved every step.
SWEEP_SMOOTHING = 1e-2


def symbolic_weights(vector: ca.SX) -> CostWeights:
    """Return the weight parameter's entries by name (a CostWeights of CasADi symbols)."""
    return CostWeights(*ca.vertsplit(vector))


def stage_cost(model: RobotModel, exponent: int) -> ca.Function:
    """Return the stage cost l(x - x_s, u - u_s) of (5) as a Function of (x, u, x_s, weights).

    l = position ((dx)^p + (dy)^p) + heading (dtheta)^p + v (v - v_s)^p
    + omega (omega - omega_s)^p, with p = exponent (4 in the paper: the fourth power makes
    Assumption 3 hold for the unicycle, whose linearisation is not controllable).
    Further states share the heading's weight, further inputs the turn rate's.
    """
    x, x_s = ca.SX.sym('x', model.nx), ca.SX.sym('x_s', model.nx)
    u, w = ca.SX.sym('u', model.nu), ca.SX.sym('w', len(CostWeights._fields))
    weights = symbolic_weights(w)
    _, u_s = model.steady_state(x_s[:3])
    state_w = ca.vertcat(weights.position, weights.position, weights.heading,
                         *([weights.heading] * (model.nx - 3)))
    input_w = ca.vertcat(weights.v, weights.omega, *([weights.omega] * (model.nu - 2)))
    cost = ca.dot(state_w, (x - x_s) ** exponent) + ca.dot(input_w, (u - u_s) ** exponent)
    return ca.Function('stage', [x, u, x_s, w], [cost])


@dataclass(frozen=True)
class TerminalCondition:
    """How the prediction ends, (6d)-(6f), and what the offset cost measures.

    The artificial steady state is parametrised by a reference variable r (the path progress
    s in the paper) that is a decision variable, copied along the horizon. With ``carried``
    the steady state x_s(r) is copied along the horizon too, as a stage state, and evaluated
    once, at the last stage: a waypoint path's p(s) (hundreds of operations at the capacity
    of 128 segments) would otherwise be written into every stage cost, which made the
    generated C code 11 MB per NLP and its compilation four minutes.

    Attributes:
        family: key of the symbolic structure: NLPs are rebuilt when it changes.
        dim: size of r.
        num_params: size of the parameters it reads (the path's, or the target's).
        lower: lower bound of r.
        upper: upper bound of r.
        steady_state: (r, params) -> the artificial steady state x_s(r).
        condition: (x_N, x_s, r, params, weights) -> (residual that must be 0, offset cost
            without its weight); x_s is steady_state(r) (or the carried copy of it).
        carried: copy x_s(r) along the horizon instead of evaluating it at every stage.

    """

    family: str
    dim: int
    num_params: int
    lower: np.ndarray
    upper: np.ndarray
    steady_state: Callable[[ca.SX, ca.SX], ca.SX]
    condition: Callable[[ca.SX, ca.SX, ca.SX, ca.SX, CostWeights], tuple[ca.SX, ca.SX]]
    carried: bool = False


def path_terminal(model: RobotModel, path: ReferencePath) -> TerminalCondition:
    """Return the paper's terminal condition: x_N = g_p(s), u_N = 0, s in [0, 1].

    The offset cost is V_o(1 - s) = (1 - s)^2 (weighted by weights.offset in formulate()).
    """

    def steady_state(r: ca.SX, params: ca.SX) -> ca.SX:
        # (6e)-(6f): the steady state whose pose is the path's point p(s)
        x_s, _ = model.steady_state(path.symbolic(r[0], params))
        return x_s

    def condition(x_n: ca.SX, x_s: ca.SX, r: ca.SX, params: ca.SX,
                  weights: CostWeights) -> tuple[ca.SX, ca.SX]:
        # (6d): x_N = x_s = g_p(s); V_o(1 - s) = (1 - s)^2
        return x_n - x_s, (1 - r[0]) ** 2

    return TerminalCondition(family=path.family, dim=1, num_params=path.num_params,
                             lower=np.zeros(1), upper=np.ones(1),
                             steady_state=steady_state, condition=condition,
                             # a parametrised path (waypoints) is costly to evaluate, a
                             # closed-form one (the paper's sinusoid) is not
                             carried=path.num_params > 0)


def sweep_rate(model: RobotModel, radius: float, smoothing: float | None = None
               ) -> ca.Function:
    """Return the speed bound of every point of the body, |p'| + radius |theta'|, of (x, u).

    A body point at y (robot frame, |y| <= radius) moves at p' + theta' J R(theta) y, so no
    point moves faster than this; over a step of length h with constant rates, no point moves
    further than h times it. The rates are the model's own (model.rhs), constant over a step
    for the unicycle; a model whose heading rate changes within a step (the bicycle's
    steering) is taken at the step's start.

    Args:
        model: the robot model.
        radius: the footprint's farthest vertex from the robot's origin (r_c).
        smoothing: None: the exact |.| (for checks); eps: sqrt(z^2 + eps^2) instead of |z|,
            never below |z| and smooth (for the NLP's derivatives).

    """
    x, u = ca.SX.sym('x', model.nx), ca.SX.sym('u', model.nu)
    rates = model.rhs(x, u)
    speed2 = rates[0] ** 2 + rates[1] ** 2
    turn = rates[model.angle_index]
    eps2 = 0.0 if smoothing is None else smoothing ** 2
    if smoothing is None:
        value = ca.sqrt(speed2) + radius * ca.fabs(turn)
    else:
        value = ca.sqrt(speed2 + eps2) + radius * ca.sqrt(turn ** 2 + eps2)
    return ca.Function('sweep_rate', [x, u], [value])


def ramp_sweep_rate(model: RobotModel, radius: float, smoothing: float | None = None
                    ) -> ca.Function:
    """Return the speed bound of every body point over a first-order-hold step, of (x, q, u).

    The velocity ramps linearly from q to u, so each |rate| is largest at one end: the bound
    is max(|p'(q)|, |p'(u)|) + radius max(|theta'(q)|, |theta'(u)|), both taken at x as in
    sweep_rate (the unicycle's |p'| = |v| does not depend on the heading). Smoothed, each
    max(a, b) is (a + b + sqrt((a - b)^2 + eps^2)) / 2 of the smoothed |.|: never below it.
    """
    x = ca.SX.sym('x', model.nx)
    q, u = ca.SX.sym('q', model.nu), ca.SX.sym('u', model.nu)
    eps2 = 0.0 if smoothing is None else smoothing ** 2
    ends = []
    for v in (q, u):
        rates = model.rhs(x, v)
        speed2, turn = rates[0] ** 2 + rates[1] ** 2, rates[model.angle_index]
        ends.append((ca.sqrt(speed2 + eps2), ca.sqrt(turn ** 2 + eps2)))
    if smoothing is None:
        value = ca.fmax(ends[0][0], ends[1][0]) + radius * ca.fmax(ends[0][1], ends[1][1])
    else:
        def smax(a: ca.SX, b: ca.SX) -> ca.SX:
            return (a + b + ca.sqrt((a - b) ** 2 + eps2)) / 2
        value = smax(ends[0][0], ends[1][0]) + radius * smax(ends[0][1], ends[1][1])
    return ca.Function('ramp_sweep_rate', [x, q, u], [value])


class Layout(NamedTuple):
    """Indices of each variable in the NLP's decision vector w."""

    x: np.ndarray  # (N+1, nx) the states x_0..x_N
    r: np.ndarray  # (N+1, nr) the copies of the reference r (s, or the steady state)
    # (N+1, nx) the copies of the steady state x_s(r) (TerminalCondition.carried), else (N+1, 0)
    xs: np.ndarray
    u: np.ndarray  # (N, nu) the inputs u_0..u_{N-1}
    mu: np.ndarray  # (N, slots * block) the multipliers of steps 1..N (see Formulation)
    # (N, 1) the sweep rate of the step before x_1..x_N (polygon), (N, 0) for a circle
    c: np.ndarray = np.zeros((0, 0), dtype=int)
    # (N+1, nu) the copies of the input before each stage (u_prev, u_0..u_{N-1}) with
    # max_accel, else (N+1, 0)
    prev: np.ndarray = np.zeros((0, 0), dtype=int)


@dataclass(frozen=True)
class Formulation:
    """Problem (6) for a given number of obstacle slots, ready for casadi.nlpsol.

    Attributes:
        problem: nlpsol's {'x': w, 'p': parameters, 'f': J_N, 'g': constraints}.
        structure: the stage sizes a structure-exploiting solver needs (fatrop's N, nx,
            nu, ng).
        slots: obstacles the NLP holds.
        faces: half-planes per obstacle slot.
        robot_faces: faces of the polygonal footprint (0 for a circle). Each slot's block of
            multipliers is its faces' Farkas mu (circle), or its faces' lambda followed by
            the robot's faces' mu (polygon).
        sweep_fn: the smoothed sweep_rate(x, u) the polygon's NLP carries from one stage to
            the next, mapped over the N steps (columns x_0..x_{N-1}, u_0..u_{N-1}); with
            first_order ramp_sweep_rate(x, q, u) (columns q_0..q_{N-1} too); None for a
            circle.
        first_order: the inputs are first-order-hold knots (MpcConfig.input_hold): the
            velocity of step l ramps from q_l (the input before, q_0 = u_prev) to u_l.
        lbw: lower bounds of w.
        ubw: upper bounds of w.
        lbg: lower bounds of the constraints.
        ubg: upper bounds of the constraints.
        layout: where x, r, u and mu sit in w.
        cost_fn: J_N as a Function of (w, parameters).
        g_fn: the constraints as a Function of (w, parameters).

    """

    problem: dict[str, ca.SX]
    structure: dict[str, int | list[int]]
    slots: int
    faces: int
    lbw: np.ndarray
    ubw: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    layout: Layout
    cost_fn: ca.Function
    g_fn: ca.Function
    robot_faces: int = 0
    sweep_fn: ca.Function | None = None
    first_order: bool = False

    @property
    def block(self) -> int:
        """Multipliers per obstacle slot and stage."""
        return self.faces + self.robot_faces

    def pack(self, x: np.ndarray, r: np.ndarray, u: np.ndarray, mu: np.ndarray,
             steady: np.ndarray | None = None, u_prev: np.ndarray | None = None
             ) -> np.ndarray:
        """Return the decision vector w holding states, reference, inputs and multipliers.

        The polygon's carried sweep rates are computed here from x and u, so that the
        gap-closing constraints of a rolled-out plan hold exactly; a carried steady state
        is the given x_s(r) at every stage (required then); so is the input before the
        horizon with max_accel (the carried copies are u_prev, u_0, ..., u_{N-1}).
        """
        w = np.zeros(self.lbw.shape[0])
        w[self.layout.x] = x
        w[self.layout.r] = r
        if self.layout.xs.size:
            if steady is None:
                msg = 'this formulation carries the steady state: pack needs it'
                raise ValueError(msg)
            w[self.layout.xs] = np.asarray(steady, dtype=float).reshape(1, -1)
        w[self.layout.u] = u
        if self.layout.prev.size:
            if u_prev is None:
                msg = 'this formulation bounds input rates: pack needs u_prev'
                raise ValueError(msg)
            w[self.layout.prev] = np.vstack([np.asarray(u_prev, dtype=float).reshape(1, -1),
                                             np.asarray(u, dtype=float)])
        w[self.layout.mu] = mu.reshape(self.layout.mu.shape)
        if self.sweep_fn is not None and self.first_order:
            before = np.vstack([np.asarray(u_prev, dtype=float).reshape(1, -1),
                                np.asarray(u, dtype=float)[:-1]])
            rates = self.sweep_fn(np.asarray(x[:-1], dtype=float).T, before.T,
                                  np.asarray(u, dtype=float).T)
            w[self.layout.c[:, 0]] = np.asarray(rates).reshape(-1)
        elif self.sweep_fn is not None:
            rates = self.sweep_fn(np.asarray(x[:-1], dtype=float).T,
                                  np.asarray(u, dtype=float).T)
            w[self.layout.c[:, 0]] = np.asarray(rates).reshape(-1)
        return w


def formulate(model: RobotModel, config: MpcConfig, terminal: TerminalCondition,
              slots: int, faces: int) -> Formulation:
    """Write problem (6) in the stage-wise order structure-exploiting solvers need.

    Variables: z_0, u_0, z_1, u_1, mu_1, ..., z_{N-1}, u_{N-1}, mu_{N-1}, z_N, mu_N with
    z_l = (x_l, r_l): the reference r is copied along the horizon (r_{l+1} = r_l) so that each
    stage cost l(x_l - x_s(r_l), ...) only touches its own stage. Constraints, per stage l:
    the gap-closing z_{l+1} = (f(x_l, u_l), r_l), then the stage's own constraints (x_0 = x(k)
    at l = 0, the collision rows of x_l at l >= 1, the terminal condition at l = N). Each
    family of rows has its builder below (gap_closing_rows, rate_rows, initial_state_rows,
    disc_collision_rows, polygon_collision_rows, terminal_rows; variable_bounds for w).

    With a polygonal footprint (config.footprint), z_l = (x_l, r_l, c_l) for l >= 1 carries
    c_l = sweep_rate(x_{l-1}, u_{l-1}) too: the clearance at x_l must cover the step before
    it and the step after it, and a stage's constraints may only touch its own variables.
    mu_l then holds, per slot, the lambda of its faces and the mu of the robot's faces.

    With config.max_accel (a real base: its inputs cannot jump), z_l ends with q_l, the input
    before stage l (q_0 = u_prev, a parameter; q_{l+1} = u_l by the gap-closing rows), and
    stage l bounds |u_l - q_l| <= max_accel h, stage N |q_N| <= max_accel h (u_N = 0). The
    proof's shifted candidate keeps them (its inputs u_1..u_{N-1}, 0 follow u_0, which was
    commanded), so the guarantee holds for the commanded inputs.

    With config.input_hold 'first_order' the inputs are the knots of a piecewise-linear
    velocity: step l integrates the model with the velocity ramping from q_l to u_l
    (model.discrete_ramp), the rate rows bound its acceleration, and stage N asks q_N =
    u_{N-1} = 0 (x_N is reached at that velocity: the steady state needs it at rest). A
    polygon's clearance covers the faster end of each ramp (ramp_sweep_rate). The shifted
    candidate (knots u_1..u_{N-1}, 0 from q_0 = u_0) keeps every row.

    Args:
        model: the robot model (f, bounds Z, steady states).
        config: horizon N, step h, cost exponent, Farkas margin and footprint.
        terminal: the terminal condition and offset cost (path_terminal for the paper).
        slots: obstacles the NLP holds.
        faces: half-planes per obstacle.

    Returns:
        The NLP, its bounds and the layout of its decision vector.

    """
    n, nx, nu = config.horizon, model.nx, model.nu
    nr = terminal.dim
    ns = nx if terminal.carried else 0  # the carried steady state
    nz = nx + nr + ns
    footprint = config.robot_footprint
    polygon = not footprint.is_circle
    if polygon:
        body = footprint.body  # {y : G y <= g}, unit rows, robot frame
        G, g_body = ca.DM(body.A), ca.DM(body.b)
        robot_faces = body.num_faces
        sweep = (ramp_sweep_rate if config.first_order_hold else sweep_rate)(
            model, footprint.radius, SWEEP_SMOOTHING)
    else:
        robot_faces = 0
        sweep = None
    nc = 1 if polygon else 0  # the carried sweep rate of z_1..z_N
    npv = nu if config.max_accel is not None else 0  # the carried input before each stage
    first_order = config.first_order_hold
    rate = (np.asarray(config.max_accel, dtype=float) * config.step if npv
            else np.zeros(0))
    block = faces + robot_faces
    nm = block * slots
    # RK4 over one step h; with a first-order hold, of the ramp from q_l to u_l
    f = model.discrete_ramp(config.step) if first_order else model.discrete(config.step)
    stage = stage_cost(model, config.cost_exponent)
    half_step = config.step / 2

    # ---- parameters: the measured state, the weights, the obstacles, the path (or target)
    x_k = ca.SX.sym('x0', nx)
    w_weights = ca.SX.sym('w', len(CostWeights._fields))
    weights = symbolic_weights(w_weights)
    obs = ca.SX.sym('obs', (3 * faces + MOTION_SIZE) * slots)
    p_path = ca.SX.sym('path', terminal.num_params)
    u_prev = ca.SX.sym('u_prev', npv)
    A_list, b_list, motion_list = obstacle_halfplanes(obs, slots, faces)

    # ---- decision variables, stage by stage, in the order _blocks writes once
    blocks = _blocks(n, nx, nr, nz, nu, nm, nc, npv)
    Z = [ca.SX.sym(f'z{k}', sum(size for _, size in blocks[k]['z'])) for k in range(n + 1)]
    # q_l, the input before stage l, at the end of z_l
    Q = [Z[k][Z[k].numel() - npv:] for k in range(n + 1)]
    U = [ca.SX.sym(f'u{k}', nu) for k in range(n)]  # u_N = u_s is a constant, (6d)-(6e)
    MU = [None] + [ca.SX.sym(f'mu{k}', nm) for k in range(1, n + 1)]
    symbols = {'z': Z, 'u': U, 'mu': MU}
    w = ca.vertcat(*(symbols[kind][k] for k in range(n + 1) for kind in blocks[k]))
    layout = _layout(blocks, n, nu, nm, nc, npv)

    g, lbg, ubg = [], [], []
    ng_stage = []

    def add(rows: list[Row]) -> int:
        count = 0
        for expr, lower, upper in rows:
            size = expr.numel()
            g.append(ca.vec(expr))
            lbg.append(np.full(size, lower, dtype=float))
            ubg.append(np.full(size, upper, dtype=float))
            count += size
        return count

    cost = 0
    for k in range(n + 1):
        x_l, r_l = Z[k][:nx], Z[k][nx:nx + nr]
        x_s = Z[k][nx + nr:nz] if ns else terminal.steady_state(r_l, p_path)
        # the inputs of step k: u_k, or the ramp from q_k to u_k
        step_inputs = (Q[k], U[k]) if first_order and k < n else (U[k],) if k < n else ()
        if k < n:
            # (6a), cost (5): + l(x_l - x_s, u_l - u_s)
            cost = cost + stage(x_l, U[k], x_s, w_weights)
            # the steady state (when carried), this step's sweep rate (a polygon) and input
            # (max_accel) go on to the next stage
            carried = ([x_s] if ns else []) + ([sweep(x_l, *step_inputs)] if polygon
                                               else []) + ([U[k]] if npv else [])
            add(gap_closing_rows(Z[k + 1], f(x_l, *step_inputs), r_l, carried))
        rows = 0
        # the obstacles at this stage's time (moving ones moved and grown; static as given)
        b_stage = [stage_offsets(A, b, motion, k * config.step, half_step)
                   for A, b, motion in zip(A_list, b_list, motion_list, strict=True)]
        if npv:
            rows += add(rate_rows(k, n, Q[k], U[k] if k < n else None, u_prev, rate,
                                  first_order))
        if k == 0:
            rows += add(initial_state_rows(x_l, x_k))
        elif polygon:
            rows += add(polygon_collision_rows(
                x_l, model.angle_index, MU[k], A_list, b_stage, faces, G, g_body,
                config.farkas_margin,
                # the step before x_l, and the one after it (u_N = 0: none)
                [half_step * Z[k][nz]]
                + ([half_step * sweep(x_l, *step_inputs)] if k < n else [])))
        else:
            rows += add(disc_collision_rows(x_l[0:2], MU[k], A_list, b_stage, faces,
                                            config.farkas_margin))
        if k == n:
            end_rows, offset_cost = terminal_rows(terminal, x_l, x_s, r_l, p_path,
                                                  weights, carried=bool(ns))
            rows += add(end_rows)
            cost = cost + weights.offset * offset_cost
        ng_stage.append(rows)

    lbw, ubw = variable_bounds(model, terminal, layout, n, w.numel())
    g_all = ca.vertcat(*g)
    params = ca.vertcat(x_k, w_weights, obs, p_path, u_prev)
    structure = {
        'N': n,
        'nx': [nz + npv] + [nz + nc + npv] * n,
        'nu': [nu] + [nu + nm] * (n - 1) + [nm] if n > 1 else [nu, nm],
        'ng': ng_stage,
    }
    return Formulation(
        problem={'x': w, 'p': params, 'f': cost, 'g': g_all}, structure=structure,
        slots=slots, faces=faces, lbw=lbw, ubw=ubw,
        lbg=np.concatenate(lbg), ubg=np.concatenate(ubg), layout=layout,
        cost_fn=ca.Function('cost', [w, params], [cost]),
        g_fn=ca.Function('g', [w, params], [g_all]),
        robot_faces=robot_faces, sweep_fn=None if sweep is None else sweep.map(n),
        first_order=first_order,
    )


def obstacle_halfplanes(obs: ca.SX, slots: int, faces: int
                        ) -> tuple[list[ca.SX], list[ca.SX], list[ca.SX]]:
    """Return (A_j, b_j, motion_j) of each slot of the obstacle parameter.

    Obstacle j is A_j p <= b_j now; motion_j is its (vx, vy, growth, |v|), zeros for a static one
    (core/moving_obstacles.py). Slot j holds its A column by column (2 faces values), its b
    (faces values), then its motion, as nlp_values.obstacle_parameters packs them.
    """
    A_list, b_list, motion_list = [], [], []
    size = 3 * faces + MOTION_SIZE
    for j in range(slots):
        base = size * j
        A_list.append(ca.reshape(obs[base:base + 2 * faces], faces, 2))
        b_list.append(obs[base + 2 * faces:base + 3 * faces])
        motion_list.append(obs[base + 3 * faces:base + size])
    return A_list, b_list, motion_list


def stage_offsets(A: ca.SX, b: ca.SX, motion: ca.SX, t: float, half_step: float) -> ca.SX:
    """Return the faces' offsets of an obstacle at time t ahead: b + t A v + d(t).

    d(t) = t growth + h/2 (|v| + growth) (core/moving_obstacles.py): the obstacle moved at
    its velocity v, grown with its uncertainty and by where it may be within half a step of
    the sample. A static obstacle's motion is zero, and then this is b to the bit.
    """
    velocity, growth, speed = motion[0:2], motion[2], motion[3]
    pad = t * growth + half_step * (speed + growth)
    return b + t * ca.mtimes(A, velocity) + pad


class Row(NamedTuple):
    """Constraint rows lower <= expr <= upper (every entry of expr, the same bounds)."""

    expr: ca.SX
    lower: float
    upper: float


def gap_closing_rows(z_next: ca.SX, x_next: ca.SX, r_l: ca.SX, carried: list[ca.SX]
                     ) -> list[Row]:
    """(6c): x_{l+1} = f(x_l, u_l), and the reference and carried values copied on.

    z_{l+1} = (f(x_l, u_l), r_l, carried...): one reference along the horizon, and whatever
    a later stage reads of this one (the steady state, a sweep rate, the input).
    """
    return [Row(z_next - ca.vertcat(x_next, r_l, *carried), 0.0, 0.0)]


def rate_rows(k: int, n: int, q_k: ca.SX, u_k: ca.SX | None, u_prev: ca.SX,
              rate: np.ndarray, first_order: bool) -> list[Row]:
    """(6g) for a real base: stage k's input within max_accel h of the one before it.

    q_k is the input before stage k (q_0 = u_prev, fixed here at k = 0); at k = N, where
    u_N = 0, the bound is on q_N itself, and a first-order hold reaches x_N at the velocity
    q_N = u_{N-1}, which must then be 0.
    """
    rows = [Row(q_k - u_prev, 0.0, 0.0)] if k == 0 else []
    change = u_k - q_k if k < n else q_k
    bound = np.zeros(len(rate)) if first_order and k == n else rate
    rows.extend(Row(change[i], -bound[i], bound[i]) for i in range(len(rate)))
    return rows


def initial_state_rows(x_0: ca.SX, x_k: ca.SX) -> list[Row]:
    """(6b): x_0 = x(k), the measured state."""
    return [Row(x_0 - x_k, 0.0, 0.0)]


def disc_collision_rows(p: ca.SX, multipliers: ca.SX, A_list: list[ca.SX],
                        b_list: list[ca.SX], faces: int, margin: float) -> list[Row]:
    """(6h) via Farkas (8) for a disc (obstacles grown by its radius), every slot.

    p is outside {A p <= b} iff some mu >= 0 with sum(mu) = 1 has (A p - b)^T mu > 0
    (without sum(mu) = 1, mu = 0 would do): (A p - b)^T mu >= margin and sum(mu) = 1.
    """
    rows = []
    for j in range(len(A_list)):
        mu = multipliers[j * faces:(j + 1) * faces]
        rows.append(Row(ca.dot(ca.mtimes(A_list[j], p) - b_list[j], mu), margin, ca.inf))
        rows.append(Row(ca.sum1(mu), 1.0, 1.0))
    return rows


def polygon_collision_rows(x_l: ca.SX, angle: int, multipliers: ca.SX,
                           A_list: list[ca.SX], b_list: list[ca.SX], faces: int,
                           G: ca.DM, g_body: ca.DM, margin: float,
                           sweeps: list[ca.SX]) -> list[Row]:
    """(6h) for a polygonal footprint at x_l against every slot.

    Per slot, with w = A^T lambda (the separating direction, from obstacle to robot):
    (A p - b)^T lambda - g^T mu - sweep >= margin for each sweep (the clearance covers the
    motion of both adjacent steps), G^T mu + R(theta)^T w = 0, and |w|^2 <= 1. An empty slot
    (A = 0, b = -1) is satisfied by lambda_0 >= margin + sweep, mu = 0.
    """
    p, theta = x_l[0:2], x_l[angle]
    cos, sin = ca.cos(theta), ca.sin(theta)
    robot_faces = G.shape[0]
    rows = []
    for j in range(len(A_list)):
        base = j * (faces + robot_faces)
        lam = multipliers[base:base + faces]
        mu = multipliers[base + faces:base + faces + robot_faces]
        direction = ca.mtimes(A_list[j].T, lam)  # A^T lambda, in the world frame
        value = ca.dot(p, direction) - ca.dot(b_list[j], lam) - ca.dot(g_body, mu)
        rows.extend(Row(value - sweep, margin, ca.inf) for sweep in sweeps)
        # R(theta)^T A^T lambda: the direction in the robot frame
        local = ca.vertcat(cos * direction[0] + sin * direction[1],
                           -sin * direction[0] + cos * direction[1])
        rows.append(Row(ca.mtimes(G.T, mu) + local, 0.0, 0.0))
        rows.append(Row(ca.sumsqr(direction), -ca.inf, 1.0))
    return rows


def terminal_rows(terminal: TerminalCondition, x_n: ca.SX, x_s: ca.SX, r_n: ca.SX,
                  p_path: ca.SX, weights: CostWeights, *, carried: bool
                  ) -> tuple[list[Row], ca.SX]:
    """(6d)-(6f): the terminal set's rows at stage N, and the offset cost V_o (unweighted).

    A carried steady state is x_s(r) here, where it is evaluated once. Residual entries that
    are identically zero (a free steady state) are dropped: an empty Jacobian row makes the
    KKT system singular and the solver wanders off.
    """
    rows = [Row(x_s - terminal.steady_state(r_n, p_path), 0.0, 0.0)] if carried else []
    residual, offset_cost = terminal.condition(x_n, x_s, r_n, p_path, weights)
    kept = [residual[i] for i in range(residual.numel()) if not residual[i].is_zero()]
    if kept:
        rows.append(Row(ca.vertcat(*kept), 0.0, 0.0))
    return rows, offset_cost


def variable_bounds(model: RobotModel, terminal: TerminalCondition, layout: Layout, n: int,
                    size: int) -> tuple[np.ndarray, np.ndarray]:
    """(6g): (x_l, u_l) in Z; r in its range (s in [0, 1]); multipliers >= 0 (8).

    Everything else (the carried copies) is free: its gap-closing rows fix it.
    """
    lbw, ubw = np.full(size, -np.inf), np.full(size, np.inf)
    for k in range(n + 1):
        lbw[layout.x[k]], ubw[layout.x[k]] = model.x_min, model.x_max
        lbw[layout.r[k]], ubw[layout.r[k]] = terminal.lower, terminal.upper
        if k < n:
            lbw[layout.u[k]], ubw[layout.u[k]] = model.u_min, model.u_max
        if k >= 1:
            lbw[layout.mu[k - 1]], ubw[layout.mu[k - 1]] = 0.0, np.inf
    return lbw, ubw


def _blocks(n: int, nx: int, nr: int, nz: int, nu: int, nm: int, nc: int,
            npv: int) -> list[dict[str, list[tuple[str, int]]]]:
    """Return the order of w, the one place it is written: per stage k, its blocks in order.

    Stage k holds z_k (x_k, the reference copy r_k, the carried steady state, for k >= 1 the
    sweep rate c_k, and the input before the stage), then u_k (k < N), then mu_k (k >= 1),
    each block as (field, size) parts.
    """
    stages = []
    for k in range(n + 1):
        z = [('x', nx), ('r', nr), ('xs', nz - nx - nr)]
        if k >= 1:
            z.append(('c', nc))
        z.append(('prev', npv))
        stage = {'z': z}
        if k < n:
            stage['u'] = [('u', nu)]
        if k >= 1:
            stage['mu'] = [('mu', nm)]
        stages.append(stage)
    return stages


def _layout(blocks: list[dict[str, list[tuple[str, int]]]], n: int, nu: int, nm: int,
            nc: int, npv: int) -> Layout:
    """Return the indices of x, r, the carried x_s, u, mu, sweep rates and inputs in w."""
    fields: dict[str, list[np.ndarray]] = {name: [] for name in
                                           ('x', 'r', 'xs', 'u', 'mu', 'c', 'prev')}
    offset = 0
    for stage in blocks:
        for parts in stage.values():
            for name, size in parts:
                fields[name].append(np.arange(offset, offset + size))
                offset += size
    return Layout(x=np.array(fields['x']), r=np.array(fields['r']),
                  xs=np.array(fields['xs'], dtype=int).reshape(n + 1, -1),
                  u=np.array(fields['u']), mu=np.array(fields['mu']).reshape(n, nm),
                  c=np.array(fields['c'], dtype=int).reshape(n, nc),
                  prev=np.array(fields['prev'], dtype=int).reshape(n + 1, npv))
