# Copyright 2026 mpc_local_planner developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""mpc_bench: solve times of the MPC backends against a naive Opti + IPOPT implementation.

Every figure is measured in the run that prints it: the paper's obstacle scenario in closed
loop (h = 0.2 s, Unicycle().step as the plant) for N in {10, 20, 40} and each backend, the
same problem written naively (CasADi Opti, IPOPT with default options, no warm start), N = 10
with 1, 5 and 20 obstacles, RRT* planning time for 1000 iterations, and (unless --skip-dds)
the controller node's latency from /odom to /cmd_vel over DDS and its resident memory.

Usage: ``python -m mpc_local_planner.evaluation.bench [--quick] [--skip-dds] [--out FILE]``.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
from typing import Any, NamedTuple, Sequence

import casadi as ca
import numpy as np

from mpc_local_planner.core.config import MpcConfig, SOLVERS
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.mpc import PathReferenceMPC
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import paper_sinusoid, ReferencePath
from mpc_local_planner.evaluation.rollout import ControlStep, rollout, StopRule

__all__ = ['closed_loop', 'extra_obstacles', 'main', 'NaiveMpc', 'paper_obstacle']

STEP = 0.2
HORIZONS = (10, 20, 40)
OBSTACLE_COUNTS = (1, 5, 20)
# Stop a closed loop when the robot is this close to the target (and count it as reached;
# headings compared wrapped).
REACHED_POSITION = 0.02
REACHED_HEADING = 0.05


def paper_obstacle() -> ConvexPolygon:
    """Return the paper's box (1, -1)-(1.5, 1)."""
    return ConvexPolygon.from_box(1.0, -1.0, 1.5, 1.0)


def extra_obstacles(count: int, path: ReferencePath) -> list[ConvexPolygon]:
    """Return count small boxes beside the path, on the side away from the paper's box.

    They sit 0.4 to 0.5 m from the path (the horizon reaches 0.62 m at N = 10), so each one
    enters the problem at some time without blocking the way.
    """
    boxes = []
    centre = np.array([1.25, 0.0])
    for i, s in enumerate(np.linspace(0.03, 0.97, count)):
        pose = path.pose(float(s))
        normal = np.array([-math.sin(pose[2]), math.cos(pose[2])])
        if normal @ (pose[:2] - centre) < 0:
            normal = -normal
        c = pose[:2] + (0.42 + 0.08 * (i % 2)) * normal
        boxes.append(ConvexPolygon.from_box(c[0] - 0.05, c[1] - 0.05, c[0] + 0.05, c[1] + 0.05))
    return boxes


class NaiveSolution(NamedTuple):
    """What the naive MPC reports of a step beyond the rollout's ControlStep."""

    iterations: int


class NaiveMpc:
    """The same OCP as a user would write it in an afternoon: Opti, IPOPT defaults, no warm start.

    Decision variables X, U, s and a Farkas multiplier per obstacle, face and step; all
    obstacles are always in the problem; each solve starts from Opti's default guess (zeros).
    """

    def __init__(self, model: Unicycle, config: MpcConfig, obstacles: Sequence[ConvexPolygon],
                 path: ReferencePath) -> None:
        n, h = config.horizon, config.step
        inflation = config.inflation(float(model.u_max[0]))
        opti = ca.Opti()
        X = opti.variable(3, n + 1)
        U = opti.variable(2, n)
        s = opti.variable()
        x0 = opti.parameter(3)
        x_s = path.symbolic(s, [])
        cost = 0
        for i in range(n):
            dx = X[:, i] - x_s
            cost += (dx[0] ** 4 + dx[1] ** 4 + config.weight_heading * dx[2] ** 4
                     + U[0, i] ** 4 + U[1, i] ** 4)
        opti.minimize(cost + config.offset_weight * (1 - s) ** 2)
        F = model.discrete(h)
        opti.subject_to(X[:, 0] == x0)
        for i in range(n):
            opti.subject_to(X[:, i + 1] == F(X[:, i], U[:, i]))
        opti.subject_to(X[:, n] == x_s)
        for i in range(n):
            opti.subject_to(opti.bounded(model.u_min, U[:, i], model.u_max))
        opti.subject_to(opti.bounded(0, s, 1))
        for obstacle in obstacles:
            grown = obstacle.inflate(inflation)
            mu = opti.variable(grown.num_faces, n)
            opti.subject_to(ca.vec(mu) >= 0)
            for i in range(n):
                opti.subject_to(ca.sum1(mu[:, i]) == 1)
                p = X[0:2, i + 1]
                opti.subject_to(ca.dot(ca.mtimes(grown.A, p) - grown.b, mu[:, i])
                                >= config.farkas_margin)
        opti.solver('ipopt', {'print_time': False}, {'print_level': 0, 'sb': 'yes'})
        self._opti, self._x0, self._U = opti, x0, U

    def step(self, x: np.ndarray) -> ControlStep:
        """Return the rollout's step: u0, solve time, success, iterations in detail."""
        u, seconds, iterations, ok = self.solve(x)
        return ControlStep(u=u, solve_time_s=seconds, success=ok,
                           detail=NaiveSolution(iterations=iterations))

    def solve(self, x: np.ndarray) -> tuple[np.ndarray, float, int, bool]:
        """Return (u0, solve seconds, iterations, success)."""
        self._opti.set_value(self._x0, x)
        start = time.perf_counter()
        try:
            sol = self._opti.solve()
            ok = True
            u = np.asarray(sol.value(self._U)).reshape(2, -1)[:, 0]
        except RuntimeError:
            ok = False
            u = np.asarray(self._opti.debug.value(self._U)).reshape(2, -1)[:, 0]
        seconds = time.perf_counter() - start
        return u, seconds, int(self._opti.stats().get('iter_count', 0)), ok


