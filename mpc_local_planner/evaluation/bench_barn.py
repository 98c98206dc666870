# SPDX-License-Identifier: Apache-2.0
"""mpc_bench's barn rows: the control step on recorded hard BARN states, part by part.

The headline solve (the paper's one box) is not what a robot among BARN's cylinders pays.
These rows time what the controller node does per scan on states a robot really meets:

1. **Record.** The in-process navigator (`run_navigation`: laser only, no map, the Jackal at
   2 m/s, the suites' iteration budget, so the run is the same on any machine) drives the
   paper's MPC through each hard world, and keeps every step's inputs (`RecordedStep`: the
   pose, the scan, a plan adopted at that step, the command).
2. **Replay.** Each controller, fresh, takes the same inputs in the same order as the node
   gives them: the scan into its own `ObstacleMemory` and `LocalObstacles` (perception), the
   obstacles near the robot and the plan, then `compute` (the solve, verification, the
   candidate and the Python around them). The commands are not applied: every controller is
   timed on the MPC's states, so the rows compare the same work.

The replayed MPC is the recorded one (the same cached instance, reset), so with the
iteration budget it answers exactly as it did; the rows say whether it did (`same
commands`), which shows that the replay is the run. Step times are wall time on this machine
as loaded now (printed with the load average): medians are worth comparing in one run, the
tails are the machine's as much as the controller's.
"""

from __future__ import annotations

import math
import time
from typing import Any, Sequence

import numpy as np

from mpc_local_planner.core.mpc.compilation import compile_wait_seconds
from mpc_local_planner.evaluation.bench_runs import stats
from mpc_local_planner.evaluation.navigation import NavigationSettings, RecordedStep
from mpc_local_planner.evaluation.sensing_suites import local_controller, Robot, run_navigation
from mpc_local_planner.evaluation.suite_runs import navigation_world, Task
from mpc_local_planner.perception.local_obstacles import LocalObstacles
from mpc_local_planner.perception.scan_obstacles import ObstacleMemory
from mpc_local_planner.worlds.world import World

__all__ = [
    'BARN_CONTROLLERS',
    'BARN_WORLDS',
    'barn_figures',
    'barn_lines',
    'bench_barn',
    'record_barn_run',
    'replay_steps',
    'TARGET_BARN_STEP_MS',
]

# Hard worlds (the last third of BARN's difficulty order), the ones issue 34's profile used.
BARN_WORLDS = (200, 201, 202)
# The paper's MPC and the two peers timed on its states.
BARN_CONTROLLERS = ('proposed', 'dwa', 'regulated_pure_pursuit')
# The Jackal at its limits, as the BARN suites run it.
BARN_V_MAX = 2.0
BARN_OMEGA_MAX = 4.0
# Issue 34's targets for the paper's MPC's whole step (ms, on this machine when idle).
TARGET_BARN_STEP_MS = {'median': 10.0, 'p99': 40.0, 'max': 100.0}
# The parts of a step, in the order the tables show them.
PARTS = ('step', 'perception', 'controller', 'solver', 'rest')
# The faces per obstacle the navigator's local controller takes (Navigator's default).
FACES = 8


def record_barn_run(world_index: int) -> tuple[Robot, World, list[RecordedStep], str]:
    """Drive the paper's MPC through a BARN world in process; return its recorded steps.

    Returns the robot, the world, the steps and the run's outcome in words.
    """
    task = Task('barn', world_index, 'proposed', v_max=BARN_V_MAX, omega_max=BARN_OMEGA_MAX,
                sensing=True, robot='jackal')
    robot, world, _ = navigation_world(task)
    result = run_navigation(world, 'proposed', robot, record=True)
    assert result.navigator is not None and result.navigator.recorded is not None
    run = result.run
    outcome = f'{run.outcome.value} at {run.end_time:.1f} s'
    return robot, world, result.navigator.recorded, outcome


def replay_steps(name: str, robot: Robot, world: World, steps: Sequence[RecordedStep]
                 ) -> dict[str, Any]:
    """Feed the recorded steps to a fresh controller as the node would; time each part.

    Returns per part the milliseconds of every step ('solver' and 'rest' only for the steps
    where an MPC solved), the solver iterations of those steps, and how many commands
    differ from the recorded ones (by more than 1e-9).
    """
    built = local_controller(name, robot, world)
    controller: Any = built.controller
    settings = NavigationSettings()  # the navigator's, as the recorded run had them
    memory = ObstacleMemory(settings.memory_ttl)
    obstacles = LocalObstacles(FACES, memory=memory)
    radius = built.reach + settings.sensing_margin
    times: dict[str, list[float]] = {part: [] for part in PARTS}
    iterations: list[float] = []
    differ = 0
    for step in steps:
        if step.plan is not None:
            controller.set_plan(step.plan)
        started = time.perf_counter()
        if step.scan is not None:
            memory.update(step.scan, step.x, body=robot.footprint)
            obstacles.scan_updated()
        nearby = obstacles.near(step.x[:2], radius)
        perceived = time.perf_counter()
        waited = compile_wait_seconds()
        controller.set_obstacles(nearby)
        output = controller.compute(step.x, step.twist, step.t)
        ended = time.perf_counter()
        controller_s = ended - perceived - (compile_wait_seconds() - waited)
        times['perception'].append(1e3 * (perceived - started))
        times['controller'].append(1e3 * controller_s)
        times['step'].append(1e3 * (perceived - started + controller_s))
        solution = output.solution
        if solution is not None and output.fresh:
            times['solver'].append(1e3 * solution.solve_time_s)
            times['rest'].append(1e3 * (controller_s - solution.solve_time_s))
            iterations.append(float(solution.iterations))
        differ += int(not np.allclose(output.u, step.u, rtol=0.0, atol=1e-9)
                      and output.reason.applies_input)
    return {'times': times, 'iterations': iterations, 'differ': differ}


