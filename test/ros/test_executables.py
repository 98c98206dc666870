# SPDX-License-Identifier: Apache-2.0
"""Every console script answers --help and starts nothing; bag_recorder refuses in one line.

``<script> --help`` exits 0 with a usage line, names each node's parameters with their
defaults, and writes nothing in its working directory; bag_recorder with an existing output
folder exits 2 with exactly one line on stderr. ``mpc_local_planner_share`` prints the folder
of the shipped parameter files, and a node started with ``--params-file`` from it takes
their values (the pip route of docs/usage.md).

The scripts are the package's ``console_scripts`` entry points as installed
(importlib.metadata), plus any that setup.py declares and an older editable install does not
list yet (run as ``python -m <module>``), so a new executable is covered without a reinstall.
They run with this checkout first on ``PYTHONPATH``: an installed script runs this
checkout's code, whatever copy of the package is installed.
"""

from __future__ import annotations

import ast
from importlib import import_module
from importlib.metadata import entry_points
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import time
from typing import Any, Callable

from conftest import flat_parameters
import pytest
from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.task import Future
import yaml

from mpc_local_planner.ros.parameters import ParameterSpec

pytestmark = pytest.mark.dds  # one process per executable

DISTRIBUTION = 'mpc_local_planner'
CHECKOUT = Path(__file__).resolve().parents[2]
SETUP_PY = CHECKOUT / 'setup.py'
# Wall seconds an executable may take to print its help (or refuse) before it counts as hung.
HANG_GUARD = 60.0
# Wall seconds after which an unanswered service request to another process is sent again.
RESEND_AFTER = 5.0


def setup_py_scripts() -> dict[str, str]:
    """Return setup.py's console_scripts as {name: 'module:function'}."""
    tree = ast.parse(SETUP_PY.read_text(encoding='utf-8'))
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values, strict=True):
                if isinstance(key, ast.Constant) and key.value == 'console_scripts':
                    entries = ast.literal_eval(value)
                    return {name.strip(): target.strip()
                            for name, target in (entry.split('=') for entry in entries)}
    return {}


def console_scripts() -> dict[str, str]:
    """Return every console script of the package as {name: 'module:function'}."""
    installed = {ep.name: ep.value for ep in entry_points(group='console_scripts')
                 if ep.dist is not None and ep.dist.name == DISTRIBUTION}
    return {**setup_py_scripts(), **installed}


SCRIPTS = console_scripts()


def command(name: str) -> list[str]:
    """Return how to run script name: the installed script, else ``python -m module``."""
    beside = Path(sys.executable).parent / name  # the script of this interpreter's install
    found = str(beside) if beside.is_file() else shutil.which(name)
    if found is not None:
        return [found]
    return [sys.executable, '-m', SCRIPTS[name].split(':')[0]]


def checkout_env() -> dict[str, str]:
    """Return the environment with this checkout first on PYTHONPATH (its code, not a copy's)."""
    paths = [str(CHECKOUT), *filter(None, os.environ.get('PYTHONPATH', '').split(os.pathsep))]
    return {**os.environ, 'PYTHONPATH': os.pathsep.join(paths)}


def node_parameters(name: str) -> tuple[ParameterSpec, ...] | None:
    """Return the PARAMETERS table of a node's module, None for an argparse command."""
    module_name = SCRIPTS[name].split(':')[0]
    if not (module_name.startswith('mpc_local_planner.ros.') and module_name.endswith('_node')):
        return None
    return getattr(import_module(module_name), 'PARAMETERS', ())


def scalar_default(value: object) -> str | None:
    """Return how --help shows a scalar default (None for lists and unset parameters)."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float):
        return f'{value:g}'
    if isinstance(value, (int, str)):
        return repr(value) if isinstance(value, str) else str(value)
    return None


def test_the_package_has_the_executables_the_readme_names() -> None:
    assert {'global_planner', 'mpc_controller', 'unicycle_simulator', 'bag_recorder',
            'closed_loop', 'analyze_bag', 'mpc_bench', 'mpc_bench_dds',
            'world_to_map'} <= set(SCRIPTS)


@pytest.mark.parametrize('name', sorted(SCRIPTS))
def test_help_prints_usage_and_the_parameters_starts_nothing_and_writes_nothing(
        name, tmp_path) -> None:
    result = subprocess.run([*command(name), '--help'], cwd=tmp_path, capture_output=True,
                            text=True, timeout=HANG_GUARD, check=False, env=checkout_env())
    assert result.returncode == 0, result.stderr
    assert 'usage' in result.stdout.lower(), result.stdout
    assert 'Traceback' not in result.stderr, result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    specs = node_parameters(name)
    if specs is None:
        return  # an argparse command: usage is all it owes
    assert specs, f'{name} has no PARAMETERS table for --help'
    lines = result.stdout.splitlines()
    for spec in specs:
        row = [line for line in lines if line.split()[:1] == [spec.name]]
        assert row, f'{name} --help does not list {spec.name}:\n{result.stdout}'
        shown = scalar_default(spec.default)
        if shown is not None:
            after_name = row[0].split(None, 1)[1]
            assert after_name.startswith(shown), (spec.name, row[0])


def test_bag_recorder_refuses_an_existing_output_folder_in_one_line(tmp_path) -> None:
    (tmp_path / 'bag').mkdir()
    result = subprocess.run([*command('bag_recorder'), '--ros-args', '-p', 'output:=bag'],
                            cwd=tmp_path, capture_output=True, text=True, timeout=HANG_GUARD,
                            check=False, env=checkout_env())
    assert result.returncode == 2, result.stderr
    assert result.stderr.count('\n') == 1, result.stderr
    assert result.stderr.startswith('bag_recorder: refusing to start: ')
    assert 'exists' in result.stderr and 'Traceback' not in result.stderr
    assert list((tmp_path / 'bag').iterdir()) == []  # nothing written into it



def shipped_share_files() -> set[str]:
    """Return the files setup.py's data_files install under share/mpc_local_planner/."""
    tree = ast.parse(SETUP_PY.read_text(encoding='utf-8'))
    shipped = {'package.xml'}
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, 'id', '') == 'glob':
            pattern = ast.literal_eval(node.args[0])
            shipped |= {str(p.relative_to(CHECKOUT)) for p in CHECKOUT.glob(pattern)}
    return shipped


