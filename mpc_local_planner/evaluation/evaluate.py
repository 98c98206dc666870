# SPDX-License-Identifier: Apache-2.0
"""Evidence at scale: the paper's MPC beside baselines on random worlds and BARN worlds.

``python -m mpc_local_planner.evaluation.evaluate --suite {random,barn,unknown,worlds,dynamic}
--out DIR --jobs K``

With sensing (``--suite unknown``, ``--suite worlds --sensing``, ``--suite barn --sensing``,
``--suite dynamic``: DynaBARN-like worlds whose cylinders move, `dynamic_worlds`)
every run is the navigation stack of `sensing_suites` (laser, obstacle memory, re-planning
planner, local controller; ``--robot circle|jackal``); see that module for the suites. The
suites below are the easier "known map" setting: every obstacle known, the reference path
planned once (their worlds are built in `known_map_worlds`).

- random: ``--count`` worlds from ``--seed``: random convex obstacles between start (0, 0, 0)
  and goal (6, 0, 0), the first one across the straight line; the reference path from RRT*
  (seeded from the world). Each world records whether its path satisfies the paper's
  Assumption 1 (every segment clear of the obstacles inflated as the MPC inflates them:
  robot radius plus collision margin; start and goal clear). Success: within
  RANDOM_GOAL_TOLERANCE of the goal position, with no collision, before the time limit.
- barn: the BARN worlds ``--worlds`` (e.g. 0-99,200-299) from ``--barn-dir``: robot radius 0.2 m,
  success as the challenge defines it (within the file's goal tolerance of the goal before
  its time limit, no contact). Contact is measured from the exact cylinders (circles), not
  the octagons the MPC and the planner use. Score: the challenge's, success * t_opt /
  clip(t, 2 t_opt, 8 t_opt), t_opt = barn_path_length / 2, with the full reference path
  (start -> path file -> goal; see barn_score).

Controllers: ``proposed`` (PathReferenceMPC on the RRT* WaypointPath), ``tracking`` (the
TrackingMPC baseline, target only) and ``pure_pursuit`` (lookahead pure pursuit of the same
polyline, no obstacle constraints); with sensing also ``dwa`` (Nav2 DWB's critics) and
``regulated_pure_pursuit`` (Nav2's RPP: curvature-regulated speed, velocity-scaled
lookahead, collision detection on the sensed obstacles). Each run is an evaluation.rollout:
it stops at success (position only), at first contact, at the time limit, or after
STALL_STEPS steps standing still; the ``stop_reason`` column holds the rollout's Outcome
value.

Reproducible: the MPCs bound a control step's solving by solver iterations
(``--budget iterations``, the default: SolverSettings.budget, the wall budget's worth on a typical
machine), so the same command gives the same runs on any machine under any load; ``--budget
wall`` bounds it by wall time as the robot does, on this machine as loaded now (four such
runs of BARN with sensing at 2 m/s gave 95 to 98 successes).

Writes ``runs.csv`` (one row per world x controller, appended as runs finish, sorted by world
and controller at the end), ``summary.md`` (one table row per controller) and
``settings.json`` (what decides the rows). With ``--save-trajectories``, the runs go to
``OUT/trajectories`` and ``--plot 0,1,2`` later draws those worlds in ``OUT/<suite>_runs.png``;
for the navigation suites ``--plot`` runs the worlds again (the runs are deterministic) and
draws them in ``OUT/<suite>_sensing_runs.png`` (`plot_navigation_suite`); for the dynamic
suite, a strip of frames per world and a row per controller in
``OUT/dynamic_strip_<world>.png`` (`plot_dynamic_suite`).

Where the runs run (`sweep`): ``--jobs K`` local processes, or ``--executor dask`` on a Dask
cluster (``--scheduler tcp://HOST:8786``; without it a LocalCluster of K processes); the rows
are the same. A stopped sweep is continued with ``--resume``: the runs in ``OUT/runs.csv``
made with the same settings are kept and only the others run.

This module is the command (its options, the sweep, the summary and the figures); one run,
a `Task` to its row, is `suite_runs`'.
"""

from __future__ import annotations

