# SPDX-License-Identifier: Apache-2.0
"""Typos in parameters and params files, against real node processes.

rclpy ignores a parameter no declaration takes, and a params file section that matches no
node: ``horizn: 15`` would start the controller with horizon 10, without a word. Every node
of the package refuses an unknown parameter (exit code 2, one line naming the closest
declared one), warns of a params file with no section for it, and refuses a params file it
cannot read in one line; the shipped parameter files start every node without a word.
"""

from __future__ import annotations

from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Any

import pytest

from mpc_local_planner.ros.closed_loop_parameters import MODULES
from mpc_local_planner.ros.node_main import EXIT_INVALID_PARAMETERS
from mpc_local_planner.ros.parameters import section_applies, unknown_parameters
from mpc_local_planner.worlds.data_files import resolve_data_file

pytestmark = pytest.mark.dds  # node processes over DDS
# Wall seconds a process may take to refuse, or to start, before it counts as hung.
HANG_GUARD = 60.0
NODE_MODULES = {**MODULES, 'bag_recorder': 'mpc_local_planner.ros.bag_recorder_node'}


def node_command(node: str, *ros_args: str) -> list[str]:
    """Return the command that runs node's module with ros_args (this checkout's code)."""
    return [sys.executable, '-m', NODE_MODULES[node], '--ros-args', *ros_args]


