# SPDX-License-Identifier: Apache-2.0
"""MPC settings as frozen dataclasses, each with a validator shared by code and ROS parameters.

MpcConfig is the problem (horizon, step, cost, robot shape, margins, input rates) and holds a
SolverSettings, how it is solved (which obstacles the NLPs hold, the backend, its limits, the
step's budget), as acados keeps ocp.model, ocp.cost and ocp.constraints apart from
ocp.solver_options. The node's on-set-parameters callback and the library both construct
them, so a value refused at run time is refused for the same reason (validate_mpc_config,
validate_solver_settings) as in a script.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from enum import StrEnum
from functools import cached_property
import math
from typing import Any, NamedTuple, Sequence

from mpc_local_planner.core.footprint import Footprint, parse_footprint

__all__ = ['BUDGETS', 'BudgetKind', 'CostWeights', 'INPUT_HOLDS', 'InputHold', 'MpcConfig',
           'NlpSolver', 'OBSTACLE_SOURCES', 'ObstacleSource', 'SOLVERS', 'STRUCTURAL_FIELDS',
           'STRUCTURAL_SOLVER_FIELDS', 'SolverSettings', 'validate_mpc_config',
           'validate_solver_settings']


class _Choice(StrEnum):
    """A closed choice written as its string (YAML, CLI, ROS parameters): it is that string.

    str() and format() give the value, == compares with it, and the hash is the string's, so
    a member and the string a user wrote are the same key of a dict or set.
    """

    __hash__ = str.__hash__

    @classmethod
    def parse(cls, value: object) -> object:
        """Return the member value names, or value as it is (refused by the validation)."""
        if isinstance(value, str) and value in cls._value2member_map_:
            return cls(value)
        return value


class NlpSolver(_Choice):
    """The NLP backend (SolverSettings.solver).

    fatrop (structure-exploiting interior point) is the fastest that gives IPOPT's closed
    loop; IPOPT is the reference. SQP is not offered: from rest, where every derivative of
    the quartic cost vanishes, it stops or stalls (see docs/design/mpc.md, section SOLVERS).
    """

    FATROP = 'fatrop'
    IPOPT = 'ipopt'


class BudgetKind(_Choice):
    """What bounds a control step's solving (SolverSettings.budget).

    Wall time, the robot's, or solver iterations, the same on any machine and under any load
    (the evaluation's).
    """

    WALL = 'wall'
    ITERATIONS = 'iterations'


class InputHold(_Choice):
    """How an input acts over a step (MpcConfig.input_hold).

    Held constant (the paper's), or a linear ramp from the input before it (a velocity a
    rate-limited base can follow).
    """

    ZERO = 'zero'
    FIRST_ORDER = 'first_order'


class ObstacleSource(_Choice):
    """Where the controller's obstacles come from (the node's obstacle_sources)."""

    WORLD = 'world'  # the world file's obstacles
    SCAN = 'scan'  # the laser's, with a memory
    MAP = 'map'  # the occupancy grid's, as rectangles


# The values a user writes, in the members' order (CLI choices, messages).
SOLVERS = tuple(member.value for member in NlpSolver)
BUDGETS = tuple(member.value for member in BudgetKind)
INPUT_HOLDS = tuple(member.value for member in InputHold)
OBSTACLE_SOURCES = tuple(member.value for member in ObstacleSource)
# Seconds one solver iteration typically takes, to turn the wall budget into an iteration
# allowance (MpcConfig.solve_iterations()): the typical time of an iteration in the steps the
# wall budget binds (large NLPs), so the default 0.1 s is 100 iterations (see
# docs/design/mpc.md, section ITERATION_SECONDS).
ITERATION_SECONDS = 1e-3


class CostWeights(NamedTuple):
    """Weights of the stage cost l and of the offset cost V_o, in the solver's order.

    The stage cost is l(x - x_s, u - u_s) = position ((dx)^p + (dy)^p) + heading (dtheta)^p
    + v (v - v_s)^p + omega (omega - omega_s)^p; the offset cost is offset V_o(1 - s). The
    formulation holds the same record with CasADi symbols: the solver's weight parameter.

    Attributes:
        position: weight of (dx)^p and (dy)^p.
        heading: weight of (dtheta)^p (and of further states of richer models).
        v: weight of the speed term.
        omega: weight of the turn-rate term (and of further inputs).
        offset: weight of the offset cost.

    """

    position: float
    heading: float
    v: float
    omega: float
    offset: float

    def as_vector(self) -> list[float]:
        """Return the weights in the order of the solver's weight parameter."""
        return list(self)


