# SPDX-License-Identifier: Apache-2.0
"""mpc_bench: solve times of the MPC backends against a plain CasADi Opti + IPOPT peer.

Every figure is measured in the run that prints it: the paper's obstacle scenario in closed
loop (h = 0.2 s, Unicycle().step as the plant) for N in {10, 20, 40} and each backend, the
same problem written as a competent CasADi user would (`opti_peer.OptiMpc`: casadi.Opti, IPOPT with
expand=True, warm-started from the shifted previous solution and multipliers), N = 10
with 1, 5 and 20 obstacles, and RRT* planning time for 1000 iterations. The controller
node's latency over DDS is ``mpc_bench_dds`` (ros/latency_bench.py): the one benchmark that
needs rclpy lives in ros/, and this module imports nothing from there.

Perception on BARN world 0 (the robot at poses along its start-goal line, heading to the
goal): a simulated 720-beam scan; scan -> obstacles and the obstacle memory's update; and
the whole control step with scan obstacles (memory update, obstacles set, MPC solve, N = 10)
in a ROS-free closed loop along the world's RRT* path.

Polygon footprint (the Jackal, core/footprint.JACKAL, N = 10): the whole control step in the
same closed loop, along an RRT* plan made for the footprint, on the paper's box (start and
goal as in the paper; the paper's sinusoid itself crosses the box for the Jackal's rectangle,
an Assumption 1 violation for that path) and on BARN world 0, with scan obstacles (the
perception rows' step) and with the world's obstacles known (the MPC's step alone).

Control rate (section 'rate'): MpcController.compute called at CONTROL_FREQUENCY (20 Hz,
t = k / 20) in closed loop on the paper's scenario (N = 10, h = 0.2 s, the model as the
plant): the MPC solves once per step, so three calls in four apply the held plan after the
safety checks; their times are reported apart from the solving calls' and together
(median, p99, max), which is what a 20 Hz control timer has to fit into its 50 ms period.

Hard BARN states (section 'barn', `bench_barn`): the paper's MPC recorded in process on hard
BARN worlds (laser only, the Jackal at 2 m/s), then the node's step (perception, the
controller, and within it the solver and the rest) replayed on the same states for the MPC,
the DWA and Nav2's regulated pure pursuit; median, p99 and max per part.

Usage: ``python -m mpc_local_planner.evaluation.bench [--quick] [--out FILE] [--sections ...]``.

This module is the command (its options, the tables, the JSON); the measurements themselves
are `bench_runs`'.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
from typing import Any, Sequence

import casadi as ca
import numpy as np

from mpc_local_planner.core.config import SOLVERS
from mpc_local_planner.core.footprint import Footprint, JACKAL
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.paths import paper_sinusoid
from mpc_local_planner.evaluation.bench_barn import barn_lines, BARN_WORLDS, bench_barn
from mpc_local_planner.evaluation.bench_runs import (
    bench_cold_start,
    bench_control_rate,
    bench_footprint,
    bench_laser,
    bench_rrt,
    bench_scan_control,
    bench_scan_obstacles,
    closed_loop,
    CONTROL_FREQUENCY,
    extra_obstacles,
    FOOTPRINT_HORIZON,
    FOOTPRINT_SCENARIOS,
    HORIZONS,
    OBSTACLE_COUNTS,
    OBSTACLE_TTL,
    paper_obstacle,
    PEER,
    REACHED_HEADING,
    REACHED_POSITION,
    SCAN_PERIOD,
    STEP,
    SWEEP_SPEED,
    TARGET_CONTROL_STEP_MS,
    TARGET_FOOTPRINT_SOLVE_MS,
    TARGET_FOOTPRINT_STEP_MS,
    TARGET_LASER_MS,
    TARGET_SCAN_OBSTACLES_MS,
    verdict,
)
from mpc_local_planner.evaluation.opti_peer import OptiMpc

__all__ = ['main']

# What main() can run, in this order.
SECTIONS = ('horizons', 'obstacles', 'rrt', 'perception', 'footprint', 'rate', 'cold_start',
            'barn')
# --quick's barn rows: one world, its first steps.
QUICK_BARN_STEPS = 80
# The closed loops on the paper's scenario end at the goal (72-76 steps at h = 0.2 s), or
# after this many steps, in both modes: a row that did not reach the goal says why.
CLOSED_LOOP_STEPS = 250
# The `end` column: the rollout's Outcome value -> the word in the table.
ENDS = {'reached': 'goal', 'time limit': 'cap', 'stalled': 'stall', 'collision': 'contact',
        'stopped': 'stop'}
# What the perception and footprint targets are (they come with the perception and the
# footprint work, docs/results.md; medians, on this machine as loaded now).
TARGETS_NOTE = (
    f'targets (medians, on this machine as loaded now: the load average is printed at the '
    f'end): a simulated 720-beam scan <= {TARGET_LASER_MS:g} ms, scan -> obstacles <= '
    f'{TARGET_SCAN_OBSTACLES_MS:g} ms, the whole control step with scan obstacles (N = 10) '
    f'<= {TARGET_CONTROL_STEP_MS:g} ms; the memory update has no target of its own: it is '
    'part of the whole step')


def _end(r: dict[str, Any]) -> str:
    """Return how a closed loop ended, as the `end` column says it."""
    return ENDS.get(str(r.get('outcome')), 'goal' if r.get('reached') else '?')


def _goal_cell(r: dict[str, Any]) -> str:
    """Return 'yes' at the goal, 'cap' when the step cap came first, else 'NO'."""
    if r['reached']:
        return 'yes'
    return 'cap' if r['steps'] >= r['max_steps'] else 'NO'


def _ended(reached: bool, done: int, cap: int, what: str, distance: float | None) -> str:
    """Say how a capped run ended: at the goal, at its cap (short of it), or before it."""
    away = f' ({distance:.2f} m from it)' if distance is not None else ''
    if reached:
        return 'goal reached'
    if done >= cap:
        return f'stopped at the cap of {cap} {what}, short of the goal{away}'
    return f'goal not reached{away}'


def _missed(name: str, figures: dict[str, float], target: float, why: str = '') -> str:
    """Say which target a row misses, by how much, and what its time is made of."""
    return (f"missed: {name}, median {figures['median']:.3f} ms > {target:g} ms"
            + (f'; {why}' if why else ''))


def _rate_lines(rate: dict[str, Any]) -> list[str]:
    """Return the control-rate table: solving calls, holding calls, all; then context."""
    title = f"compute at {rate['frequency']:g} Hz (N = {rate['horizon']})"
    lines = [f'| {title:<25} | calls | median ms |  p99 ms  |  max ms  |',
             '|---------------------------|-------|-----------|----------|----------|']
    for name, key, count in (('solving (once per step h)', 'solve_ms', rate['solves']),
                             ('holding the verified plan', 'hold_ms', rate['holds']),
                             ('all', 'all_ms', rate['solves'] + rate['holds'])):
        f = rate[key]
        lines.append(f"| {name:<25} | {count:>5} | {f['median']:9.3f} | {f['p99']:8.3f} "
                     f"| {f['max']:8.3f} |")
    lines.append(
        f"paper's scenario, {rate['solver']}, h = {rate['step']:g} s, calls at t = k / "
        f"{rate['frequency']:g} s: {rate['calls']} calls, "
        f"{_ended(rate['reached'], rate['calls'], rate['max_calls'], 'calls', None)}; the "
        f"period is {1e3 / rate['frequency']:g} ms.")
    return lines


FOOTPRINT_HEADER = (
    '| scenario (Jackal, N = 10)        | steps | goal | solve ms |  p95 ms  |  max ms  '
    '| <= 2 ms | step ms  |  max ms  | <= 5 ms | nsv |\n'
    '|----------------------------------|-------|------|----------|----------|----------'
    '|---------|----------|----------|---------|-----|')


def _footprint_lines(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Return the footprint table: a row per scenario, then a line of context for each."""
    lines = FOOTPRINT_HEADER.split('\n')
    for r in rows:
        s, w = r['solve_ms'], r['step_ms']
        lines.append(
            f"| {r['label']:<32} | {r['steps']:>5} | {_goal_cell(r):>4} "
            f"| {s['median']:8.3f} | {s['p95']:8.3f} | {s['max']:8.3f} "
            f"| {r['solve_verdict']:<7} | {w['median']:8.3f} | {w['max']:8.3f} "
            f"| {r['step_verdict']:<7} | {r['not_solved_steps']:>3} |")
    for r in rows:
        if r['obstacles'] == 'scan':
            obstacles = (f"scan obstacles: the step is memory update (median "
                         f"{r['memory_update_ms']['median']:.3f} ms) + set_obstacles and "
                         f"compute (median {r['set_and_solve_ms']['median']:.3f} ms)")
        else:
            obstacles = 'known obstacles: the step is MpcController.compute'
        lines.append(
            f"{r['scenario']}: {r['solver']}, {obstacles}; along the {r['reference']}; "
            f"{r['steps']} steps, "
            f"{_ended(r['reached'], r['steps'], r['max_steps'], 'steps', r['goal_distance'])}, "
            f"in reach median {r['in_reach_median']:g} "
            f"(max {r['in_reach_max']}), in the NLP median {r['active_median']:g} "
            f"(max {r['active_max']}), {r['contact_steps']} steps in contact, "
            f"{r['timed_out_steps']} out of time budget; untimed warm-up "
            f"{r['warmup_s']:.1f} s (NLP builds and compilation).")
    for r in rows:
        if r['solve_verdict'] != 'met':
            lines.append(_missed(f"{r['label']}: the solve", r['solve_ms'],
                                 r['target_solve_ms']))
        if r['step_verdict'] != 'met':
            why = ('the step is the memory update (median '
                   f"{r['memory_update_ms']['median']:.3f} ms) and set + solve (median "
                   f"{r['set_and_solve_ms']['median']:.3f} ms)" if r['obstacles'] == 'scan'
                   else 'the step is MpcController.compute: the solve (median '
                   f"{r['solve_ms']['median']:.3f} ms) and its checks")
            lines.append(_missed(f"{r['label']}: the whole step", r['step_ms'],
                                 r['target_step_ms'], why))
    return lines