import argparse
from contextlib import ExitStack
import csv
from dataclasses import asdict, replace
import json
import math
import os
from pathlib import Path
import sys
import time
from typing import Any, Sequence

import numpy as np

from mpc_local_planner.core.config import BUDGETS
from mpc_local_planner.core.controllers import ControllerName
from mpc_local_planner.evaluation.dynamic_worlds import DYNAMIC_WORLDS
from mpc_local_planner.evaluation.plotting import plot_world_panels, WorldPanel
from mpc_local_planner.evaluation.rollout import EVALUATION_BUDGET
from mpc_local_planner.evaluation.run_row import RunRow
from mpc_local_planner.evaluation.suite_runs import (
    CONTROLLERS,
    CSV_COLUMNS,
    DEFAULT_BARN_DIR,
    drive_task,
    empty_row,
    KNOWN_MAP_CONTROLLERS,
    NAVIGATION_SUITES,
    navigation_world,
    parse_worlds,
    run_task,
    saved_world_path,
    SUITES,
    Task,
)
from mpc_local_planner.evaluation.sweep import (
    EXECUTORS,
    ExecutorUnavailable,
    open_executor,
    Runner,
    RunTable,
    SettingsMismatch,
)
from mpc_local_planner.evaluation.trajectory import read_trajectory_csv
from mpc_local_planner.sim.physics import mujoco_missing, PLANTS
from mpc_local_planner.sim.reality import REALITY_PRESETS

__all__ = [
    'main',
    'plot_navigation_suite',
    'plot_suite_runs',
    'summarize',
    'sweep_settings',
]


def _fmt(value: Any, digits: int = 2) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return '-'
    if isinstance(value, float):
        return f'{value:.{digits}f}'
    return str(value)


def _floats(rows: list[RunRow], key: str) -> np.ndarray:
    values = []
    for r in rows:
        value = getattr(r, key)
        if value is not None:
            values.append(float(value))
    values = np.array(values, dtype=float)
    return values[np.isfinite(values)]


def summarize(rows: list[RunRow], *, suite: str, title: str = '') -> str:
    """Return the Markdown summary: one table row per controller."""
    lines = [f'# {title or suite} suite', '']
    worlds = sorted({r.world for r in rows})
    a1 = {r.world for r in rows if r.assumption_1}
    if a1:
        lines.append(f'Worlds: {len(worlds)}; reference path satisfies Assumption 1 in '
                     f'{len(a1 & set(worlds))} of them.')
    else:
        lines.append(f'Worlds: {len(worlds)}; paths planned and re-planned during the runs '
                     '(Assumption 1 is not checked ahead).')
    lines.append('')
    head = ['controller', 'runs', 'success', 'rate', 'contacts', 'success (Assumption 1)',
            're-plans', 'median time [s]', 'median path [m]', 'median step [ms]',
            'max step [ms]', 'median solve [ms]', 'p95 of medians [ms]', 'max solve [ms]']
    if suite == 'barn':
        head.append('mean BARN score')
    lines += ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    order = [c for c in CONTROLLERS if any(r.controller is c for r in rows)]
    for name in order:
        mine = [r for r in rows if r.controller is name]
        ok = [r for r in mine if r.success]
        mine_a1 = [r for r in mine if r.assumption_1]
        ok_a1 = [r for r in mine_a1 if r.success]
        times = _floats(ok, 'time')
        paths = _floats(ok, 'path_length')
        med = _floats(mine, 'solve_ms_median')
        worst = _floats(mine, 'solve_ms_max')
        step_med = _floats(mine, 'step_ms_median')
        step_max = _floats(mine, 'step_ms_max')
        replans = _floats(mine, 'replans')
        cells = [
            str(name), str(len(mine)), str(len(ok)), f'{len(ok) / max(1, len(mine)):.1%}',
            str(sum(bool(r.collision) for r in mine)), f'{len(ok_a1)}/{len(mine_a1)}',
            str(int(np.sum(replans))) if len(replans) else '-',
            _fmt(float(np.median(times)) if len(times) else None, 1),
            _fmt(float(np.median(paths)) if len(paths) else None, 2),
            _fmt(float(np.median(step_med)) if len(step_med) else None, 2),
            _fmt(float(np.max(step_max)) if len(step_max) else None, 1),
            _fmt(float(np.median(med)) if len(med) else None, 2),
            _fmt(float(np.percentile(med, 95)) if len(med) else None, 2),
            _fmt(float(np.max(worst)) if len(worst) else None, 1),
        ]
        if suite == 'barn':
            scores = _floats(mine, 'barn_score')
            cells.append(_fmt(float(np.mean(scores)) if len(scores) else None, 4))
        lines.append('| ' + ' | '.join(cells) + ' |')
    lines.append('')
    if any(r.recoveries is not None for r in rows):
        lines += [_recovery_line(rows, order), '']
    if suite == 'dynamic':
        lines += [_contact_kinds_line(rows, order), '']
    reasons: dict[ControllerName, dict[str, int]] = {}
    for r in rows:
        key = r.stop_reason.split(':')[0]
        reasons.setdefault(r.controller, {}).setdefault(key, 0)
        reasons[r.controller][key] += 1
    lines.append('Stop reasons: ' + '; '.join(
        f'{c}: ' + ', '.join(f'{k} {v}' for k, v in sorted(reasons[c].items()))
        for c in order))
    failed = sorted(r.world for r in rows
                    if r.controller is ControllerName.PROPOSED and not r.success)
    if failed:
        lines.append('')
        lines.append('Proposed MPC failed in worlds: ' + ', '.join(map(str, failed)))
    return '\n'.join(lines) + '\n'