def bench_barn(worlds: Sequence[int] = BARN_WORLDS, *, max_steps: int | None = None,
               controllers: Sequence[str] = BARN_CONTROLLERS) -> dict[str, Any]:
    """Record the paper's MPC on each world, replay every controller; return the figures.

    max_steps: replay at most this many steps of each recorded run (all: None).
    """
    runs, replays = [], []
    for index in worlds:
        robot, world, steps, outcome = record_barn_run(index)
        steps = steps[:max_steps] if max_steps is not None else steps
        runs.append({'world': index, 'outcome': outcome, 'steps': len(steps),
                     'scans': sum(s.scan is not None for s in steps)})
        replays.append({name: replay_steps(name, robot, world, steps) for name in controllers})
    return barn_figures(runs, replays)


def barn_figures(runs: list[dict[str, Any]], replays: Sequence[dict[str, dict[str, Any]]]
                 ) -> dict[str, Any]:
    """Pool the replays of every world per controller; return the rows and the checks.

    runs: per world its number, outcome and steps; replays: per world, controller name ->
    `replay_steps`'s answer.
    """
    controllers = list(replays[0]) if replays else []
    pooled: dict[str, dict[str, list[float]]] = {
        name: {part: [] for part in (*PARTS, 'iterations')} for name in controllers}
    for replay in replays:
        for name, replayed in replay.items():
            for part, values in replayed['times'].items():
                pooled[name][part] += values
            pooled[name]['iterations'] += replayed['iterations']
    differ = sum(replay['proposed']['differ'] for replay in replays if 'proposed' in replay)
    rows = {name: {part: stats(values, tail=99) for part, values in parts.items()}
            for name, parts in pooled.items()}
    return {'worlds': runs, 'rows': rows,
            'solved_steps': {name: len(pooled[name]['solver']) for name in controllers},
            'same_commands': differ == 0 if 'proposed' in controllers else None,
            'differing_commands': differ}


def barn_lines(result: dict[str, Any]) -> list[str]:
    """Return the barn table: per controller and part, median / p99 / max in ms."""
    lines = ["worlds (the paper's MPC recorded in process, laser only, the Jackal at 2 m/s, "
             "the suites' iteration budget): "
             + '; '.join(f"{r['world']}: {r['outcome']}, {r['steps']} steps, {r['scans']} scans"
                         for r in result['worlds'])]
    lines.append(f"{'controller':<24} {'part':<11} {'median':>8} {'p99':>8} {'max':>8}")
    for name, parts in result['rows'].items():
        for part in PARTS:
            figures = parts[part]
            if math.isnan(figures['median']):
                continue
            lines.append(f"{name:<24} {part:<11} {figures['median']:8.2f} "
                         f"{figures['p99']:8.2f} {figures['max']:8.2f}")
        if not math.isnan(parts['iterations']['median']):
            it = parts['iterations']
            lines.append(f"{name:<24} {'iterations':<11} {it['median']:8.0f} {it['p99']:8.0f} "
                         f"{it['max']:8.0f}  ({result['solved_steps'][name]} solving steps)")
    if 'proposed' in result['rows']:
        step = result['rows']['proposed']['step']
        verdicts = ', '.join(
            f"{key} {step[key]:.1f} <= {target:g}: "
            f"{'met' if step[key] <= target else 'MISSED'}"
            for key, target in TARGET_BARN_STEP_MS.items())
        lines.append(f"the paper's MPC's step against issue 34's targets (idle machine): "
                     f"{verdicts}")
        lines.append("replayed MPC commands equal to the recorded run's: "
                     + ('yes' if result['same_commands']
                        else f"no ({result['differing_commands']} differ)"))
    for line in ('parts: perception = the memory update and the obstacles near the robot; '
                 'controller = set_obstacles + compute; solver = the NLP solves of a solving '
                 "step; rest = the controller's time around them (verification, the "
                 'candidate, the Python); step = perception + controller',):
        lines.append(line)
    return lines
