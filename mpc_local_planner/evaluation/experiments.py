# SPDX-License-Identifier: Apache-2.0
"""The paper's three experiments as closed loops without ROS, with metrics and figures.

``python -m mpc_local_planner.evaluation.experiments {obstacle,horizon,rrt,all} --out DIR``

- obstacle: Fig. 1 of the paper: the path-reference MPC passes the box and reaches the
  target; the tracking MPC (Limon et al. 2018) stops in front of it.
- horizon: Fig. 2: straight, 90 degree turn, straight; N in {5, 10, 20} x h in {0.1, 0.2,
  0.4}: a longer horizon N h cuts the corner more.
- rrt: Fig. 3: an RRT* path after 1000 iterations, corners and all, followed by the MPC on a
  shorter route, with no smoothing.

Each run is an evaluation.rollout (stopping within STOP_POSITION_TOLERANCE and
STOP_HEADING_TOLERANCE of the target, headings wrapped) and writes metrics.json (with the
rollout's outcome) and trajectory.csv (evaluation/trajectory.py) in its own folder; each
experiment draws a PNG with all its runs. A step's solving is bounded by solver iterations
(``--budget iterations``, the default, as evaluate's), so the runs are the same on any machine
under any load; ``--budget wall`` gives the robot's wall-time budget.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import json
from pathlib import Path
import sys
from typing import Any, Sequence

import numpy as np

from mpc_local_planner.core.baselines.tracking_mpc import TrackingMPC
from mpc_local_planner.core.config import BUDGETS, MpcConfig, SolverSettings
from mpc_local_planner.core.models import RobotModel, Unicycle
from mpc_local_planner.core.mpc import PathReferenceMPC
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import analytic_path, WaypointPath
from mpc_local_planner.core.planner import RrtStarPlanner
from mpc_local_planner.core.planner_config import PlannerConfig
from mpc_local_planner.evaluation.metrics import compute_metrics
from mpc_local_planner.evaluation.plotting import plot_runs
from mpc_local_planner.evaluation.rollout import (
    EVALUATION_BUDGET,
    Outcome,
    polygon_clearance,
    rollout,
    StopRule,
)
from mpc_local_planner.evaluation.trajectory import write_trajectory_csv
from mpc_local_planner.worlds.world import load_world, World

__all__ = ['ClosedLoopResult', 'main', 'run_closed_loop', 'save_run']

CONFIG_DIR = Path(__file__).resolve().parents[2] / 'config'
WORLDS_DIR = CONFIG_DIR / 'worlds'
# Stop a run once the robot is this close: tighter than the metrics' 0.05 m / 0.1 rad, so
# the figures show convergence, not just arrival.
STOP_POSITION_TOLERANCE = 0.01
STOP_HEADING_TOLERANCE = 0.05
PREDICTIONS_SHOWN = 6
# RRT* extension length of the rrt experiment: short steps, as a planner that must answer
# fast would use, leave the corners of the paper's Fig. 3 after 1000 iterations.
RRT_RANGE = 0.3
# The horizon figure's enlarged panel: the corner, where the nine runs part.
HORIZON_ZOOM = (1.3, 2.15, -0.1, 0.75)


@dataclass
class ClosedLoopResult:
    """What a closed-loop run produced: the rollout, a few predictions and the metrics."""

    label: str
    rows: np.ndarray
    predictions: list[np.ndarray]
    lyapunov_ok: list[bool | None]
    solver_failures: int
    outcome: Outcome
    metrics: dict[str, Any] = field(default_factory=dict)


def run_closed_loop(
    controller: Any,
    model: RobotModel,
    start: np.ndarray,
    *,
    goal: np.ndarray,
    obstacles: Sequence[ConvexPolygon],
    label: str,
    max_time: float = 60.0,
    robot_radius: float = 0.0,
    reference_length: float | None = None,
) -> ClosedLoopResult:
    """Run an MPC and the model in closed loop (evaluation.rollout) and compute the metrics.

    The run ends at the goal (within the STOP_* tolerances, headings wrapped), at contact,
    after max_time, or when the robot has stood still for STALL_STEPS steps away from the
    goal (the baseline's local minimum).
    """
    h = controller.config.step
    rule = StopRule(time_limit=max_time, position_tolerance=STOP_POSITION_TOLERANCE,
                    heading_tolerance=STOP_HEADING_TOLERANCE)
    run = rollout(controller, model, start, goal, h=h, rule=rule,
                  clearance=polygon_clearance(obstacles, robot_radius))
    stride = max(1, rule.steps(h) // 40)
    predictions = [step.prediction[:, :3].copy() for k, step in enumerate(run.steps)
                   if k % stride == 0 and step.prediction is not None]
    shown = predictions[:: max(1, len(predictions) // PREDICTIONS_SHOWN)][:PREDICTIONS_SHOWN]
    result = ClosedLoopResult(label=label, rows=run.rows, predictions=shown,
                              lyapunov_ok=run.lyapunov_ok, solver_failures=run.solver_failures,
                              outcome=run.outcome)
    result.metrics = compute_metrics(
        run.rows, goal=goal, obstacles=obstacles, robot_radius=robot_radius,
        reference_length=reference_length, solver_failures=run.solver_failures,
        lyapunov_ok=run.lyapunov_ok,
        lyapunov_cases=[getattr(step.solution, 'lyapunov_case', None) for step in run.steps])
    result.metrics['label'] = label
    result.metrics['outcome'] = run.outcome.value
    result.metrics['horizon'] = controller.config.horizon
    result.metrics['step'] = h
    result.metrics['solver'] = controller.config.solving.solver
    return result


def save_run(result: ClosedLoopResult, folder: Path) -> None:
    """Write metrics.json and trajectory.csv of one run."""
    folder.mkdir(parents=True, exist_ok=True)
    write_trajectory_csv(folder / 'trajectory.csv', result.rows)
    (folder / 'metrics.json').write_text(json.dumps(result.metrics, indent=2) + '\n')


def _mpc_config(world: World, base: MpcConfig, **changes: Any) -> MpcConfig:
    return base.with_changes(robot_radius=world.robot_radius, **changes)


def obstacle_experiment(out: Path, base: MpcConfig) -> list[ClosedLoopResult]:
    """Fig. 1: the proposed MPC and the tracking baseline on the paper's box."""
    world = load_world(WORLDS_DIR / 'paper_obstacle.yaml')
    path = analytic_path(world.path or 'paper_sinusoid')
    model = Unicycle()
    config = _mpc_config(world, base)
    proposed = PathReferenceMPC(model, config, obstacles=world.obstacles, path=path)
    baseline = TrackingMPC(model, config, obstacles=world.obstacles, target=world.goal)
    results = []
    for name, controller in (('proposed', proposed), ('tracking_baseline', baseline)):
        result = run_closed_loop(controller, model, world.start, goal=world.goal,
                                 obstacles=world.obstacles, label=name, max_time=60.0,
                                 robot_radius=world.robot_radius,
                                 reference_length=path.length())
        result.metrics['max_x'] = float(np.max(result.rows[:, 1]))
        save_run(result, out / name)
        results.append(result)
    _, reference = path.sample(400)
    plot_runs(out / 'obstacle.png', world=world, reference=reference,
              runs=[('path-reference MPC (proposed)', results[0].rows),
                    ('tracking MPC (Limon et al. 2018)', results[1].rows)],
              predictions=results[0].predictions,
              title=f'Obstacle avoidance: N = {config.horizon}, h = {config.step:.1f} s')
    return results


def horizon_experiment(out: Path, base: MpcConfig,
                       horizons: Sequence[int] = (5, 10, 20),
                       steps: Sequence[float] = (0.1, 0.2, 0.4)) -> list[ClosedLoopResult]:
    """Fig. 2: closed-loop path length against the horizon N h."""
    world = load_world(WORLDS_DIR / 'corridor_turn.yaml')
    path = WaypointPath(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]]),
                        start_heading=float(world.start[2]), goal_heading=float(world.goal[2]))
    model = Unicycle()
    results = []
    for n in horizons:
        for h in steps:
            controller = PathReferenceMPC(model, _mpc_config(world, base, horizon=n, step=h),
                                          obstacles=world.obstacles, path=path)
            result = run_closed_loop(controller, model, world.start, goal=world.goal,
                                     obstacles=world.obstacles, label=f'N={n}, h={h:g}',
                                     max_time=120.0, reference_length=path.length())
            save_run(result, out / f'N{n}_h{h:g}')
            results.append(result)
    lines = ['| N | h [s] | N h [s] | reached | path length [m] | time to target [s] |',
             '|---|---|---|---|---|---|']
    for r in sorted(results, key=lambda r: (r.metrics['horizon'] * r.metrics['step'])):
        m = r.metrics
        ttt = '-' if m['time_to_target'] is None else f"{m['time_to_target']:.1f}"
        lines.append(f"| {m['horizon']} | {m['step']:g} | {m['horizon'] * m['step']:.1f} | "
                     f"{'yes' if m['reached'] else 'no'} | {m['path_length']:.3f} | {ttt} |")
    lines.append(f'\nReference path length: {path.length():.3f} m')
    (out / 'table.md').write_text('\n'.join(lines) + '\n')
    plot_runs(out / 'horizon.png', world=world, reference=path.knots,
              runs=[(r.label, r.rows) for r in results], zoom=HORIZON_ZOOM,
              title='Longer horizon, shorter path (straight, 90 degree turn, straight)')
    return results


