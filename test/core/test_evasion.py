# SPDX-License-Identifier: Apache-2.0
"""A robot whose MPC has no plan steps out of a walker's way instead of standing to be hit.

The solver is replaced by one that never succeeds, so every step ends in the MPC's stop (the
proof's candidate, standing still, is refused once the walker is predicted to reach it). Before
core/evasion.py the controller then stood, and the walker ran into it. The Jackal drives the
unicycle, integrated in sub-steps; the walker is a disc moving at a constant velocity, given to
the controller each step as a MovingPolygon where it is then; clearances are exact distances of
the footprint from the walker where it truly is, and from the walls.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import numpy as np

from mpc_local_planner.core.config import BudgetKind, MpcConfig, SolverSettings
from mpc_local_planner.core.control_output import Reason
from mpc_local_planner.core.controller import MpcController
from mpc_local_planner.core.evasion import Evasion, first_conflict
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.moving_obstacles import MovingPolygon
from mpc_local_planner.core.mpc.backends import SolverRun
from mpc_local_planner.core.mpc.candidate import Rollout
from mpc_local_planner.core.mpc.clearance import Clearance
from mpc_local_planner.core.obstacles import ConvexPolygon, ObstacleSet, polygon_separation

WALKER_RADIUS = 0.3
SUBSTEPS = 10
MODEL = Unicycle(v_max=2.0, omega_max=4.0)
CONFIG = MpcConfig(footprint=tuple((float(x), float(y)) for x, y in JACKAL.vertices),
                   solving=SolverSettings(compile=False, max_solve_time=None,
                                          budget=BudgetKind.ITERATIONS))
# a corridor 1.1 m wide along the x axis, from x = -4 to 6: the Jackal (0.43 m wide) cannot
# pass a walker in it
WALLS = [ConvexPolygon.from_box(-4.0, 0.55, 6.0, 1.5),
         ConvexPolygon.from_box(-4.0, -1.5, 6.0, -0.55)]


def no_solution(nlp: object, w0: np.ndarray, params: np.ndarray, solver: object = None, *,
                time_limit: float = math.inf, iteration_limit: float = math.inf) -> SolverRun:
    """A solver that never finds a plan: every step is the MPC's stop (or its candidate)."""
    return SolverRun(w=np.asarray(w0, dtype=float).reshape(-1), value=math.inf, success=False,
                     status='test: no solution', iterations=0, seconds=0.0)


def walker(start: Sequence[float], velocity: Sequence[float], t: float) -> ConvexPolygon:
    """The walker's disc at time t."""
    return ConvexPolygon.from_circle(*(np.asarray(start) + t * np.asarray(velocity)),
                                     WALKER_RADIUS)


class Run(NamedTuple):
    """What a run did: its least clearance from the walker and from the walls, its reasons."""

    walker_clearance: float
    wall_clearance: float
    reasons: list[Reason]
    final: np.ndarray


def gap(x: np.ndarray, obstacles: list[ConvexPolygon]) -> float:
    """Return the exact distance of the footprint at pose x from the nearest obstacle."""
    if not obstacles:
        return math.inf
    return float(np.min(polygon_separation(JACKAL.at_poses(x[None]), ObstacleSet(obstacles))[0]))


def drive(start: Sequence[float], velocity: Sequence[float], *, walls: list[ConvexPolygon],
          seconds: float = 4.0) -> Run:
    """Run the controller whose solver finds nothing, the walker coming, for seconds."""
    controller = MpcController(MODEL, CONFIG, runner=no_solution)
    controller.set_plan(np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]]))
    h = CONFIG.step
    x = np.zeros(3)
    walker_clearance = wall_clearance = math.inf
    reasons = []
    for k in range(int(round(seconds / h))):
        t = k * h
        controller.set_obstacles([*walls, MovingPolygon.moving(walker(start, velocity, t),
                                                               velocity)])
        output = controller.compute(x, None, t)
        reasons.append(output.reason)
        u = np.asarray(output.u, dtype=float)
        for j in range(SUBSTEPS):
            walker_clearance = min(walker_clearance,
                                   gap(x, [walker(start, velocity, t + j * h / SUBSTEPS)]))
            wall_clearance = min(wall_clearance, gap(x, walls))
            x = x + h / SUBSTEPS * np.array([u[0] * np.cos(x[2]), u[0] * np.sin(x[2]), u[1]])
    return Run(walker_clearance, wall_clearance, reasons, x)