def run_all(commands: dict[str, list[str]]) -> dict[str, subprocess.CompletedProcess]:
    """Run the commands side by side until each exits; kill any that outlives HANG_GUARD."""
    processes = {case: subprocess.Popen(command, stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, text=True)
                 for case, command in commands.items()}
    done = {}
    deadline = time.monotonic() + HANG_GUARD
    try:
        for case, process in processes.items():
            try:
                stdout, stderr = process.communicate(
                    timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.kill()
                stdout, stderr = process.communicate()
                stderr += f'\n(killed: still running after {HANG_GUARD:g} s)'
            done[case] = subprocess.CompletedProcess(commands[case], process.returncode,
                                                     stdout, stderr)
    finally:
        for process in processes.values():
            if process.poll() is None:
                process.kill()
                process.communicate()
    return done


def params_file(folder: Path, name: str, text: str) -> str:
    path = folder / name
    path.write_text(text, encoding='utf-8')
    return str(path)


def test_a_misspelt_parameter_is_refused_in_one_line_with_the_closest_name(tmp_path) -> None:
    bag = str(tmp_path / 'bag')
    in_file = {
        'horizn in a params file': ('mpc_controller', 'horizn', 'horizon',
                                    'mpc_controller:\n  ros__parameters:\n    horizn: 15\n'),
        'v_maxx in a params file': ('mpc_controller', 'v_maxx', 'v_max',
                                    'mpc_controller:\n  ros__parameters:\n    v_maxx: 0.5\n'),
        'weights.positon, nested': ('mpc_controller', 'weights.positon', 'weights.position',
                                    'mpc_controller:\n  ros__parameters:\n    weights:\n'
                                    '      positon: 2.0\n'),
        # sections apply as ROS matches them: the wildcard, and a namespaced name
        'a /** section': ('global_planner', 'iteratons', 'iterations',
                          '/**:\n  ros__parameters:\n    iteratons: 10\n'),
    }
    commands = {case: node_command(node, '--params-file',
                                   params_file(tmp_path, f'{index}.yaml', text))
                for index, (case, (node, _, _, text)) in enumerate(in_file.items())}
    namespaced = params_file(tmp_path, 'robot.yaml',
                             'robot:\n  unicycle_simulator:\n    ros__parameters:\n'
                             '      initial_pos: [1.0, 0.0, 0.0]\n')
    commands['a namespaced section'] = node_command(
        'unicycle_simulator', '-r', '__ns:=/robot', '--params-file', namespaced)
    on_command_line = {
        'horizn with -p': ('mpc_controller', 'horizn', 'horizon', ['-p', 'horizn:=15']),
        'the map server': ('map_server', 'frame', 'frame_id',
                           ['-p', 'yaml_filename:=maps/paper_obstacle.yaml',
                            '-p', 'frame:=world']),
        'the bag recorder': ('bag_recorder', 'topcis', 'topics',
                             ['-p', f'output:={bag}', '-p', 'topcis:=[odom]']),
    }
    commands.update({case: node_command(node, *args)
                     for case, (node, _, _, args) in on_command_line.items()})
    expected = {case: (node, typo, name) for case, (node, typo, name, _) in
                {**in_file, **on_command_line}.items()}
    expected['a namespaced section'] = ('unicycle_simulator', 'initial_pos', 'initial_pose')
    problems = []
    for case, result in run_all(commands).items():
        node, typo, name = expected[case]
        line = (f"{node}: refusing to start: unknown parameter '{typo}' "
                f"(did you mean '{name}'?)")
        if result.returncode != EXIT_INVALID_PARAMETERS or result.stderr.splitlines() != [line]:
            problems.append(f'{case}: exit {result.returncode}, stderr {result.stderr!r}')
    assert not problems, '\n'.join(problems)
    assert not Path(bag).exists()  # the recorder refused before it opened its bag


def test_a_params_file_that_is_missing_or_unparsable_is_refused_in_one_line(
        tmp_path) -> None:
    cases = {
        'missing': ('mpc_controller', str(tmp_path / 'no_such.yaml'), 'not found'),
        'not YAML': ('global_planner',
                     params_file(tmp_path, 'broken.yaml', 'global_planner: [\n'),
                     'is not valid YAML'),
        'a list of mixed types (rcl refuses it)': (
            'unicycle_simulator',
            params_file(tmp_path, 'mixed.yaml', 'unicycle_simulator:\n  ros__parameters:\n'
                                                "    initial_pose: [1.0, 'x', 0.0]\n"),
            'Sequence should be of same type'),
        'a value outside ros__parameters (rcl refuses it)': (
            'map_server', params_file(tmp_path, 'flat.yaml', 'map_server:\n  frame_id: map\n'),
            'Cannot have a value before ros__parameters'),
    }
    commands = {case: node_command(node, '--params-file', path)
                for case, (node, path, _) in cases.items()}
    problems = []
    for case, result in run_all(commands).items():
        node, path, reason = cases[case]
        lines = result.stderr.splitlines()
        if (result.returncode != EXIT_INVALID_PARAMETERS or len(lines) != 1
                or not lines[0].startswith(f'{node}: refusing to start: ')
                or path not in lines[0] or reason not in lines[0]):
            problems.append(f'{case}: exit {result.returncode}, stderr {result.stderr!r}')
    assert not problems, '\n'.join(problems)


# What shows that a node process got past its parameters: an endpoint it creates after.
STARTED = {'unicycle_simulator': ('/odom', 'publisher'), 'global_planner': ('/plan', 'publisher'),
           'mpc_controller': ('/cmd_vel', 'publisher'), 'map_server': ('/map', 'publisher'),
           'bag_recorder': ('/odom', 'subscription')}


def start_and_stop(ros: Any, commands: dict[str, list[str]]) -> dict[str, tuple[int, str]]:
    """Start a process per node, wait until each has its STARTED endpoint, then SIGINT all.

    Returns each node's exit code and output (stdout and stderr).
    """
    from rclpy.node import Node

    probe = ros.add(Node('typo_probe', context=ros.context))

    def has_started(node: str) -> bool:
        topic, kind = STARTED[node]
        infos = (probe.get_publishers_info_by_topic(topic) if kind == 'publisher'
                 else probe.get_subscriptions_info_by_topic(topic))
        return any(info.node_name == node for info in infos)

    processes = {node: subprocess.Popen(command, stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT, text=True)
                 for node, command in commands.items()}
    try:
        ros.spin_until(lambda: all(has_started(node) or processes[node].poll() is not None
                                   for node in processes), timeout=HANG_GUARD)
        started = {node: has_started(node) for node in processes}
        for process in processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        outputs = {node: process.communicate(timeout=HANG_GUARD)[0]
                   for node, process in processes.items()}
    finally:
        for process in processes.values():
            if process.poll() is None:
                process.kill()
                process.communicate()
    assert all(started.values()), {node: outputs[node] for node, ok in started.items()
                                   if not ok}
    return {node: (process.returncode, outputs[node]) for node, process in processes.items()}


def test_the_shipped_params_files_start_every_node_without_a_refusal_or_a_warning(
        ros, tmp_path) -> None:
    def shipped(name: str) -> str:
        return str(resolve_data_file(f'{name}.yaml'))

    commands = {
        'unicycle_simulator': node_command('unicycle_simulator', '--params-file',
                                           shipped('unicycle_simulator')),
        'global_planner': node_command('global_planner', '--params-file',
                                       shipped('global_planner')),
        # a Jackal's parameters, on top of the controller's (docs/real_robot.md)
        'mpc_controller': node_command('mpc_controller', '--params-file',
                                       shipped('mpc_controller'), '--params-file',
                                       shipped('jackal')),
        'map_server': node_command('map_server', '-p',
                                   'yaml_filename:=maps/paper_obstacle.yaml'),
        'bag_recorder': node_command('bag_recorder', '--params-file', shipped('bag_recorder'),
                                     '-p', f'output:={tmp_path / "bag"}'),
    }
    for node, (code, output) in start_and_stop(ros, commands).items():
        assert code == 0, (node, output)
        for word in ('unknown parameter', 'no section', 'refusing', 'Traceback'):
            assert word not in output, (node, output)


def test_a_params_file_without_a_section_for_the_node_gets_one_warning_and_it_starts(
        ros, tmp_path) -> None:
    misspelt = params_file(tmp_path, 'misspelt.yaml',
                           'mpc_contoller:\n  ros__parameters:\n    horizon: 15\n')
    commands = {'mpc_controller': node_command('mpc_controller', '--params-file', misspelt)}
    code, output = start_and_stop(ros, commands)['mpc_controller']
    assert code == 0, output
    [warning] = [line for line in output.splitlines() if 'WARN' in line]
    assert (f'params file {misspelt} has no section for /mpc_controller (its sections: '
            "mpc_contoller; did you mean 'mpc_controller'?): none of its parameters is "
            'used') in warning


@pytest.mark.parametrize(('section', 'node', 'applies'), [
    ('/**', '/mpc_controller', True),
    ('/**', '/robot/mpc_controller', True),
    ('mpc_controller', '/mpc_controller', True),
    ('/mpc_controller', '/mpc_controller', True),
    ('mpc_controller', '/robot/mpc_controller', False),
    ('robot/mpc_controller', '/robot/mpc_controller', True),
    ('/robot/*', '/robot/mpc_controller', True),
    ('/robot/*', '/mpc_controller', False),
    ('/*', '/robot/mpc_controller', False),
    ('mpc_contoller', '/mpc_controller', False),
])
def test_a_params_file_section_applies_as_rcl_matches_it(section: str, node: str,
                                                        applies: bool) -> None:
    assert section_applies(section, node) is applies


def test_rclpys_own_parameters_are_never_unknown() -> None:
    given = ['use_sim_time', 'start_type_description_service',
             'qos_overrides./cmd_vel.publisher.depth', 'horizon', 'horizn']
    assert unknown_parameters(given, ['horizon']) == [
        "unknown parameter 'horizn' (did you mean 'horizon'?)"]
