# SPDX-License-Identifier: Apache-2.0
"""The package's files come from the copy whose code runs, whatever other copy is installed.

A source checkout tested beside a ``pip install .`` or a sourced colcon workspace reads its
own config/; an installed copy reads the share/ of its own prefix. The other copy is made
here in a temporary folder and put everywhere the lookup could find it: the ament index
(``AMENT_PREFIX_PATH``), ``sys.prefix`` and the user base.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path
import shutil
import site
import sys
import types

import pytest

import mpc_local_planner
from mpc_local_planner.worlds import data_files

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ('mpc_controller.yaml', 'worlds/unknown_box.yaml', 'maps/paper_obstacle.yaml')


def _install_share(prefix: Path, marker: str) -> Path:
    """Lay out prefix/share/mpc_local_planner as setup.py installs it, files saying marker."""
    share = prefix / 'share' / 'mpc_local_planner'
    for name in ('package.xml', *(f'config/{name}' for name in SHIPPED)):
        (share / name).parent.mkdir(parents=True, exist_ok=True)
        (share / name).write_text(f'# {marker}\n', encoding='utf-8')
    index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'mpc_local_planner').write_text('', encoding='utf-8')
    return share


def _another_copy_everywhere(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Path:
    """Install another copy's share/ where the ament index, sys.prefix and the user base see it."""
    other = tmp_path / 'other'
    _install_share(other, 'the other copy')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(other))
    monkeypatch.setattr(sys, 'prefix', str(other))
    monkeypatch.setattr(site, 'USER_BASE', str(other))
    return other


def _installed_module(site_packages: Path) -> types.ModuleType:
    """Return data_files as a copy installed in site_packages would run it."""
    path = site_packages / 'mpc_local_planner' / 'worlds' / 'data_files.py'
    path.parent.mkdir(parents=True)
    shutil.copy(data_files.__file__, path)
    spec = importlib.util.spec_from_file_location('installed_data_files', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_tests_import_the_package_of_this_checkout() -> None:
    # else they test another copy's code (run python3 -m pytest from the checkout's root)
    assert Path(mpc_local_planner.__file__).resolve().parent == ROOT / 'mpc_local_planner'


def test_a_checkout_reads_its_own_configs_whatever_other_copy_is_installed(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    _another_copy_everywhere(monkeypatch, tmp_path)
    for name in SHIPPED:
        assert data_files.resolve_data_file(name) == ROOT / 'config' / name
    unknown_box = data_files.resolve_data_file('unknown_box')
    assert unknown_box == ROOT / 'config' / 'worlds' / 'unknown_box.yaml'
    assert data_files.share_directory() == ROOT


@pytest.mark.parametrize('site_dir', ['lib/python3.12/site-packages',  # pip, colcon
                                      'lib/python3/dist-packages',  # Debian's python3
                                      'Lib/site-packages'])  # Windows
def test_an_installed_copy_reads_the_share_of_its_own_prefix_whatever_other_copy_is_installed(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path, site_dir: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    _another_copy_everywhere(monkeypatch, tmp_path)
    prefix = tmp_path / 'venv'
    share = _install_share(prefix, 'this copy')
    installed = _installed_module(prefix / site_dir)
    for name in SHIPPED:
        found = installed.resolve_data_file(name)
        assert found == share / 'config' / name
        assert found.read_text(encoding='utf-8') == '# this copy\n'
    assert installed.share_directory() == share
    assert installed.main([]) == 0
    assert capsys.readouterr().out == f'{share}\n'


def test_without_a_share_directory_the_share_command_says_so_in_one_line(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    nowhere = tmp_path / 'empty_prefix'
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)
    monkeypatch.setattr(sys, 'prefix', str(nowhere))
    monkeypatch.setattr(site, 'USER_BASE', str(nowhere))
    installed = _installed_module(tmp_path / 'venv' / 'lib' / 'python3.12' / 'site-packages')
    assert installed.main([]) == 2
    out, err = capsys.readouterr()
    assert out == ''
    assert err.startswith('mpc_local_planner_share: no share/mpc_local_planner (package.xml '
                          'and config/) beside ')
    assert err.count('\n') == 1 and str(nowhere) in err
    with pytest.raises(FileNotFoundError, match='no share/mpc_local_planner'):
        installed.share_directory()
    with pytest.raises(FileNotFoundError, match='mpc_controller.yaml: not found'):
        installed.resolve_data_file('mpc_controller.yaml')
