# SPDX-License-Identifier: Apache-2.0
"""The layers: only ros/ talks ROS, each layer imports only the layers below it, no cycles.

Checked by reading every module's import statements (at any depth, so a lazy import inside a
function counts too), not by importing the modules.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / 'mpc_local_planner'
MODULES = sorted(PACKAGE.rglob('*.py'))
# What a module may import from this package, by layer (the first folder under the package).
ALLOWED_LAYERS = {
    'core': {'core'},
    'worlds': {'core', 'worlds'},
    'perception': {'core', 'worlds', 'perception'},
    'sim': {'core', 'worlds', 'perception', 'sim'},
    'evaluation': {'core', 'perception', 'worlds', 'sim', 'evaluation'},
    'ros': {'core', 'perception', 'worlds', 'sim', 'evaluation', 'ros'},
}
# ament_index_python is a plain lookup of installed files (worlds/data_files.py), not ROS I/O
ROS_PREFIXES = ('rclpy', 'rcl_interfaces', 'rosidl', 'launch')


def _imports(path: Path) -> list[tuple[str, int]]:
    """Return (module name, line) of every import in the file, relative ones resolved."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = list(path.relative_to(PACKAGE.parent).with_suffix('').parts[:-1])
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                module = '.'.join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ''
            names.append((module, node.lineno))
    return names


def _layer(path: Path) -> str:
    parts = path.relative_to(PACKAGE).parts
    return parts[0] if len(parts) > 1 else ''


def _is_ros(module: str) -> bool:
    top = module.split('.')[0]
    return top.startswith(ROS_PREFIXES) or top.endswith('_msgs')


def test_the_scan_finds_the_imports_it_must_judge() -> None:
    names = {name for name, _ in _imports(PACKAGE / 'ros' / 'mpc_controller_node.py')}
    assert any(name.startswith('rclpy') for name in names)
    assert 'nav_msgs.msg' in names
    assert _is_ros('geometry_msgs.msg') and _is_ros('rclpy') and not _is_ros('numpy')


@pytest.mark.parametrize('path', MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_only_ros_modules_import_rclpy_or_message_packages(path: Path) -> None:
    if _layer(path) == 'ros':
        return
    found = [f'{name} (line {line})' for name, line in _imports(path) if _is_ros(name)]
    assert not found, f'{path.relative_to(PACKAGE)} imports ROS: {found}'


@pytest.mark.parametrize('path', MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_each_layer_imports_only_the_layers_below_it(path: Path) -> None:
    layer = _layer(path)
    if layer not in ALLOWED_LAYERS:
        return
    used = {name.split('.')[1] for name, _ in _imports(path)
            if name.startswith('mpc_local_planner.') and len(name.split('.')) > 2}
    assert used <= ALLOWED_LAYERS[layer], f'{layer} imports {used - ALLOWED_LAYERS[layer]}'


def _module(path: Path) -> str:
    """Return the dotted name of a module of the package (a package's, for __init__.py)."""
    parts = path.relative_to(PACKAGE.parent).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def test_no_module_imports_itself_through_others() -> None:
    # every import counts, a TYPE_CHECKING one too: a cycle ties its modules into one job
    modules = {_module(path): path for path in MODULES}
    graph = {}
    for name, path in modules.items():
        deps = set()
        for imported, _ in _imports(path):
            parts = imported.split('.')
            while parts and '.'.join(parts) not in modules:
                parts.pop()
            target = '.'.join(parts)
            if parts and target != name and not name.startswith(target + '.'):
                deps.add(target)  # (a module's own package is not a cycle)
        graph[name] = deps
    done: set[str] = set()

    def cycle_from(name: str, trail: list[str]) -> list[str] | None:
        if name in trail:
            return [*trail[trail.index(name):], name]
        if name in done:
            return None
        for dep in sorted(graph[name]):
            found = cycle_from(dep, [*trail, name])
            if found:
                return found
        done.add(name)
        return None

    for name in sorted(graph):
        cycle = cycle_from(name, [])
        assert cycle is None, ' -> '.join(cycle)