def test_a_standing_robot_steps_out_of_the_way_of_a_walker_coming_at_it() -> None:
    """A walker at 1 m/s head-on: standing, the robot is run into at 1.9 s; it moves aside."""
    start, velocity = (2.5, 0.0), (-1.0, 0.0)
    standing = min(gap(np.zeros(3), [walker(start, velocity, t)])
                   for t in np.arange(0.0, 4.0, 0.02))
    assert standing < 0.0  # what the stop did before evasion: the walker runs into it
    run = drive(start, velocity, walls=[])
    assert Reason.EVADE in run.reasons
    assert run.walker_clearance > 0.05


def test_in_a_corridor_the_robot_backs_out_before_the_walker_and_never_touches_a_wall() -> None:
    """In a corridor too narrow to pass, every move that clears the walls goes back."""
    run = drive((2.5, 0.0), (-1.0, 0.0), walls=WALLS)
    assert Reason.EVADE in run.reasons
    assert run.walker_clearance > 0.05
    assert run.wall_clearance > 0.0
    assert run.final[0] < -0.5  # backed out along the corridor


def test_no_move_is_chosen_when_stopping_stays_clear_of_every_walker() -> None:
    """A walker walking away, or none at all: the stop is kept (the static behaviour)."""
    clearance = Clearance(MODEL, CONFIG)
    clearance.clear()
    evasion = Evasion(MODEL, CONFIG, clearance)
    x0 = np.zeros(3)
    standing = np.tile(x0, (CONFIG.horizon + 1, 1))
    away = MovingPolygon.moving(ConvexPolygon.from_circle(1.5, 0.0, WALKER_RADIUS), (1.0, 0.0))
    toward = np.array([4.0, 0.0])
    assert evasion.choose(x0, standing, ObstacleSet([away, *WALLS]), toward) is None
    assert evasion.choose(x0, standing, ObstacleSet(WALLS), toward) is None
    coming = MovingPolygon.moving(ConvexPolygon.from_circle(1.5, 0.0, WALKER_RADIUS),
                                  (-1.0, 0.0))
    move = evasion.choose(x0, standing, ObstacleSet([coming, *WALLS]), toward)
    assert move is not None and move.conflict > CONFIG.horizon >= move.stop_conflict
    margins = clearance.margins(move.x, move.u, ObstacleSet([coming]))
    assert first_conflict(margins) == move.conflict and np.all(margins >= 0.0)
    assert clearance.penetration(move.x, move.u, ObstacleSet(WALLS)) == 0.0


def test_the_margins_of_many_plans_at_once_are_those_of_each_plan() -> None:
    """The evasion's batched check finds each move short where, and by as much as, the MPC's.

    Where a pose clears an obstacle both give a margin >= 0 (a cheap bound may stand for the
    exact distance there, in either); where it falls short both give the exact shortfall.
    """
    clearance = Clearance(MODEL, CONFIG)
    clearance.clear()
    rng = np.random.default_rng(3)
    coming = MovingPolygon.moving(ConvexPolygon.from_circle(1.2, 0.2, WALKER_RADIUS),
                                  (-1.0, 0.3), 0.2)
    obstacles = ObstacleSet([coming, *WALLS])
    inputs = rng.uniform(MODEL.u_min, MODEL.u_max, size=(12, CONFIG.horizon, 2))
    rollout = Rollout(MODEL)
    states = np.array([rollout(np.zeros(3), u, CONFIG.step) for u in inputs])
    many = clearance.margins_of_many(states, inputs, obstacles)
    each = np.array([clearance.margins(x, u, obstacles)
                     for x, u in zip(states, inputs, strict=True)])
    assert np.any(each < 0.0) and np.any(each > 0.0)  # plans that meet them, plans that do not
    np.testing.assert_array_equal(many < 0.0, each < 0.0)
    np.testing.assert_allclose(np.minimum(many, 0.0), np.minimum(each, 0.0), rtol=0,
                               atol=1e-12)


