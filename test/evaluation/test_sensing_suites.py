# SPDX-License-Identifier: Apache-2.0
"""The navigation stack without DDS and the suites with sensing (laser, re-planning)."""

from __future__ import annotations

import csv
import dataclasses

import numpy as np
import pytest

from mpc_local_planner.core.controllers import ControllerName
from mpc_local_planner.core.footprint import JACKAL
from mpc_local_planner.evaluation import evaluate, suite_runs
from mpc_local_planner.evaluation import sensing_suites as suites
from mpc_local_planner.evaluation.rollout import Outcome
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import load_world

CIRCLE = suites.ROBOTS['circle']


def along(route: np.ndarray) -> np.ndarray:
    """Return points along a polyline (200 per segment)."""
    return np.concatenate([np.linspace(a, b, 200)
                           for a, b in zip(route[:-1], route[1:], strict=True)])


def test_unknown_worlds_are_reproducible_and_their_first_plan_meets_an_unknown_obstacle() -> None:
    world = suites.unknown_world(0, 0)
    again = suites.unknown_world(0, 0)
    assert 1 <= len(world.unknown_obstacles) <= 3
    assert all(np.allclose(a.vertices, b.vertices)
               for a, b in zip(world.unknown_obstacles, again.unknown_obstacles, strict=True))
    # the navigator's first plan, on the map of the known obstacles only, crosses one
    known = suites.rasterize_world(world, suites.MAP_RESOLUTION)
    _, planner = suites._grid_planner(known, CIRCLE, world.bounds, 0)
    route = planner.plan(world.start, world.goal)
    assert any(np.any(o.contains(along(route))) for o in world.unknown_obstacles)


@pytest.mark.parametrize('controller', ['proposed', 'dwa', 'regulated_pure_pursuit'])
def test_the_laser_reveals_what_the_map_lacks_and_the_planner_replans_around_it(
        controller: str) -> None:
    world = load_world(resolve_data_file('unknown_box.yaml'))
    # interpreted: the compiled functions' solutions, without gcc's wait on a fresh machine
    result = suites.run_navigation(world, controller, CIRCLE, prepare=False,
                                   setup=suites.MpcSetup(compile=False))
    assert result.run.outcome is Outcome.REACHED, result.run.note
    assert result.contacts == 0 and result.min_clearance > 0.0
    log = result.navigator.log
    assert log.replans >= 1 and log.plans[1][2] == 'blocked'
    # the first plan (the map alone) runs through the box, the last one does not
    box = world.unknown_obstacles[0]
    first, last = log.plans[0][1], log.plans[-1][1]
    assert np.any(box.contains(along(first))) and not np.any(box.contains(along(last)))
    assert log.sensed and len(log.control_seconds) == len(result.run.steps)
    # scans are read as the nodes read them: returns inside the robot's footprint are it
    assert result.navigator.footprint is CIRCLE.footprint


def test_without_sensing_the_unknown_box_is_hit() -> None:
    world = load_world(resolve_data_file('unknown_box.yaml'))
    result = suites.run_navigation(world, 'pure_pursuit', CIRCLE, sensing=False,
                                   prepare=False)
    assert result.run.outcome is Outcome.COLLISION and result.contacts == 1
    assert result.navigator.log.replans == 0


def test_barn_for_the_challenge_knows_no_obstacle_beforehand() -> None:
    robot = dataclasses.replace(suites.ROBOTS['jackal'])
    world = suites.barn_sensing_world(suite_runs.DEFAULT_BARN_DIR / 'world_000.json', robot)
    assert world.obstacles == () and len(world.unknown_obstacles) > 50
    assert np.allclose(world.footprint.vertices, JACKAL.vertices)
    assert any(type(shape).__name__ == 'Circle' for shape in world.physical_shapes())