def _contact_kinds_line(rows: list[RunRow], order: list[ControllerName]) -> str:
    """Say, per controller, its runs with an active and with a passive contact (DynaBARN's)."""
    parts = [f'{name}: {sum(bool(r.active_contacts) for r in rows if r.controller is name)} '
             f'active, {sum(bool(r.passive_contacts) for r in rows if r.controller is name)} '
             'passive' for name in order]
    return ('Contacts (runs; active: the robot was moving into it, passive: it stood and '
            'was run into): ' + '; '.join(parts) + '.')


def _recovery_line(rows: list[RunRow], order: list[ControllerName]) -> str:
    """Say, per controller, how many runs needed a recovery, how many, how long, how they ended."""
    parts = []
    for name in order:
        needed = [r for r in rows if r.controller is name and r.recoveries]
        if not needed:
            parts.append(f'{name}: none')
            continue
        seconds = [float(r.recovery_s or 0.0) for r in needed]
        started = sum(r.recoveries or 0 for r in needed)
        parts.append(f'{name}: {len(needed)} runs needed one ({started} in all, median '
                     f'{np.median(seconds):.1f} s per run), '
                     f'{sum(bool(r.success) for r in needed)} of them reached')
    return 'Recoveries (back out, spin, wait): ' + '; '.join(parts) + '.'


def _panel(out: Path, suite: str, world: int, barn_dir: Path,
           rows: dict[tuple[int, ControllerName], RunRow]) -> WorldPanel:
    """Return the figure panel of one world of an earlier run with --save-trajectories."""
    folder = out / 'trajectories'
    if suite == 'barn':
        data = json.loads((barn_dir / f'world_{world:03d}.json').read_text(encoding='utf-8'))
        polygons: list[np.ndarray] = []
        circles = np.asarray(data['cylinders'], dtype=float).reshape(-1, 2)
        radius = float(data['cylinder_radius'])
        bounds = None
        name = f'BARN world {world}'
    else:
        data = json.loads(saved_world_path(folder, world).read_text(encoding='utf-8'))
        polygons = [np.asarray(v, dtype=float) for v in data['obstacles']]
        circles, radius = None, 0.0
        bounds = tuple(data['bounds'])
        name = f'random world {world}'
    path_file = folder / f'path_{world:03d}.csv'
    reference = (np.loadtxt(path_file, delimiter=',', skiprows=1, ndmin=2)
                 if path_file.is_file() else None)
    runs, outcomes = [], []
    for controller in CONTROLLERS:
        run = folder / f'{controller}_{world:03d}.csv'
        if not run.is_file():
            continue
        row = rows.get((world, controller))
        reached = bool(row is not None and row.success)
        reason = row.stop_reason if row is not None else '?'
        runs.append((str(controller), read_trajectory_csv(run), reached))
        outcomes.append(f"{controller}: {reason.split(':')[0]}")
    return WorldPanel(
        title='\n'.join([name, *outcomes]), polygons=polygons, circles=circles,
        circle_radius=radius, start=np.asarray(data['start'], dtype=float),
        goal=np.asarray(data['goal'], dtype=float),
        goal_tolerance=float(data.get('goal_tolerance', 1.0)), reference=reference, runs=runs,
        bounds=bounds)