def stats(values: list[float]) -> dict[str, float]:
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return {'median': math.nan, 'p95': math.nan, 'max': math.nan}
    return {'median': float(np.median(a)), 'p95': float(np.percentile(a, 95)),
            'max': float(np.max(a))}


def closed_loop(solver: str, horizon: int, obstacles: list[ConvexPolygon], *,
                max_steps: int, compile_functions: bool = True) -> dict[str, Any]:
    """Run the paper's scenario in closed loop (evaluation.rollout); return timings and outcome.

    solver is a backend of MpcConfig.solver or 'naive'. For the package's backends, a first
    closed loop builds (and compiles) the NLPs it meets; the timed one reuses them. A run
    ends within REACHED_POSITION and REACHED_HEADING of the target (headings wrapped) or
    after max_steps solves (every recorded state is solved for, the final one included).
    """
    model, path = Unicycle(), paper_sinusoid()
    if solver == 'naive':
        config = MpcConfig(horizon=horizon, step=STEP)
        controller: Any = NaiveMpc(model, config, obstacles, path)
        runs = 1
    else:
        config = MpcConfig(horizon=horizon, step=STEP, solver=solver, compile=compile_functions)
        controller = PathReferenceMPC(model, config, obstacles=obstacles, path=path)
        runs = 2
    # No stall rule: the naive MPC stands in front of the box, and its solves there are timed
    # for the whole run, as the published tables were.
    rule = StopRule(time_limit=(max_steps - 1) * STEP, position_tolerance=REACHED_POSITION,
                    heading_tolerance=REACHED_HEADING, stall_steps=max_steps + 2)
    warmup: dict[str, Any] = {}
    for run in range(runs):
        result = rollout(controller, model, path.start, path.goal, h=STEP, rule=rule)
        if run == 0 and runs == 2:
            warmup = {'step_ms': stats(list(1e3 * result.step_times))}
            controller.wait_compiled()
            controller.reset()
    details = [step.detail for step in result.steps]
    iterations = [int(getattr(d, 'iterations', 0)) for d in details]
    in_reach = [d.obstacles_in_reach for d in details if hasattr(d, 'obstacles_in_reach')]
    active = [d.obstacles_active for d in details if hasattr(d, 'obstacles_active')]
    xy = result.rows[:, 1:3]
    return {
        'solver': solver if solver == 'naive' or not compile_functions else f'{solver}+compiled',
        'horizon': horizon, 'obstacles': len(obstacles), 'steps': len(result.steps),
        'solve_ms': stats(list(1e3 * result.solve_times)),
        'step_ms': stats(list(1e3 * result.step_times)),
        'iterations_median': float(np.median(iterations)),
        'iterations_max': int(np.max(iterations)),
        'in_reach_max': int(max(in_reach, default=len(obstacles))),
        'in_reach_median': float(np.median(in_reach)) if in_reach else float(len(obstacles)),
        'active_max': int(max(active, default=len(obstacles))),
        'active_median': float(np.median(active)) if active else float(len(obstacles)),
        'reached': result.reached, 'outcome': result.outcome.value,
        'path_length': float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1))),
        'collision': any(bool(np.any(o.contains(xy))) for o in obstacles),
        'failures': result.solver_failures,
        'lyapunov_violations': sum(1 for ok in result.lyapunov_ok if ok is False),
        'first_run': warmup,
    }


def bench_rrt(repeats: int) -> dict[str, Any]:
    """Time RrtStarPlanner for 1000 iterations on config/worlds/rrt_cluttered.yaml."""
    from mpc_local_planner.core.planner import PlannerConfig, RrtStarPlanner
    from mpc_local_planner.worlds.data_files import resolve_data_file
    from mpc_local_planner.worlds.world import load_world

    world = load_world(resolve_data_file('worlds/rrt_cluttered.yaml'))
    times = []
    for seed in range(repeats):
        planner = RrtStarPlanner(world.obstacles, world.bounds, config=PlannerConfig(
            iterations=1000, seed=seed, robot_radius=float(world.robot_radius),
            time_limit=60.0))
        start = time.perf_counter()
        planner.plan(world.start, world.goal)
        times.append(1e3 * (time.perf_counter() - start))
    return {'iterations': 1000, 'plans': repeats, 'plan_ms': stats(times)}