def test_the_unknown_suite_writes_contacts_replans_and_step_times(tmp_path) -> None:
    code = evaluate.main(['--suite', 'unknown', '--count', '1', '--controllers',
                          'pure_pursuit,dwa', '--out', str(tmp_path)])
    assert code == 0
    with open(tmp_path / 'runs.csv', newline='') as stream:
        rows = list(csv.DictReader(stream))
    assert [r['controller'] for r in rows] == ['pure_pursuit', 'dwa']
    for row in rows:
        assert row['sensing'] == 'True' and row['robot'] == 'circle'
        assert int(row['replans']) >= 1 and row['contacts'] in ('0', '1')
        assert float(row['step_ms_max']) >= float(row['step_ms_median']) > 0.0
    summary = (tmp_path / 'summary.md').read_text()
    assert 're-plans' in summary and 'max step [ms]' in summary and '| dwa |' in summary
    assert 'iterations budget' in summary  # reproducible: the MPCs count solver iterations


def test_suite_options_are_checked(tmp_path) -> None:
    with pytest.raises(SystemExit):
        evaluate.main(['--suite', 'random', '--sensing', '--out', str(tmp_path)])
    with pytest.raises(SystemExit):
        evaluate.main(['--suite', 'barn', '--robot', 'jackal', '--out', str(tmp_path)])
    with pytest.raises(SystemExit):
        evaluate.main(['--suite', 'barn', '--controllers', 'dwa', '--out', str(tmp_path)])
    with pytest.raises(SystemExit):
        evaluate.main(['--suite', 'worlds', '--out', str(tmp_path)])
    with pytest.raises(SystemExit):
        evaluate.main(['--suite', 'unknown', '--budget', 'cpu', '--out', str(tmp_path)])


def test_the_figure_draws_the_sensed_obstacles_every_plan_and_the_footprint(tmp_path) -> None:
    world = load_world(resolve_data_file('unknown_box.yaml'))
    # interpreted: the compiled functions' solutions, without gcc's wait on a fresh machine
    target = suites.plot_navigation_runs(tmp_path / 'runs.png', [('unknown box', world)],
                                         'proposed', CIRCLE, prepare=False,
                                         setup=suites.MpcSetup(compile=False))
    assert target.is_file() and target.stat().st_size > 10_000


def test_every_controller_arrives_where_a_localized_truth_still_succeeds() -> None:
    from mpc_local_planner.sim.reality import true_goal_tolerance

    world = suites.unknown_world(0, 0)
    robot = suites.ROBOTS['jackal']
    tolerance = float(world.goal_tolerance or suites.GOAL_TOLERANCE)
    mpc = suites.controller_setup(ControllerName.PROPOSED, robot, world)
    arrivals = [mpc.settings.xy_goal_tolerance]
    for name in ('pure_pursuit', 'dwa', 'regulated_pure_pursuit'):
        local = suites.local_controller(name, robot, world, prepare=False).controller
        config = getattr(local, 'config', None)
        arrivals.append(getattr(config, 'goal_tolerance', None) or config.xy_goal_tolerance)
    assert all(true_goal_tolerance(a) <= tolerance + 1e-12 for a in arrivals)


def test_regulated_pure_pursuit_checks_its_arc_against_the_sensed_obstacles() -> None:
    from mpc_local_planner.core.obstacles import ConvexPolygon
    from mpc_local_planner.sim.reality import reality_preset

    world = suites.unknown_world(0, 0)
    robot = dataclasses.replace(suites.ROBOTS['jackal'], v_max=2.0, omega_max=4.0)
    local, reach = suites.local_controller('regulated_pure_pursuit', robot, world,
                                            prepare=False, reality=reality_preset('real'))
    local.set_plan(np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]]))
    x, moving = np.zeros(3), np.array([2.0, 0.0])
    assert local.compute(x, moving, 0.0).u[0] == pytest.approx(2.0)
    # the navigator hands it the obstacles within its reach, as it does the DWA's
    post = ConvexPolygon.from_box(1.0, -0.1, 1.2, 0.1)
    assert reach >= 1.2
    local.set_obstacles([post])
    assert not local.compute(x, moving, 0.0).u.any()
    assert local.collision_ahead
    # the measured speed scales its lookahead: 0.2 m off the path, at rest it aims 0.3 m
    # ahead (a tighter arc), at 2 m/s 0.9 m ahead
    local.set_obstacles([])
    off = np.array([0.0, -0.2, 0.0])
    at_speed = local.compute(off, moving, 0.0).u
    at_rest = local.compute(off, np.zeros(2), 0.0).u
    assert at_rest[1] / at_rest[0] == pytest.approx(2.0 * 0.2 / (0.3**2 + 0.2**2))
    assert at_speed[1] / at_speed[0] == pytest.approx(2.0 * 0.2 / (0.9**2 + 0.2**2), rel=0.01)