def plot_suite_runs(out: Path, suite: str, worlds: Sequence[int], *,
                    barn_dir: Path = DEFAULT_BARN_DIR) -> Path:
    """Draw the saved runs of some worlds (obstacles, reference path, trajectories) in a PNG.

    Reads ``OUT/runs.csv`` and ``OUT/trajectories`` (written with --save-trajectories) and
    writes ``OUT/barn_runs.png`` or ``OUT/random_runs.png``.

    Raises:
        FileNotFoundError: if the run's files for a world are missing.

    """
    folder = out / 'trajectories'
    runs_csv = out / 'runs.csv'
    needed = [runs_csv] + ([saved_world_path(folder, w) for w in worlds] if suite == 'random'
                           else [folder])
    missing = [str(p) for p in needed if not p.exists()]
    if missing:
        msg = (f'{", ".join(missing[:3])} not found: run the {suite} suite with '
               f'--save-trajectories and --out {out} first')
        raise FileNotFoundError(msg)
    rows = {r.key: r for r in _read_rows(runs_csv)}
    panels = [_panel(out, suite, w, barn_dir, rows) for w in worlds]
    if suite == 'barn':
        title = 'BARN worlds: RRT* reference and closed loops (circle robot, known map)'
        size = (2.4, 7.0)
    else:
        title = 'Random worlds: RRT* reference and closed loops'
        size = (4.6, 3.8)
    target = out / f'{suite}_runs.png'
    plot_world_panels(target, panels, title=title, panel_size=size,
                      columns=5 if suite == 'barn' else 3)
    return target


def plot_dynamic_suite(out: Path, template: Task, worlds: Sequence[int],
                       controllers: Sequence[str]) -> list[Path]:
    """Run some dynamic worlds again with each controller; draw each as a strip of frames.

    The runs are the sweep's (deterministic, `drive_task`). Writes
    OUT/dynamic_strip_<world>.png per world (dynamic_strip.py): one row per controller.
    """
    from mpc_local_planner.evaluation.dynamic_strip import plot_dynamic_strip

    written = []
    for w in worlds:
        # the world and the robot are the task's, whichever controller drives it
        robot, world, _ = navigation_world(replace(template, world=w))
        runs = [(controller, drive_task(replace(template, world=w, controller=controller),
                                        robot, world).run)
                for controller in controllers]
        written.append(plot_dynamic_strip(
            out / f'dynamic_strip_{w:03d}.png', world, runs, footprint=robot.footprint,
            title=f'dynamic world {w}: {len(world.moving_obstacles)} moving obstacles'))
    return written


def plot_navigation_suite(out: Path, template: Task, worlds: Sequence[int],
                          world_files: Sequence[str] = ()) -> Path:
    """Run some worlds of a navigation suite again and draw them (sensing_suites' figure).

    The runs are deterministic: the same world, robot, controller (template.controller),
    seed, budget and reality as the sweep's give the same run. Writes
    OUT/<suite>_sensing_runs.png.

    Args:
        out: The output folder.
        template: The sweep's settings (world and world_file are set per world).
        worlds: The worlds to draw (for the worlds suite: indices into world_files).
        world_files: The worlds suite's files, sorted as the sweep numbers them.

    """
    from mpc_local_planner.evaluation import sensing_suites as suites

    panels = []
    robot = None
    for w in worlds:
        task = replace(template, world=w, world_file=world_files[w] if world_files else '')
        robot, world, _ = navigation_world(task)
        title = f'BARN world {w}' if template.suite == 'barn' else f'{world.name} ({w})'
        panels.append((title, world))
    assert robot is not None, 'no world to draw'
    return suites.plot_navigation_runs(
        out / f'{template.suite}_sensing_runs.png', panels, template.controller, robot,
        seed=template.seed, setup=suites.MpcSetup(budget=template.budget,
                                                  compile=template.compile),
        reality=template.reality, localized=template.suite != 'barn', plant=template.plant,
        recoveries=template.recoveries, track_moving=template.track_moving)