def _perception_lines(laser: dict[str, Any], scan: dict[str, Any],
                      control: dict[str, Any]) -> list[str]:
    def cell(figures: dict[str, float]) -> str:
        return (f"{figures['median']:7.3f} | {figures['p95']:7.3f} | {figures['max']:7.3f}")

    rows = [
        ('simulated scan (720 beams)', laser['scan_ms'], laser['target_ms']),
        ('scan_to_obstacles', scan['scan_to_obstacles_ms'], scan['target_ms']),
        ('ObstacleMemory.update', scan['memory_update_ms'], math.nan),  # part of the step
        ('control step: memory + MPC', control['step_ms'], control['target_ms']),
        ('  of which memory update', control['memory_update_ms'], math.nan),
        ('  of which set + solve', control['set_and_solve_ms'], math.nan),
    ]
    lines = ['| BARN world 0                 | median  |   p95   |   max   | target ms |'
             '        |',
             '|------------------------------|---------|---------|---------|-----------|'
             '--------|']
    for name, figures, target in rows:
        goal = f'{target:9.1f}' if math.isfinite(target) else ' ' * 9
        mark = verdict(figures, target) if math.isfinite(target) else ''
        lines.append(f'| {name:<28} | {cell(figures)} | {goal} | {mark:<6} |')
    lines.append(
        f"scans: {scan['scans']} poses along the start-goal line, one scan per "
        f"{SWEEP_SPEED * SCAN_PERIOD:g} m ({SCAN_PERIOD:g} s at {SWEEP_SPEED:g} m/s): median "
        f"{scan['obstacles_per_scan_median']:g} obstacles per scan, "
        f"{scan['remembered_median']:g} remembered (max {scan['remembered_max']}, ttl "
        f"{OBSTACLE_TTL:g} s).")
    cap = control.get('max_steps', control['steps'])
    lines.append(
        f"control: N = {control['horizon']}, {control['solver']}, along the "
        f"{control['reference']}, {control['steps']} steps, "
        f"{_ended(control['reached'], control['steps'], cap, 'steps', control['goal_distance'])}"
        f", {control['remembered_median']:g} "
        f"obstacles remembered (median), in reach median {control['in_reach_median']:g} "
        f"(max {control['in_reach_max']}), "
        f"{control['contact_steps']} steps in contact, {control['not_solved_steps']} steps "
        'without a verified solver solution.')
    lines.append(TARGETS_NOTE + '.')
    for name, figures, target in rows:
        if math.isfinite(target) and verdict(figures, target) != 'met':
            why = ''
            if figures is control['step_ms']:
                why = (f"of it, the memory update {control['memory_update_ms']['median']:.3f} "
                       f"ms and set + solve {control['set_and_solve_ms']['median']:.3f} ms "
                       '(medians)')
            lines.append(_missed(name, figures, target, why))
    return lines