@dataclass(frozen=True)
class SolverSettings:
    """How the MPC's problem is solved: the NLPs' shape, the backend, its limits, the budget.

    The obstacle slots, the faces per slot and the activation distance are here, not in
    MpcConfig: they shape the NLPs and choose which obstacles one holds, while the problem
    (clear of every obstacle in reach, each solution checked against all of them) stays the
    same.

    Attributes:
        obstacle_slots: the obstacle counts prepare() builds NLPs for in advance (one NLP
            per count of obstacles near the trajectory and face count), and the most a step
            holds once prepared (the nearest; its solution is checked against all obstacles
            in reach).
        faces_per_obstacle: half-planes per obstacle slot (larger polygons are refused).
        activation_distance: obstacles within this distance of the candidate trajectory get
            Farkas multipliers in the NLP; the others within reach are checked and added
            when a solution comes within half of it (None: v_max h / 2). For a polygon, the
            distance is what its exact clearance exceeds the clearance the motion needs by.
        solver: NLP backend, one of SOLVERS.
        fatrop_stage_limit: with solver 'fatrop', an NLP shape whose stages have more
            variables than this is solved by IPOPT instead. fatrop's Riccati recursion costs
            about the cube of a stage's size, IPOPT's sparse factorisation about its size, so
            beyond some stage size IPOPT is the faster (see docs/design/mpc.md, section
            fatrop_stage_limit). Each obstacle adds its faces plus the robot's as
            multipliers (a box beside the Jackal: 8).
        max_iterations: solver iteration limit per solve.
        tolerance: solver and verification tolerance.
        compile: compile the NLP's functions to C with the system compiler ($CC or gcc), in
            the background, cached on disk (see mpc.compile_cache_dir); until it is done, or
            if it fails (a logged warning), the interpreted functions are used.
        max_solve_time: wall-time budget of one control step's solving, in seconds, from the
            start of the MPC's solve(); None means step / 2 (see MpcConfig.solve_budget()).
            The first NLP solve gets what is left of it (an NLP built mid-step has used its
            share); the retries (other starts, the IPOPT fallback, further
            constraint-generation rounds) run only while some is left; once it is spent the
            verified shifted candidate is applied (or the robot stops), and the step counts
            as timed out (MpcSolution.timed_out). Not structural: the solvers get the time
            left at each call, nothing is rebuilt. Used with budget 'wall' only.
        budget: what bounds a step's solving, one of BUDGETS. 'wall' (the default, the
            robot's): seconds of wall time, max_solve_time; what a step achieves then depends
            on the machine and its load. 'iterations': solver iterations,
            MpcConfig.solve_iterations(); every try spends the iterations it made, and
            nothing in a step reads a clock, so the same inputs give the same outputs on any
            machine under any load (the evaluation's: runs are reproducible). CPU time would
            not do: it too grows under contention (caches, memory bandwidth). A step then
            waits for the background compilation of an NLP it needs (the compiled and the
            interpreted functions may round differently), and builds of the IPOPTs mid-step
            are free. Not structural.
        max_solve_iterations: with budget 'iterations', the solver iterations of one
            control step (every try and round together); None means the wall budget's
            worth on a typical machine (see MpcConfig.solve_iterations()).
        solver_options: extra options passed to casadi.nlpsol (override the defaults).

    """

    obstacle_slots: int = 4
    faces_per_obstacle: int = 8
    activation_distance: float | None = None
    solver: NlpSolver = NlpSolver.FATROP
    fatrop_stage_limit: int = 50
    max_iterations: int = 200
    tolerance: float = 1e-8
    compile: bool = True
    max_solve_time: float | None = None
    budget: BudgetKind = BudgetKind.WALL
    max_solve_iterations: int | None = None
    solver_options: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)

    def __post_init__(self) -> None:
        # frozen: the strings of YAML, the CLI or a ROS parameter become their members
        object.__setattr__(self, 'solver', NlpSolver.parse(self.solver))
        object.__setattr__(self, 'budget', BudgetKind.parse(self.budget))
        problems = validate_solver_settings(self)
        if problems:
            msg = 'invalid MPC solver settings: ' + '; '.join(problems)
            raise ValueError(msg)

    def structure_key(self) -> tuple[tuple[str, Any], ...]:
        """Return the values of STRUCTURAL_SOLVER_FIELDS by name, sorted and hashable.

        The solver options (a dict) enter sorted, by repr.
        """
        return tuple((name, tuple(sorted((k, repr(v)) for k, v in self.solver_options.items()))
                      if name == 'solver_options' else getattr(self, name))
                     for name in sorted(STRUCTURAL_SOLVER_FIELDS))

    def with_changes(self, **changes: Any) -> SolverSettings:
        """Return a copy with some fields changed (validated again)."""
        return replace(self, **changes)