def share_command_output(cwd: Path) -> str:
    """Return what mpc_local_planner_share prints, run as its console script runs it."""
    module, function = SCRIPTS['mpc_local_planner_share'].split(':')
    wrapper = f'import sys; from {module} import {function}; sys.exit({function}())'
    result = subprocess.run([sys.executable, '-c', wrapper], cwd=cwd, capture_output=True,
                            text=True, timeout=HANG_GUARD, check=False, env=checkout_env())
    assert result.returncode == 0, result.stderr
    assert result.stderr == '', result.stderr
    return result.stdout


def test_the_share_command_prints_the_folder_that_holds_the_shipped_files(tmp_path) -> None:
    output = share_command_output(tmp_path)
    assert output.count('\n') == 1, output
    share = Path(output.strip())
    assert share == CHECKOUT  # a source checkout's own (an editable install's)
    shipped = shipped_share_files()
    assert {'config/mpc_controller.yaml', 'config/global_planner.yaml',
            'config/unicycle_simulator.yaml', 'config/jackal.yaml',
            'config/worlds/paper_obstacle.yaml', 'launch/simulation.launch.py'} <= shipped
    for name in sorted(shipped):
        assert (share / name).is_file(), name
    assert list(tmp_path.iterdir()) == []


def ask_until_answered(ros, ask: Callable[[], Future], process: subprocess.Popen,
                       ) -> Future | None:
    """Send a request to another process until it is answered; None if it never is.

    A server that has not yet discovered the client's response reader drops its answer
    (rmw_fastrtps waits 100 ms for the match, then gives up), which a loaded machine meets
    right after the services become visible; the request is idempotent, so it is sent again.
    """
    deadline = time.monotonic() + HANG_GUARD
    while time.monotonic() < deadline and process.poll() is None:
        future = ask()
        if ros.spin_until(lambda future=future: future.done() or process.poll() is not None,
                          timeout=RESEND_AFTER) and future.done():
            return future
    return None


def test_a_node_started_with_params_files_from_the_share_command_takes_their_values(
        ros, tmp_path) -> None:
    # docs/usage.md's pip route, the Jackal's file over the defaults as README.md says
    config = Path(share_command_output(tmp_path).strip()) / 'config'
    files = [config / 'mpc_controller.yaml', config / 'jackal.yaml']
    expected: dict[str, Any] = {}
    for path in files:
        expected |= flat_parameters(
            yaml.safe_load(path.read_text(encoding='utf-8'))['mpc_controller']['ros__parameters'])
    defaults = flat_parameters(yaml.safe_load(
        files[0].read_text(encoding='utf-8'))['mpc_controller']['ros__parameters'])
    assert {name for name in expected if expected[name] != defaults[name]} >= {
        'v_max', 'footprint', 'max_accel'}  # the second file changes something
    arguments = [argument for path in files for argument in ('--params-file', str(path))]
    process = subprocess.Popen([*command('mpc_controller'), '--ros-args', *arguments],
                               cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True, env=checkout_env())
    try:
        client = AsyncParameterClient(ros.add(Node('parameter_reader', context=ros.context)),
                                      'mpc_controller')
        assert ros.spin_until(lambda: client.services_are_ready() or process.poll() is not None,
                              timeout=HANG_GUARD)
        assert process.poll() is None, 'mpc_controller exited'
        future = ask_until_answered(ros, lambda: client.get_parameters(sorted(expected)),
                                    process)
        assert future is not None, 'mpc_controller did not answer get_parameters'
        values = [parameter_value_to_python(value) for value in future.result().values]
        assert dict(zip(sorted(expected), values, strict=True)) == expected
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=HANG_GUARD)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 0, output
    assert 'Traceback' not in output, output