def _beside_peer(horizon: int, obstacles: list[ConvexPolygon],
                 variants: Sequence[tuple[str, bool]], max_steps: int) -> list[dict[str, Any]]:
    """Run the peer and each (backend, compiled) variant in closed loop; print their rows.

    Returns the variants' results, each with its ratio to the peer, then the peer's.
    """
    peer = closed_loop(PEER, horizon, obstacles, max_steps=max_steps)
    rows = []
    for backend, compiled in variants:
        r = closed_loop(backend, horizon, obstacles, max_steps=max_steps,
                        compile_functions=compiled)
        r['ratio_to_peer'] = peer['solve_ms']['median'] / r['solve_ms']['median']
        rows.append(r)
        print(_row(r, peer), flush=True)
    print(_row(peer, peer), flush=True)
    return rows + [peer]


def _row(r: dict[str, Any], peer: dict[str, Any] | None) -> str:
    s = r['solve_ms']
    ratio = peer['solve_ms']['median'] / s['median'] if peer else math.nan
    return (f"| {r['solver']:<16} | {r['horizon']:>3} | {r['obstacles']:>3} "
            f"| {r['in_reach_max']:>5} | {r.get('active_max', r['in_reach_max']):>6} "
            f"| {s['median']:8.3f} | {s['p95']:8.3f} | {s['max']:8.3f} "
            f"| {r['iterations_median']:5.1f} | {r['step_ms']['median']:8.3f} "
            f"| {ratio:6.1f} | {_end(r):>7} | {r['path_length']:6.3f} "
            f"| {r['failures']:>3} |")