@dataclass(frozen=True)
class MpcConfig:
    """Settings of the MPC: its problem (the paper's Section IV values by default) and solving.

    Attributes:
        horizon: prediction steps N.
        step: sampling time h in seconds.
        weight_position: stage-cost weight of (dx)^p and (dy)^p.
        weight_heading: stage-cost weight of (dtheta)^p.
        weight_v: stage-cost weight of v^p.
        weight_omega: stage-cost weight of omega^p.
        offset_weight: V_o(1 - s) = offset_weight (1 - s)^2.
        cost_exponent: p, 4 in the paper: with 2 the unicycle violates Assumption 3.
        robot_radius: obstacles are inflated by it (a circular footprint; ignored when
            footprint is a polygon).
        footprint: the robot's convex polygon in the robot frame (x forward), as ((x, y), ...)
            in either orientation; empty: a circle of robot_radius. With a polygon, the NLP
            separates the polygon from each obstacle exactly (the dual condition of Zhang,
            Liniger and Borrelli) with a clearance that follows the motion, instead of
            inflating the obstacles. Stored as a tuple so that the settings stay hashable and
            comparable with != (lists are converted); see robot_footprint.
        collision_margin: extra inflation so that the continuous motion between two samples
            stays clear; None means v_max h / 2 (half the longest step) for a circle, and
            none for a polygon (its NLP asks for a clearance that follows the motion).
        farkas_margin: the Farkas constraint asks (A p - b)^T mu >= this (metres); a polygon's
            dual bound asks for this plus the motion's h/2 (|v| + r_c |omega|).
        max_accel: None (inputs may jump, the paper's model), or the largest change of v
            (m/s^2) and omega (rad/s^2) per second: a real base cannot follow a jump. The
            NLP then bounds |u_0 - u_prev| and |u_{l+1} - u_l| by max_accel h, and
            |u_{N-1}| too (u_N = 0), with u_prev the input commanded over the step before
            (or the measured twist after a stop): see formulation.formulate.
        input_hold: how an input acts over a step, one of INPUT_HOLDS. 'zero' (the paper's):
            u_l is held constant over step l, so the velocity jumps at each sample. 'first_order'
            (requires max_accel): the velocity ramps linearly over step l from the knot before,
            q_l (q_0 = u_prev, the velocity the last plan gives for now), to u_l; the rate rows
            |u_l - q_l| <= max_accel h then bound the acceleration of a piecewise-linear
            velocity, which a rate-limited, lagging base can follow, and the plan ends at
            rest with u_{N-1} = 0 (x_N is reached at the velocity u_{N-1}). See
            docs/design/mpc.md, section "First-order hold".
        solving: how the problem is solved (SolverSettings: the NLPs' obstacle slots and
            faces, the backend and its limits, the step's budget).

    """

    horizon: int = 10
    step: float = 0.2
    weight_position: float = 1.0
    weight_heading: float = 0.1
    weight_v: float = 1.0
    weight_omega: float = 1.0
    offset_weight: float = 1000.0
    cost_exponent: int = 4
    robot_radius: float = 0.0
    footprint: tuple[tuple[float, float], ...] = ()
    collision_margin: float | None = None
    farkas_margin: float = 1e-4
    max_accel: tuple[float, float] | None = None
    input_hold: InputHold = InputHold.ZERO
    solving: SolverSettings = field(default_factory=SolverSettings)

    def __post_init__(self) -> None:
        # frozen: normalise with object.__setattr__, so that a list (from YAML, a ROS
        # parameter) or an array still gives a hashable, comparable tuple of floats
        object.__setattr__(self, 'footprint', _as_vertex_tuple(self.footprint))
        object.__setattr__(self, 'input_hold', InputHold.parse(self.input_hold))
        if self.max_accel is not None:
            try:
                object.__setattr__(self, 'max_accel', tuple(float(a) for a in self.max_accel))
            except (TypeError, ValueError):
                pass  # refused with a reason below
        problems = validate_mpc_config(self)
        if problems:
            msg = 'invalid MPC configuration: ' + '; '.join(problems)
            raise ValueError(msg)

    @cached_property
    def robot_footprint(self) -> Footprint:
        """The robot's shape: Footprint.polygon(footprint), or a circle of robot_radius."""
        return parse_footprint(self.footprint, self.robot_radius)

    def inflation(self, v_max: float) -> float:
        """Return the distance obstacles are grown by.

        A circle: robot radius plus collision margin (v_max h / 2 by default, the longest
        half step). A polygon: collision_margin only (0 by default), because its NLP asks for
        a clearance that follows the motion instead (see formulation.formulate).
        """
        if self.footprint:
            return 0.0 if self.collision_margin is None else self.collision_margin
        margin = v_max * self.step / 2 if self.collision_margin is None else self.collision_margin
        return self.robot_radius + margin

    def activation_distance(self, v_max: float) -> float:
        """Return how near a plan an obstacle must come to be held in the NLP (metres).

        solving.activation_distance, or half a step, v_max h / 2: few re-solves with few
        obstacles in the NLP, where a wider band holds many more and builds many more NLP
        shapes (see docs/design/mpc.md, section "Default activation distance").
        """
        given = self.solving.activation_distance
        return 0.5 * v_max * self.step if given is None else float(given)

    def reach(self, v_max: float) -> float:
        """Return how far from the robot's origin an obstacle (as described) can matter.

        The origin moves at most v_max h N within the horizon; obstacles are grown by
        inflation(); a polygon's points are up to its circumscribed radius r_c from the
        origin (inflation() no longer covers the body then).
        """
        body = self.robot_footprint.radius if self.footprint else 0.0
        return v_max * self.step * self.horizon + self.inflation(v_max) + body

    def solve_budget(self) -> float:
        """Return the seconds one control step may spend solving: solving.max_solve_time, or h / 2.

        Half the period by default, so that a step that uses all of it still leaves the other
        half for verification, sensing and publishing before the next one is due.
        """
        limit = self.solving.max_solve_time
        return self.step / 2 if limit is None else float(limit)

    def solve_iterations(self) -> int:
        """Return the solver iterations one control step may make (budget 'iterations').

        solving.max_solve_iterations, or solve_budget() at ITERATION_SECONDS an iteration:
        what the wall budget allows on a typical machine (0.1 s: 100 iterations).
        """
        if self.solving.max_solve_iterations is not None:
            return int(self.solving.max_solve_iterations)
        return max(1, round(self.solve_budget() / ITERATION_SECONDS))

    @property
    def first_order_hold(self) -> bool:
        """The inputs are first-order-hold knots (input_hold 'first_order', with max_accel)."""
        return self.input_hold is InputHold.FIRST_ORDER and self.max_accel is not None

    def cost_weights(self) -> CostWeights:
        """Return the cost weights by name (the solver reads them as a parameter)."""
        return CostWeights(position=self.weight_position, heading=self.weight_heading,
                           v=self.weight_v, omega=self.weight_omega,
                           offset=self.offset_weight)

    def structure_key(self) -> tuple[tuple[str, Any], ...]:
        """Return the key the built NLPs depend on, hashable.

        The values of STRUCTURAL_FIELDS and of the solving's STRUCTURAL_SOLVER_FIELDS, by
        name, in one sorted tuple. Two settings with the same key share their NLPs; a change
        of key rebuilds them.
        """
        own = tuple((name, getattr(self, name)) for name in STRUCTURAL_FIELDS)
        return tuple(sorted(own + self.solving.structure_key(), key=lambda item: item[0]))

    def with_changes(self, **changes: Any) -> MpcConfig:
        """Return a copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def with_solving(self, **changes: Any) -> MpcConfig:
        """Return a copy whose solving has some fields changed (validated again)."""
        return replace(self, solving=self.solving.with_changes(**changes))


# Fields of MpcConfig (STRUCTURAL_FIELDS) and of SolverSettings (STRUCTURAL_SOLVER_FIELDS)
# whose change alters the NLP's shape: changing them rebuilds the solver.
STRUCTURAL_FIELDS = frozenset(
    {'horizon', 'step', 'cost_exponent', 'farkas_margin', 'footprint', 'max_accel', 'input_hold'}
)
STRUCTURAL_SOLVER_FIELDS = frozenset(
    {'obstacle_slots', 'faces_per_obstacle', 'solver', 'max_iterations', 'tolerance',
     'solver_options', 'compile', 'fatrop_stage_limit'}
)


def _as_vertex_tuple(value: Any) -> Any:
    """Return footprint vertices as a tuple of (float, float); anything else unchanged.

    Nav2's string form "[[x, y], ...]" is read too. What cannot be read as pairs of numbers
    is left as it is, for validate_mpc_config to refuse with a reason.
    """
    if value is None:
        return ()
    try:
        if isinstance(value, str):
            shape = parse_footprint(value)
            return () if shape.is_circle else tuple(
                (float(x), float(y)) for x, y in shape.vertices)
        pairs: Sequence[Any] = list(value)
        return tuple((float(x), float(y)) for x, y in pairs)
    except (TypeError, ValueError):
        return value


def _non_finite(settings: MpcConfig | SolverSettings) -> list[str]:
    """Return a reason for each float field of settings that is not finite."""
    problems: list[str] = []
    for f in fields(settings):
        value = getattr(settings, f.name)
        if isinstance(value, float) and not math.isfinite(value):
            problems.append(f'{f.name} must be finite, got {value}')
    return problems


def validate_mpc_config(config: MpcConfig) -> list[str]:
    """Return the reasons config is invalid (empty when it is valid).

    Its solving is validated when it is constructed (validate_solver_settings).
    """
    problems = _non_finite(config)
    if not (isinstance(config.horizon, int) and config.horizon >= 1):
        problems.append(f'horizon must be an integer >= 1, got {config.horizon!r}')
    if not config.step > 0:
        problems.append(f'step must be > 0, got {config.step}')
    for name in ('weight_position', 'weight_heading', 'weight_v', 'weight_omega'):
        if not getattr(config, name) >= 0:
            problems.append(f'{name} must be >= 0, got {getattr(config, name)}')
    if not config.offset_weight > 0:
        problems.append(f'offset_weight must be > 0, got {config.offset_weight}')
    if config.cost_exponent not in (2, 4):
        problems.append(f'cost_exponent must be 2 or 4, got {config.cost_exponent}')
    if not config.robot_radius >= 0:
        problems.append(f'robot_radius must be >= 0, got {config.robot_radius}')
    if not isinstance(config.footprint, tuple):  # what _as_vertex_tuple could not read
        problems.append(f'footprint must be a sequence of (x, y) vertices, got '
                        f'{config.footprint!r}')
    elif config.footprint:
        try:
            Footprint.polygon(config.footprint)
        except ValueError as err:
            problems.append(f'footprint {config.footprint!r} is invalid: {err}')
    if config.collision_margin is not None and not config.collision_margin >= 0:
        problems.append(f'collision_margin must be >= 0, got {config.collision_margin}')
    if not config.farkas_margin > 0:
        problems.append(f'farkas_margin must be > 0, got {config.farkas_margin}')
    accel = config.max_accel
    if accel is not None and not (isinstance(accel, tuple) and len(accel) == 2 and all(
            isinstance(a, float) and math.isfinite(a) and a > 0 for a in accel)):
        problems.append(f'max_accel must be None or two finite numbers > 0 (m/s^2, '
                        f'rad/s^2), got {accel!r}')
    if config.input_hold not in INPUT_HOLDS:
        problems.append(f'input_hold must be one of {INPUT_HOLDS}, got {config.input_hold!r}')
    elif config.input_hold is InputHold.FIRST_ORDER and accel is None:
        problems.append("input_hold 'first_order' needs max_accel (the ramps' rate bounds)")
    if not isinstance(config.solving, SolverSettings):
        problems.append(f'solving must be a SolverSettings, got {config.solving!r}')
    return problems


def validate_solver_settings(settings: SolverSettings) -> list[str]:
    """Return the reasons settings are invalid (empty when they are valid)."""
    problems = _non_finite(settings)
    if not settings.fatrop_stage_limit >= 1:
        problems.append(f'fatrop_stage_limit must be >= 1, got {settings.fatrop_stage_limit}')
    if not settings.obstacle_slots >= 0:
        problems.append(f'obstacle_slots must be >= 0, got {settings.obstacle_slots}')
    if settings.activation_distance is not None and not settings.activation_distance >= 0:
        problems.append(f'activation_distance must be >= 0, got {settings.activation_distance}')
    if not settings.faces_per_obstacle >= 3:
        problems.append(f'faces_per_obstacle must be >= 3, got {settings.faces_per_obstacle}')
    if settings.solver not in SOLVERS:
        problems.append(f'solver must be one of {SOLVERS}, got {settings.solver!r}')
    if not settings.max_iterations >= 1:
        problems.append(f'max_iterations must be >= 1, got {settings.max_iterations}')
    if not settings.tolerance > 0:
        problems.append(f'tolerance must be > 0, got {settings.tolerance}')
    budget = settings.max_solve_time
    # a non-finite float is already refused above, for every field alike
    if budget is not None and (isinstance(budget, bool) or not isinstance(budget, (int, float))
                               or (math.isfinite(budget) and not budget > 0)):
        problems.append(f'max_solve_time must be None or a number > 0 (seconds), '
                        f'got {budget!r}')
    if settings.budget not in BUDGETS:
        problems.append(f'budget must be one of {BUDGETS}, got {settings.budget!r}')
    iterations = settings.max_solve_iterations
    if iterations is not None and (isinstance(iterations, bool)
                                   or not isinstance(iterations, int) or iterations < 1):
        problems.append(f'max_solve_iterations must be None or an integer >= 1, '
                        f'got {iterations!r}')
    return problems