def _row(r: dict[str, Any], naive: dict[str, Any] | None) -> str:
    s = r['solve_ms']
    ratio = naive['solve_ms']['median'] / s['median'] if naive else math.nan
    return (f"| {r['solver']:<16} | {r['horizon']:>3} | {r['obstacles']:>3} "
            f"| {r['in_reach_max']:>5} | {r.get('active_max', r['in_reach_max']):>6} "
            f"| {s['median']:8.3f} | {s['p95']:8.3f} | {s['max']:8.3f} "
            f"| {r['iterations_median']:5.1f} | {r['step_ms']['median']:8.3f} "
            f"| {ratio:6.1f} | {'yes' if r['reached'] else 'NO':>3} | {r['path_length']:6.3f} "
            f"| {r['failures']:>3} |")


HEADER = ('| backend          |   N | obs | reach | active | solve ms |  p95 ms  |  max ms  '
          '|  its  | step ms  | x naive| hit | length | nsv |\n'
          '|------------------|-----|-----|-------|--------|----------|----------|----------'
          '|-------|----------|--------|-----|--------|-----|')


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark, print the table and write JSON."""
    parser = argparse.ArgumentParser(prog='mpc_bench', description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='fewer steps, N = 10 and 40 only')
    parser.add_argument('--skip-dds', action='store_true', help='skip the ROS 2 measurement')
    parser.add_argument('--out', default='bench.json', help='JSON output file')
    parser.add_argument('--backends', nargs='*', default=list(SOLVERS),
                        help='backends to time (default: all)')
    args = parser.parse_args(argv)

    max_steps = 60 if args.quick else 250
    horizons = (10, 40) if args.quick else HORIZONS
    results: dict[str, Any] = {
        'machine': {'python': sys.version.split()[0], 'casadi': ca.__version__,
                    'platform': platform.platform()},
        'command': 'mpc_bench ' + ' '.join(sys.argv[1:] if argv is None else argv),
        'horizons': [], 'obstacles': [],
    }
    paper = [paper_obstacle()]
    variants = [(b, True) for b in args.backends] + [('ipopt', False)] * ('ipopt' in args.backends)
    variants += [('fatrop', False)] * ('fatrop' in args.backends)
    print(f'closed loop on the paper scenario, h = {STEP} s, medians over the steps; '
          f'nsv = steps without a verified solver solution', flush=True)
    print(HEADER, flush=True)
    for n in horizons:
        naive = closed_loop('naive', n, paper, max_steps=max_steps)
        for backend, compiled in variants:
            r = closed_loop(backend, n, paper, max_steps=max_steps, compile_functions=compiled)
            r['ratio_to_naive'] = naive['solve_ms']['median'] / r['solve_ms']['median']
            results['horizons'].append(r)
            print(_row(r, naive), flush=True)
        results['horizons'].append(naive)
        print(_row(naive, naive), flush=True)
    print("\nN = 10 with more obstacles (reach: most obstacles within the horizon's reach at "
          'once, all checked; active: most held in the NLP at once)')
    print(HEADER, flush=True)
    path = paper_sinusoid()
    for count in OBSTACLE_COUNTS:
        obstacles = paper + extra_obstacles(count - 1, path)
        naive = closed_loop('naive', 10, obstacles, max_steps=max_steps)
        for backend, compiled in variants:
            r = closed_loop(backend, 10, obstacles, max_steps=max_steps,
                            compile_functions=compiled)
            r['ratio_to_naive'] = naive['solve_ms']['median'] / r['solve_ms']['median']
            results['obstacles'].append(r)
            print(_row(r, naive), flush=True)
        results['obstacles'].append(naive)
        print(_row(naive, naive), flush=True)

    rrt = bench_rrt(3 if args.quick else 10)
    results['rrt'] = rrt
    print(f"\nRRT* 1000 iterations on rrt_cluttered.yaml: median {rrt['plan_ms']['median']:.1f} ms"
          f", p95 {rrt['plan_ms']['p95']:.1f} ms over {rrt['plans']} seeds", flush=True)

    if not args.skip_dds:
        # the one part that needs rclpy, hence in ros/ and imported only when it runs
        from mpc_local_planner.ros.latency_bench import measure_controller_latency

        dds = measure_controller_latency(steps=30 if args.quick else 100)
        results['dds'] = dds
        print(dds['summary'], flush=True)

    with open(args.out, 'w', encoding='utf-8') as f:
        json.dump(results, f, indent=2)
    print(f'\nwrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