def test_a_forward_only_robot_facing_a_walker_pivots_into_a_side_passage() -> None:
    """Head-on in a corridor with a side passage beside it: no arc clears the walker, a pivot does.

    A forward-only robot cannot back away, and a constant input gives it arcs only, which
    the corridor's walls cut short: it must turn in place first, then drive off.
    """
    model = Unicycle(v_max=2.0, omega_max=4.0, v_min=0.0)
    clearance = Clearance(model, CONFIG)
    clearance.clear()
    evasion = Evasion(model, CONFIG, clearance)
    # the corridor of WALLS, with the upper wall open over -0.5 < x < 0.5 into a passage
    walls = [WALLS[1], ConvexPolygon.from_box(-4.0, 0.55, -0.5, 1.5),
             ConvexPolygon.from_box(0.5, 0.55, 6.0, 1.5),
             ConvexPolygon.from_box(-1.5, 1.5, -0.5, 4.0),
             ConvexPolygon.from_box(0.5, 1.5, 1.5, 4.0)]
    coming = MovingPolygon.moving(ConvexPolygon.from_circle(2.0, 0.0, WALKER_RADIUS),
                                  (-1.0, 0.0))
    x0 = np.zeros(3)
    standing = np.tile(x0, (CONFIG.horizon + 1, 1))

    move = evasion.choose(x0, standing, ObstacleSet([coming, *walls]), np.array([4.0, 0.0]))

    assert move is not None and move.conflict > CONFIG.horizon >= move.stop_conflict
    assert move.u[0, 0] == 0.0 and move.u[0, 1] > 0.0  # it turns in place, to the left
    assert move.x[-1, 1] > 0.55  # and ends in the passage
    assert clearance.penetration(move.x, move.u, ObstacleSet(walls)) == 0.0
    # no arc keeps clear of the walker without touching a wall
    rollout = Rollout(model)
    for target in evasion._targets():
        u = evasion._inputs(np.zeros(2), np.tile(target, (CONFIG.horizon, 1)))
        x = rollout(x0, u, CONFIG.step)
        assert (clearance.penetration(x, u, ObstacleSet(walls)) > 0.0
                or first_conflict(clearance.margins(x, u, ObstacleSet([coming])))
                <= CONFIG.horizon)


def test_with_a_first_order_hold_each_evasive_step_goes_on_from_the_speed_reached() -> None:
    """A walker catching up from behind: the robot drives off and keeps its speed.

    Commanded at 20 Hz, each step's move ramps from the velocity the last one's ramp had
    reached. It began at the last ramp's start instead (the input commanded when that step
    was solved): the robot fell back to rest at every step and the walker caught up
    (through the nodes, dynamic world 24).
    """
    config = CONFIG.with_changes(max_accel=(20.0, 60.0), input_hold='first_order')
    controller = MpcController(MODEL, config, runner=no_solution)
    controller.set_plan(np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]]))
    start, velocity = (-1.6, 0.0), (1.2, 0.0)
    period = 0.05
    x = np.zeros(3)
    speeds, reasons, clearance = [], [], math.inf
    for k in range(int(round(3.0 / period))):
        t = k * period
        controller.set_obstacles([MovingPolygon.moving(walker(start, velocity, t), velocity)])
        output = controller.compute(x, None, t)
        u = np.asarray(output.u, dtype=float)
        speeds.append(float(u[0]))
        reasons.append(output.reason)
        for j in range(SUBSTEPS):
            clearance = min(clearance,
                            gap(x, [walker(start, velocity, t + j * period / SUBSTEPS)]))
            x = x + period / SUBSTEPS * np.array([u[0] * np.cos(x[2]), u[0] * np.sin(x[2]),
                                                   u[1]])
    evading = [k for k, reason in enumerate(reasons) if reason is Reason.EVADE]
    assert evading, 'the walker never made the robot move'
    first = evading[0]
    last = next((k for k in range(first, len(reasons)) if reasons[k] is not Reason.EVADE),
                len(reasons))
    assert last - first > 8  # several evasive steps in a row (4 ticks each)
    # after the first evasive step, the robot never falls back towards rest while it evades
    assert min(speeds[first + 4:last]) > 0.5 * max(speeds[first:first + 4])
    assert clearance > 0.0