def _read_rows(path: Path) -> list[RunRow]:
    with open(path, newline='') as stream:
        return [RunRow.from_csv(cells) for cells in csv.DictReader(stream)]


def main(argv: Sequence[str] | None = None) -> int:
    """Run the suite and write runs.csv and summary.md."""
    parser = argparse.ArgumentParser(prog='python -m mpc_local_planner.evaluation.evaluate',
                                     description=__doc__.split('\n\n')[0])
    parser.add_argument('--suite', choices=SUITES, required=True)
    parser.add_argument('--count', type=int, default=None,
                        help='random or unknown worlds (default 200), dynamic worlds '
                             f"(default {DYNAMIC_WORLDS}, DynaBARN's number)")
    parser.add_argument('--sensing', action='store_true',
                        help='barn, worlds: laser only for what the map lacks (barn: no prior '
                        'map), with the re-planning planner (unknown: always)')
    parser.add_argument('--robot', choices=('circle', 'jackal'), default='circle',
                        help='with sensing: a 0.2 m circle at 0.31 m/s, or the BARN Jackal '
                        '(its rectangle and its own limits, 2.0 m/s and 4.0 rad/s, as '
                        'config/jackal.yaml)')
    parser.add_argument('--world-dir', type=Path, default=None,
                        help='worlds: the folder of world YAML files')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--worlds', default='0-99', help='BARN worlds, e.g. 0-99 or 3,7,10-12')
    parser.add_argument('--barn-dir', type=Path, default=DEFAULT_BARN_DIR)
    parser.add_argument('--controllers', default=None,
                        help=f'comma-separated, of {",".join(CONTROLLERS)} (default: all the '
                        'suite runs; the known-map suites have no dwa)')
    parser.add_argument('--v-max', type=float, default=None,
                        help="m/s (default 0.31; with sensing, the robot's: --robot)")
    parser.add_argument('--omega-max', type=float, default=None,
                        help="rad/s (default 1.9; with sensing, the robot's: --robot)")
    parser.add_argument('--out', type=Path, required=True,
                        help='the output folder: runs.csv, summary.md, settings.json (an '
                        "earlier sweep's files there are overwritten unless --resume)")
    parser.add_argument('--jobs', type=int, default=1,
                        help='worker processes: local ones, or those of the Dask LocalCluster '
                        'that --executor dask starts without --scheduler')
    parser.add_argument('--executor', choices=EXECUTORS, default='local',
                        help="where the runs run: this machine's processes, or a Dask "
                        "cluster (pip install '.[cluster]'); the rows are the same")
    parser.add_argument('--scheduler', default=None, metavar='ADDRESS',
                        help='with --executor dask: the scheduler of a running cluster, e.g. '
                        'tcp://SCHEDULER_HOST:8786 (its workers started with --nthreads 1)')
    parser.add_argument('--resume', action='store_true',
                        help='keep the runs already in OUT/runs.csv (made with the same '
                        'settings, else refused) and run only the others')
    parser.add_argument('--budget', choices=BUDGETS, default=EVALUATION_BUDGET,
                        help='what bounds an MPC step: solver iterations (reproducible, the '
                        "default) or wall time (the robot's; outcomes move with the load)")
    parser.add_argument('--compile', action=argparse.BooleanOptionalAction, default=True,
                        help="compile the NLPs' functions with gcc (SolverSettings.compile, the "
                        "default); --no-compile runs CasADi's interpreted functions: the "
                        "same solutions, slower solves, no C compiler and no wait for it")
    parser.add_argument('--reality', choices=tuple(REALITY_PRESETS), default='ideal',
                        help='how real the robot is (sim/reality.py presets): lag, latency, '
                             'acceleration limits, odometry noise and drift, laser noise and '
                             'dropouts; navigation suites only')
    parser.add_argument('--through-nodes', action='store_true',
                        help="BARN, unknown or dynamic with sensing: the paper's MPC runs "
                             'through the real node processes over DDS (closed_loop, lockstep '
                             "clock, the package's parameter files as shipped; runs in "
                             'OUT/nodes/), the other controllers in process beside it')
    parser.add_argument('--plant', choices=PLANTS, default='kinematic',
                        help="the robot's plant: kinematic (the default) or mujoco (rigid "
                             'body, wheels, slip: the [physics] extra); navigation suites only')
    parser.add_argument('--recoveries', action='store_true',
                        help='run the recovery behaviours around every controller (back out '
                             "along the robot's trail, spin, wait for a re-plan; "
                             'core/recoveries.py), as the controller node does by default; '
                             'navigation suites only')
    parser.add_argument('--track-moving', action='store_true',
                        help="the controller's obstacle memory tracks the scans' small "
                             'clusters and forgets what moving ones built, so that a walker '
                             'leaves no trail (perception/tracking.py; through the nodes: '
                             "both nodes' track_moving); navigation suites only")
    parser.add_argument('--save-trajectories', action='store_true',
                        help='write each run as trajectory CSV under OUT/trajectories')
    parser.add_argument('--merge', action='store_true',
                        help='BARN: merge rows of touching cylinders into rectangles')
    parser.add_argument('--plot', default='',
                        help='only draw these worlds (e.g. 0,10,50), then exit: of an earlier '
                        'run of a known-map suite with --save-trajectories in OUT; with '
                        'sensing (unknown, worlds, barn --sensing) the first of --controllers '
                        'runs them again (the runs are deterministic) into '
                        'OUT/<suite>_sensing_runs.png')
    args = parser.parse_args(argv)
    navigation = args.sensing or args.suite in NAVIGATION_SUITES
    if args.plot and not navigation:
        try:
            target = plot_suite_runs(args.out, args.suite, parse_worlds(args.plot),
                                     barn_dir=args.barn_dir)
        except FileNotFoundError as err:
            parser.error(str(err))
        print(target)
        return 0

    if args.scheduler and args.executor != 'dask':
        parser.error('--scheduler needs --executor dask')
    if navigation:
        from mpc_local_planner.evaluation.sensing_suites import ROBOTS

        chosen = ROBOTS[args.robot]
        args.v_max = chosen.v_max if args.v_max is None else args.v_max
        args.omega_max = chosen.omega_max if args.omega_max is None else args.omega_max
    else:
        args.v_max = 0.31 if args.v_max is None else args.v_max
        args.omega_max = 1.9 if args.omega_max is None else args.omega_max
    if args.through_nodes and not (navigation and args.suite in ('barn', 'unknown', 'dynamic')):
        parser.error('--through-nodes needs --suite barn --sensing, --suite unknown or '
                     '--suite dynamic')
    if args.sensing and args.suite == 'random':
        parser.error('--sensing: use --suite unknown for random worlds with unknown obstacles')
    if args.robot != 'circle' and not navigation:
        parser.error('--robot jackal needs the navigation stack: add --sensing')
    if args.reality != 'ideal' and not navigation:
        parser.error('--reality needs the navigation stack (--suite unknown, --suite worlds '
                     'or --sensing): the known-map suites follow a fixed path on the model')
    if args.plant != 'kinematic' and not navigation:
        parser.error('--plant needs the navigation stack (--suite unknown, --suite worlds or '
                     '--sensing)')
    if args.track_moving and not navigation:
        parser.error('--track-moving needs the navigation stack (--suite unknown, --suite '
                     'worlds, --suite dynamic or --sensing)')
    if args.recoveries and not navigation:
        parser.error('--recoveries needs the navigation stack (--suite unknown, --suite worlds '
                     'or --sensing)')
    if args.plant == 'mujoco' and mujoco_missing() is not None:
        parser.error(f'--plant mujoco: {mujoco_missing()}')
    allowed = CONTROLLERS if navigation else KNOWN_MAP_CONTROLLERS
    controllers = ([c.strip() for c in args.controllers.split(',') if c.strip()]
                   if args.controllers else list(allowed))
    unknown = sorted(set(controllers) - set(allowed))
    if unknown:
        parser.error(f'unknown controllers {unknown} for this suite; choose from {allowed}')
    world_files: list[str] = []
    if args.count is None:
        args.count = DYNAMIC_WORLDS if args.suite == 'dynamic' else 200
    if args.suite in ('random', 'unknown', 'dynamic'):
        worlds = list(range(args.count))
        barn_dir = ''
    elif args.suite == 'worlds':
        if args.world_dir is None or not args.world_dir.is_dir():
            parser.error('--suite worlds needs --world-dir DIR (a folder of world YAML files)')
        world_files = sorted(str(f.resolve()) for f in args.world_dir.glob('*.yaml'))
        if not world_files:
            parser.error(f'no *.yaml world files in {args.world_dir}')
        worlds = list(range(len(world_files)))
        barn_dir = ''
    else:
        worlds = parse_worlds(args.worlds)
        barn_dir = str(args.barn_dir.resolve())
        missing = [w for w in worlds if not (args.barn_dir / f'world_{w:03d}.json').is_file()]
        if missing:
            parser.error(f'BARN worlds not found in {args.barn_dir}: {missing[:10]}')
    if args.plot:  # with sensing: run the worlds again and draw them
        drawn = parse_worlds(args.plot)
        if args.suite == 'barn':
            absent = [w for w in drawn if not (args.barn_dir / f'world_{w:03d}.json').is_file()]
        else:
            count = len(world_files) if args.suite == 'worlds' else args.count
            absent = [w for w in drawn if not 0 <= w < count]
        if absent:
            parser.error(f'--plot: no world {absent[:10]} in the {args.suite} suite')
        template = Task(args.suite, 0, controllers[0], args.seed, args.v_max, args.omega_max,
                        str(args.barn_dir.resolve()), '', args.merge, sensing=args.sensing,
                        robot=args.robot, budget=args.budget, compile=args.compile,
                        reality=args.reality, plant=args.plant, recoveries=args.recoveries,
                        track_moving=args.track_moving)
        if args.suite == 'dynamic':  # obstacles that move: a strip of frames per world
            for target in plot_dynamic_suite(args.out, template, drawn, controllers):
                print(target)
            return 0
        print(plot_navigation_suite(args.out, template, drawn, world_files))
        return 0
    args.out.mkdir(parents=True, exist_ok=True)
    trajectories = str((args.out / 'trajectories').resolve()) if args.save_trajectories else ''
    if barn_dir and Path(barn_dir).resolve() == Path(DEFAULT_BARN_DIR).resolve():
        barn_dir = ''  # the shipped worlds: each worker finds its own copy
    template = Task(args.suite, 0, '', args.seed, args.v_max, args.omega_max, barn_dir,
                    trajectories, args.merge, sensing=args.sensing, robot=args.robot,
                    budget=args.budget, compile=args.compile, reality=args.reality,
                    plant=args.plant, recoveries=args.recoveries,
                    track_moving=args.track_moving)
    nodes = str((args.out / 'nodes').resolve()) if args.through_nodes else ''
    tasks = [replace(template, world=w, controller=c,
                     world_file=world_files[w] if world_files else '',
                     through_nodes=nodes if c == 'proposed' else '')
             for w in worlds for c in controllers]
    settings = sweep_settings(template, worlds, controllers, world_files)
    for var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
        os.environ[var] = '1'

    if navigation:
        title = (f'{args.suite} with sensing (laser, re-planning; seed {args.seed}, '
                 f'{args.robot} robot, v_max {args.v_max:g} m/s, omega_max '
                 f'{args.omega_max:g} rad/s'
                 + (', no prior map' if args.suite == 'barn' else '')
                 + f', {args.budget} budget, reality {args.reality}'
                 + (f', {args.plant} plant' if args.plant != 'kinematic' else '')
                 + (', recoveries' if args.recoveries else '')
                 + (', moving clusters tracked' if args.track_moving else '')
                 + (", the paper's MPC through the nodes" if args.through_nodes else '') + ')')
    else:
        title = (f'{args.suite}, known map (seed {args.seed}, v_max {args.v_max:g} m/s, '
                 f'omega_max {args.omega_max:g} rad/s{", merged walls" if args.merge else ""}'
                 f', {args.budget} budget)')
    table = RunTable(args.out, CSV_COLUMNS)
    with ExitStack() as stack:
        # what can refuse the sweep, before the table is touched
        try:
            done = [RunRow.from_csv(cells) for cells in
                    table.earlier_rows(settings, keep=_finished_row)] if args.resume else []
            run = stack.enter_context(open_executor(args.executor, jobs=args.jobs,
                                                    scheduler=args.scheduler))
        except (ExecutorUnavailable, SettingsMismatch) as err:
            parser.exit(2, f'{parser.prog}: error: {err}\n')
        table.start(settings, [row.to_csv() for row in done])
        try:
            rows = _sweep(run, tasks, done, table, suite=args.suite, title=title)
        finally:
            table.close()
    table.finish([row.to_csv() for row in rows])
    summary = summarize(rows, suite=args.suite, title=title)
    (args.out / 'summary.md').write_text(summary)
    print(summary)
    print(f'wrote {table.csv_path} and {args.out / "summary.md"}', file=sys.stderr)
    return 0