HEADER = ('| backend          |   N | obs | reach | active | solve ms |  p95 ms  |  max ms  '
          '|  its  | step ms  | x peer |   end   | length | nsv |\n'
          '|------------------|-----|-----|-------|--------|----------|----------|----------'
          '|-------|----------|--------|---------|--------|-----|')
END_NOTE = (f'end: how the run ended: goal = within {REACHED_POSITION:g} m and '
            f"{REACHED_HEADING:g} rad of the paper's goal; cap = {CLOSED_LOOP_STEPS} steps "
            'came first; stall, contact, stop = the rollout stopped it')


def main(argv: Sequence[str] | None = None, *, footprint_compile: bool = True,
         footprint_steps: int | None = None, rate_compile: bool = True,
         rate_calls: int | None = None, cold_start_controllers: str = 'proposed') -> int:
    """Run the benchmark, print the tables and write JSON.

    footprint_compile: compile the footprint rows' NLPs with gcc (as a robot would run
    them); False times the interpreted functions, and footprint_steps caps each footprint
    row's steps: a test uses both to check the rows' form without waiting minutes for gcc.
    rate_compile and rate_calls do the same for the control-rate rows.
    cold_start_controllers: the controller of the cold-start runs (a test: 'dwa', no NLP).
    """
    parser = argparse.ArgumentParser(prog='mpc_bench', description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true',
                        help='N = 10 and 40 only, 3 RRT* seeds, 50 scans, 60 control steps '
                             'per perception and footprint row and 240 calls at the control '
                             'rate (those stop short of their goals: "cap"), and the barn rows '
                             f'on world {BARN_WORLDS[0]} only, its first {QUICK_BARN_STEPS} '
                             'steps')
    parser.add_argument('--out', default='bench.json', help='JSON output file')
    parser.add_argument('--backends', nargs='*', default=list(SOLVERS),
                        help='backends to time (default: all)')
    parser.add_argument('--sections', nargs='*', choices=SECTIONS, default=list(SECTIONS),
                        help='tables to measure (default: all)')
    args = parser.parse_args(argv)
    sections = set(args.sections)

    max_steps = CLOSED_LOOP_STEPS  # both modes: the paper's runs end at the goal
    horizons = (10, 40) if args.quick else HORIZONS
    results: dict[str, Any] = {
        'machine': {'python': sys.version.split()[0], 'casadi': ca.__version__,
                    'platform': platform.platform(), 'cpus': os.cpu_count(),
                    'load_average_before': list(os.getloadavg())},
        'command': 'mpc_bench ' + ' '.join(sys.argv[1:] if argv is None else argv),
    }
    paper = [paper_obstacle()]
    variants = [(b, True) for b in args.backends] + [('ipopt', False)] * ('ipopt' in args.backends)
    variants += [('fatrop', False)] * ('fatrop' in args.backends)
    if 'horizons' in sections:
        results['horizons'] = []
        print(f'closed loop on the paper scenario, h = {STEP} s, medians over the steps; '
              'nsv = steps without a verified solver solution', flush=True)
        print(f'x peer = median solve time of {PEER!r} / median solve time of the row; '
              f'{PEER!r} is the same OCP in {OptiMpc.LABEL} (shifted primal and multipliers)',
              flush=True)
        print(END_NOTE, flush=True)
        print(HEADER, flush=True)
        for n in horizons:
            results['horizons'] += _beside_peer(n, paper, variants, max_steps)
    if 'obstacles' in sections:
        results['obstacles'] = []
        print("\nN = 10 with more obstacles (reach: most obstacles within the horizon's reach "
              'at once, all checked; active: most held in the NLP at once)')
        print(HEADER, flush=True)
        path = paper_sinusoid()
        for count in OBSTACLE_COUNTS:
            obstacles = paper + extra_obstacles(count - 1, path)
            results['obstacles'] += _beside_peer(10, obstacles, variants, max_steps)

    if 'rrt' in sections:
        rrt = bench_rrt(3 if args.quick else 10)
        results['rrt'] = rrt
        print(f"\nRRT* 1000 iterations on rrt_cluttered.yaml: median "
              f"{rrt['plan_ms']['median']:.1f} ms, p95 {rrt['plan_ms']['p95']:.1f} ms over "
              f"{rrt['plans']} seeds", flush=True)

    if 'perception' in sections:
        poses = 50 if args.quick else 200
        laser = bench_laser(poses)
        scan = bench_scan_obstacles(poses)
        control = bench_scan_control(60 if args.quick else 400)
        results['perception'] = {'laser': laser, 'scan_obstacles': scan,
                                 'control_step': control}
        print('\nperception and the control step with scan obstacles, ms (median, p95, max)')
        for line in _perception_lines(laser, scan, control):
            print(line, flush=True)

    if 'footprint' in sections:
        # --quick: 60 steps a row, short of the goals (the Jackal needs about 80 steps on the
        # paper's box and 170 on BARN world 0), so 'goal' says cap there
        steps = dict.fromkeys(FOOTPRINT_SCENARIOS, 60 if args.quick else 400)
        steps['paper'] = 60 if args.quick else 250
        if footprint_steps is not None:
            steps = dict.fromkeys(steps, footprint_steps)
        print(f'\npolygon footprint: the Jackal (core/footprint.JACKAL, '
              f'{_extent(JACKAL)}), N = {FOOTPRINT_HORIZON}, ms over the timed run after an '
              f"untimed warm-up; targets (the footprint work's, on this machine as loaded "
              f'now): solve median <= {TARGET_FOOTPRINT_SOLVE_MS:g} ms, whole step median <= '
              f'{TARGET_FOOTPRINT_STEP_MS:g} ms; goal: yes, or cap when the step cap came '
              'first; nsv = steps without a verified solver solution', flush=True)
        rows = [bench_footprint(scenario, steps[scenario], compile_functions=footprint_compile)
                for scenario in FOOTPRINT_SCENARIOS]
        results['footprint'] = rows
        for line in _footprint_lines(rows):
            print(line, flush=True)

    if 'rate' in sections:
        calls = rate_calls if rate_calls is not None else (240 if args.quick else 1000)
        print(f'\ncontrol rate: MpcController.compute at {CONTROL_FREQUENCY:g} Hz in closed '
              f'loop, the MPC solving once per step h = {STEP:g} s, ms per call after an '
              'untimed warm-up', flush=True)
        rate = bench_control_rate(calls, compile_functions=rate_compile)
        results['rate'] = rate
        for line in _rate_lines(rate):
            print(line, flush=True)

    if 'cold_start' in sections:
        cold = bench_cold_start(1 if args.quick else 3, controllers=cold_start_controllers)
        results['cold_start'] = cold
        for line in _cold_start_lines(cold):
            print(line, flush=True)

    if 'barn' in sections:
        print("\nhard BARN states: the control step replayed on the paper's MPC's recorded "
              'runs, ms (median, p99, max)', flush=True)
        barn = bench_barn(BARN_WORLDS[:1] if args.quick else BARN_WORLDS,
                          max_steps=QUICK_BARN_STEPS if args.quick else None)
        results['barn'] = barn
        for line in barn_lines(barn):
            print(line, flush=True)

    results['machine']['load_average_after'] = list(os.getloadavg())
    print('\nload average (1, 5, 15 min) before: '
          + ', '.join(f'{v:.2f}' for v in results['machine']['load_average_before'])
          + '; after: ' + ', '.join(f'{v:.2f}' for v in results['machine']['load_average_after'])
          + f" on {results['machine']['cpus']} CPUs", flush=True)
    with open(args.out, 'w', encoding='utf-8') as f:
        json.dump(results, f, indent=2)
    print(f'\nwrote {args.out}')
    return 0