def rrt_experiment(out: Path, base: MpcConfig, *, seed: int = 0) -> list[ClosedLoopResult]:
    """Fig. 3: the MPC on an unsmoothed RRT* path (1000 iterations)."""
    world = load_world(WORLDS_DIR / 'rrt_cluttered.yaml')
    planner = RrtStarPlanner(world.obstacles, world.bounds,
                             config=PlannerConfig(iterations=1000, seed=seed, range=RRT_RANGE,
                                                  robot_radius=world.robot_radius))
    waypoints = planner.plan(world.start, world.goal)
    path = WaypointPath(waypoints, start_heading=float(world.start[2]),
                        goal_heading=float(world.goal[2]))
    model = Unicycle()
    controller = PathReferenceMPC(model, _mpc_config(world, base), obstacles=world.obstacles,
                                  path=path)
    result = run_closed_loop(controller, model, world.start, goal=world.goal,
                             obstacles=world.obstacles, label='path-reference MPC',
                             max_time=120.0, robot_radius=world.robot_radius,
                             reference_length=path.length())
    result.metrics['rrt_waypoints'] = int(len(waypoints))
    result.metrics['rrt_seed'] = seed
    save_run(result, out / 'proposed')
    np.savetxt(out / 'rrt_waypoints.csv', waypoints, delimiter=',', header='x,y', comments='')
    plot_runs(out / 'rrt.png', world=world, reference=None, runs=[(result.label, result.rows)],
              predictions=result.predictions,
              extra_paths=[(f'RRT* after 1000 iterations ({len(waypoints)} waypoints)',
                            waypoints)],
              title=f'RRT* reference ({path.length():.2f} m) and closed loop '
              f"({result.metrics['path_length']:.2f} m)")
    return [result]