def sweep_settings(template: Task, worlds: Sequence[int], controllers: Sequence[str],
                   world_files: Sequence[str]) -> dict[str, Any]:
    """Return what decides a sweep's rows, as OUT/settings.json records it for --resume.

    Everything a Task holds but the run itself (world, controller) and where its files go,
    and the worlds and controllers of the sweep.
    """
    settings = {k: v for k, v in asdict(template).items() if k not in _PER_RUN_FIELDS}
    settings.update(worlds=list(worlds), controllers=list(controllers),
                    world_files=list(world_files), columns=list(CSV_COLUMNS))
    return settings


# A Task's fields that name one run of a sweep or where its files go, not its settings.
_PER_RUN_FIELDS = ('world', 'controller', 'world_file', 'trajectory_dir')


def _finished_row(row: dict[str, str]) -> bool:
    """Tell whether a row of an earlier sweep is a finished run (an error is tried again)."""
    return not str(row['stop_reason']).startswith('error:')


def _canonical_order(row: RunRow) -> tuple[int, int]:
    return row.world, CONTROLLERS.index(row.controller)


def _sweep(run: Runner, tasks: Sequence[Task], done: list[RunRow], table: RunTable, *,
           suite: str, title: str) -> list[RunRow]:
    """Run the tasks without a row in ``done``, append each row as it comes; return all rows.

    The rows come back in the canonical order (world, then controller), whichever executor
    ran them and in whatever order they finished.
    """
    finished = {row.key for row in done}
    todo = [t for t in tasks if (t.world, t.controller) not in finished]
    rows = list(done)
    summary_path = table.folder / 'summary.md'
    started = time.monotonic()
    if done:
        print(f'resuming: {len(done)} of {len(tasks)} runs already in {table.csv_path}',
              file=sys.stderr, flush=True)
    for index, result in run(run_task, todo):
        if isinstance(result, BaseException):
            result = empty_row(todo[index], None,
                                f'error: {type(result).__name__}: {result}')
        rows.append(result)
        table.append(result.to_csv())
        _progress(result, len(rows), len(tasks), time.monotonic() - started)
        if len(rows) % 10 == 0:
            summary_path.write_text(summarize(rows, suite=suite, title=title))
    rows.sort(key=_canonical_order)
    return rows


def _progress(row: RunRow, done: int, total: int, elapsed: float) -> None:
    """Draw the progress bar line of a finished run on stderr."""
    filled = int(30 * done / max(total, 1))
    print(f"[{'#' * filled}{'.' * (30 - filled)}] {done}/{total} "
          f"{elapsed:6.0f} s  {row.controller!s:12s} world {row.world:3d}: "
          f"{'ok' if row.success else 'FAIL'} ({row.stop_reason})",
          file=sys.stderr, flush=True)


if __name__ == '__main__':
    # Run main() of the module imported by name, not of __main__: Dask pickles what __main__
    # defines by value, so each task would carry its own copy of the MPC caches.
    from mpc_local_planner.evaluation import evaluate

    sys.exit(evaluate.main())