def test_a_real_robot_navigates_on_odometry_corrected_by_the_localizer(monkeypatch) -> None:
    from mpc_local_planner.sim.localizer import Localizer

    given = {}
    real_rollout = suites.rollout
    drive = [True]  # the first run drives to the goal; the others stop once they start

    class Started(Exception):
        pass

    def spy(*args, **kwargs):
        given.update(kwargs)
        if not drive[0]:
            raise Started
        return real_rollout(*args, **kwargs)

    monkeypatch.setattr(suites, 'rollout', spy)
    world = suites.unknown_world(0, 0)
    robot = suites.ROBOTS['jackal']
    result = suites.run_navigation(world, 'dwa', robot, prepare=False, reality='real')
    assert isinstance(given['localizer'], Localizer)
    assert result.run.reached and result.contacts == 0
    drive[0] = False
    with pytest.raises(Started):
        suites.run_navigation(world, 'dwa', robot, prepare=False, reality='ideal')
    assert given['localizer'] is None
    # BARN's robot has no localizer: odometry only, even on a real base
    with pytest.raises(Started):
        suites.run_navigation(world, 'dwa', robot, prepare=False, reality='real',
                              localized=False)
    assert given['localizer'] is None


def test_the_barn_suite_runs_on_odometry_and_the_unknown_suite_with_the_localizer(
        monkeypatch) -> None:
    from mpc_local_planner.evaluation import suite_runs

    asked = []

    def fake(world, controller, robot, **kwargs):
        asked.append(kwargs['localized'])
        raise suite_runs.PlanningError('stop here')

    monkeypatch.setattr(suites, 'run_navigation', fake)
    for suite in ('barn', 'unknown'):
        row = suite_runs.run_navigation_task(suite_runs.Task(
            suite=suite, world=0, controller='dwa', sensing=True, robot='jackal',
            reality='real'))
        assert row.stop_reason == 'no plan: stop here'
    assert asked == [False, True]


def test_the_jackal_runs_at_its_own_limits_unless_told_otherwise(monkeypatch, tmp_path) -> None:
    from mpc_local_planner.evaluation import suite_runs

    given = []

    def fake(task):
        given.append((task.v_max, task.omega_max))
        return suite_runs.empty_row(task, None, 'not run')

    monkeypatch.setattr(evaluate, 'run_task', fake)
    command = ['--suite', 'barn', '--sensing', '--robot', 'jackal', '--worlds', '0',
               '--controllers', 'dwa']
    assert evaluate.main([*command, '--out', str(tmp_path / 'own')]) == 0
    assert evaluate.main([*command, '--v-max', '0.5', '--omega-max', '1.57',
                          '--out', str(tmp_path / 'told')]) == 0
    # config/jackal.yaml's and every headline's limits, as the ROBOTS entry says
    assert given == [(2.0, 4.0), (0.5, 1.57)]
    assert suites.ROBOTS['jackal'].v_max == 2.0 and suites.ROBOTS['jackal'].omega_max == 4.0
    assert '2 m/s' in (tmp_path / 'own' / 'summary.md').read_text()


@pytest.mark.parametrize('suite', ['unknown', 'worlds'])
def test_plot_draws_the_navigation_suites_too_not_only_barn(suite, tmp_path) -> None:
    command = ['--suite', suite, '--plot', '0', '--controllers', 'pure_pursuit',
               '--out', str(tmp_path / 'out')]
    if suite == 'worlds':
        folder = tmp_path / 'worlds'
        folder.mkdir()
        (folder / 'unknown_box.yaml').write_text(
            resolve_data_file('unknown_box.yaml').read_text(encoding='utf-8'))
        command += ['--world-dir', str(folder), '--sensing']
    assert evaluate.main(command) == 0
    figure = tmp_path / 'out' / f'{suite}_sensing_runs.png'
    assert figure.is_file() and figure.stat().st_size > 10_000
    # a world the suite does not have is refused with the reason, not a traceback
    with pytest.raises(SystemExit):
        evaluate.main([*command[:2], '--plot', '500', *command[4:]])