EXPERIMENTS = {'obstacle': obstacle_experiment, 'horizon': horizon_experiment,
               'rrt': rrt_experiment}


def _summary(name: str, results: Sequence[ClosedLoopResult]) -> str:
    lines = []
    for r in results:
        m = r.metrics
        lines.append(
            f"{name:9s} {r.label:28s} reached={m['reached']!s:5s} collision={m['collision']!s:5s}"
            f" err={m['final_position_error']:.3f} m/{m['final_heading_error']:.3f} rad"
            f" length={m['path_length']:.2f} m (reference {m['reference_length']:.2f} m)"
            f" solve median={m['solve_ms_median']:.1f} ms"
            f" V_N violations={m['lyapunov_violations']} failures={m['solver_failures']}")
    return '\n'.join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the chosen experiments and print a one-line summary per run."""
    parser = argparse.ArgumentParser(prog='python -m mpc_local_planner.evaluation.experiments',
                                     description=__doc__.split('\n\n')[0])
    parser.add_argument('experiment', choices=[*EXPERIMENTS, 'all'])
    parser.add_argument('--out', type=Path, default=Path('out/experiments'))
    parser.add_argument('--solver', default=None, help='MPC backend (SolverSettings.solver)')
    parser.add_argument('--seed', type=int, default=0, help='RRT* seed (rrt experiment)')
    parser.add_argument('--budget', choices=BUDGETS, default=EVALUATION_BUDGET,
                        help="a step's solving: solver iterations (the same runs under any "
                             "load) or the robot's wall time (SolverSettings.budget)")
    parser.add_argument('--compile', action=argparse.BooleanOptionalAction, default=True,
                        help="compile the NLPs' functions with gcc (SolverSettings.compile, the "
                        "default); --no-compile runs CasADi's interpreted functions: the "
                        "same solutions, slower solves, no C compiler and no wait for it")
    args = parser.parse_args(argv)
    base = MpcConfig(solving=SolverSettings(budget=args.budget, compile=args.compile))
    if args.solver is not None:
        base = base.with_solving(solver=args.solver)
    names = list(EXPERIMENTS) if args.experiment == 'all' else [args.experiment]
    for name in names:
        folder = args.out / name
        folder.mkdir(parents=True, exist_ok=True)
        kwargs = {'seed': args.seed} if name == 'rrt' else {}
        results = EXPERIMENTS[name](folder, base, **kwargs)
        print(_summary(name, results))
        print(f'{name}: wrote {folder}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