def _cold_start_lines(result: dict[str, Any]) -> list[str]:
    cold, warm = result['cold_s'], result['warm_s']
    verdict = 'OK' if cold['median'] <= result['target_cold_s'] else 'NO'
    return [
        f"\ncold start: {result['command']} (gcc {' '.join(result['compile_flags'])}; "
        f"without obstacles {' '.join(result['no_obstacle_compile_flags'])}), "
        f"medians over {result['repeats']} fresh cache folder(s)",
        f"  cold (empty cache): {cold['median']:.1f} s (max {cold['max']:.1f} s; target "
        f"{result['target_cold_s']:g} s: {verdict}), "
        f"solve median {result['cold_solve_ms_median']:.2f} ms, "
        f"{int(np.median(result['libraries_after_cold']))} libraries compiled by its end",
        f"  warm (cache present): {warm['median']:.1f} s (max {warm['max']:.1f} s), "
        f"solve median {result['warm_solve_ms_median']:.2f} ms",
    ]


def _extent(footprint: Footprint) -> str:
    """Say a footprint's size as length x width (m), for the table's title."""
    vertices = np.asarray(footprint.vertices)
    length, width = np.ptp(vertices, axis=0)
    return f'{length:.3f} m x {width:.3f} m'


if __name__ == '__main__':
    sys.exit(main())
