# SPDX-License-Identifier: Apache-2.0
"""The launch files and the RViz config, checked without ``launch`` (not installable here).

``launch`` and ``launch_ros`` are not on PyPI, so the launch files run against small stand-ins
of the few launch classes they use: the stand-ins record what the launch file asks for, and
the tests check it against the package (console scripts, installed files, declared
parameters). What launch itself does with a description is not checked here.

The tests check the checkout's launch files and configs whatever else is installed: another
copy of the package is put where an installed one would be found (``sys.prefix``, the user
base, the ament index), as a colcon workspace or a ``pip install .`` puts one beside the
checkout, with a map of its own that the checkout does not have.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
from pathlib import Path
import shutil
import site
import sys
import types
from typing import Any

import pytest
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
import yaml

ROOT = Path(__file__).resolve().parents[2]
LAUNCH_FILES = sorted((ROOT / 'launch').glob('*.launch.py'))
RVIZ_FILE = ROOT / 'rviz' / 'mpc_local_planner.rviz'
SHARE = '/install/share/mpc_local_planner'


class _Recorded:
    """Stand-in for a launch class: keeps its arguments."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args, self.kwargs = args, kwargs


class _LaunchConfiguration(_Recorded):
    def perform(self, context: dict[str, str]) -> str:
        return context[self.args[0]]


def _stand_in_modules() -> dict[str, types.ModuleType]:
    """Return modules named like launch's, with just the names the launch files import."""
    names = {
        'launch': {'LaunchDescription': _Recorded, 'LaunchContext': dict},
        'launch.actions': {'DeclareLaunchArgument': _Recorded, 'OpaqueFunction': _Recorded},
        'launch.conditions': {'IfCondition': _Recorded},
        'launch.substitutions': {'LaunchConfiguration': _LaunchConfiguration},
        'launch_ros': {},
        'launch_ros.actions': {'Node': _Recorded},
        'ament_index_python': {},
        'ament_index_python.packages': {'get_package_share_directory': lambda pkg: SHARE},
    }
    modules = {}
    for name, attributes in names.items():
        module = types.ModuleType(name)
        module.__dict__.update(attributes)
        modules[name] = module
    return modules


@pytest.fixture(scope='module')
def other_copy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Return the prefix of another installed copy: the checkout's share/ and one more map."""
    prefix = tmp_path_factory.mktemp('other_copy')
    share = prefix / 'share' / 'mpc_local_planner'
    shutil.copytree(ROOT / 'config', share / 'config')
    shutil.copy(ROOT / 'package.xml', share)
    shutil.copy(share / 'config' / 'maps' / 'paper_obstacle.yaml',
                share / 'config' / 'maps' / 'mapless_world.yaml')
    index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'mpc_local_planner').write_text('', encoding='utf-8')
    return prefix


@pytest.fixture(autouse=True)
def _other_copy_installed(other_copy: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Install the other copy where an installed one is found."""
    monkeypatch.setattr(sys, 'prefix', str(other_copy))
    monkeypatch.setattr(site, 'USER_BASE', str(other_copy))
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(other_copy))


def _describe(path: Path, monkeypatch: pytest.MonkeyPatch,
              overrides: dict[str, str] | None = None) -> tuple[dict[str, str], list]:
    """Run the launch file's generate_launch_description; return (arguments, nodes).

    overrides are launch arguments given on the command line (``world:=...``).
    """
    for name, module in _stand_in_modules().items():
        monkeypatch.setitem(sys.modules, name, module)
    spec = importlib.util.spec_from_file_location(path.stem.replace('.', '_'), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    entities = description.args[0]
    arguments = {e.args[0]: e.kwargs['default_value'] for e in entities
                 if isinstance(e, _Recorded) and 'default_value' in e.kwargs}
    nodes = []
    for entity in entities:
        if 'package' in entity.kwargs:
            nodes.append(entity)
        elif 'function' in entity.kwargs:  # OpaqueFunction: run it as launch would
            nodes += entity.kwargs['function']({**arguments, **(overrides or {})})
    return arguments, nodes


def _console_scripts() -> set[str]:
    """Return the console scripts setup.py declares.

    Read from setup.py, not from the installed metadata: an editable install's entry points
    are stale until it is reinstalled.
    """
    tree = ast.parse((ROOT / 'setup.py').read_text())
    scripts = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values, strict=True):
                if isinstance(key, ast.Constant) and key.value == 'console_scripts':
                    scripts |= {entry.split('=')[0].strip()
                                for entry in ast.literal_eval(value)}
    return scripts


def _installed_share_files() -> set[str]:
    """Return share/mpc_local_planner/... paths that setup.py's data_files install."""
    tree = ast.parse((ROOT / 'setup.py').read_text())
    installed = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, 'id', '') == 'glob':
            pattern = ast.literal_eval(node.args[0])
            installed |= {str(p.relative_to(ROOT)) for p in ROOT.glob(pattern)}
    return {f'{SHARE}/{p}' for p in installed}


def _installed_path(path: str) -> str:
    """Return where a file the launch file names lies once installed.

    Under the stand-ins the package's files resolve to the source tree's config/, which
    setup.py installs under share/.
    """
    resolved = Path(path).resolve()
    if not path.startswith(SHARE) and resolved.is_relative_to(ROOT):
        return f'{SHARE}/{resolved.relative_to(ROOT)}'
    return path


def _make_node(executable: str, ros: Any) -> Any:
    """Construct the real node of an executable with its defaults, spun by ros."""
    module_name = {'unicycle_simulator': 'unicycle_simulator_node',
                   'global_planner': 'global_planner_node',
                   'mpc_controller': 'mpc_controller_node',
                   'map_server': 'map_server_node',
                   'bag_recorder': 'bag_recorder_node'}[executable]
    module = importlib.import_module(f'mpc_local_planner.ros.{module_name}')
    node_class = next(value for name, value in vars(module).items()
                      if name.endswith('Node') and isinstance(value, type)
                      and value.__module__ == module.__name__)
    from rclpy.parameter import Parameter

    overrides = []
    if executable == 'bag_recorder':  # it opens its bag at construction
        overrides = [Parameter('output', value=str(ros.tmp_path / 'bag'))]
    elif executable == 'map_server':  # it has no default map
        overrides = [Parameter('yaml_filename', value='maps/paper_obstacle.yaml')]
    return ros.add(node_class(context=ros.context, parameter_overrides=overrides))


def _declared_parameters(executable: str, ros: Any) -> set[str]:
    """Return the parameter names a node of the executable declares (the real node)."""
    return set(_make_node(executable, ros).list_parameters([], 0).names)  # 0: every depth


def test_there_are_a_simulation_and_a_navigation_launch_file() -> None:
    assert {p.name for p in LAUNCH_FILES} == {'simulation.launch.py', 'navigation.launch.py'}


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_launch_file_compiles(path: Path) -> None:
    compile(path.read_text(), str(path), 'exec')


@pytest.mark.dds
@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_launch_file_names_only_console_scripts_installed_files_and_declared_parameters(
        path: Path, monkeypatch: pytest.MonkeyPatch, ros: Any, tmp_path: Path) -> None:
    ros.tmp_path = tmp_path
    arguments, nodes = _describe(path, monkeypatch)
    scripts, installed = _console_scripts(), _installed_share_files()
    assert f'{SHARE}/launch/{path.name}' in installed
    assert nodes, 'the launch file starts no node'
    for node in nodes:
        executable = node.kwargs['executable']
        assert node.kwargs['package'] == 'mpc_local_planner'
        assert executable in scripts, f'{executable} is not a console script'
        declared = _declared_parameters(executable, ros)
        for entry in node.kwargs['parameters']:
            if isinstance(entry, str):
                assert entry in installed, f'{entry} is not installed'
            elif isinstance(entry, dict):
                assert set(entry) <= declared, f'{executable}: {set(entry) - declared}'
            else:  # a LaunchConfiguration naming a params file
                default = arguments[entry.args[0]]
                assert default in installed, f'{default} is not installed'
    for name, default in arguments.items():
        if default.startswith(SHARE):
            assert default in installed, f'argument {name}: {default} is not installed'


def test_simulation_launch_runs_every_node_on_simulated_time_and_records_on_request(
        monkeypatch: pytest.MonkeyPatch) -> None:
    _, nodes = _describe(ROOT / 'launch' / 'simulation.launch.py', monkeypatch)
    by_name = {n.kwargs['executable']: n for n in nodes}
    assert set(by_name) == {'unicycle_simulator', 'map_server', 'global_planner',
                            'mpc_controller', 'bag_recorder'}
    for name, node in by_name.items():
        values = {k: v for entry in node.kwargs['parameters'] if isinstance(entry, dict)
                  for k, v in entry.items()}
        if name == 'unicycle_simulator':
            assert values['publish_clock'] is True
        else:
            assert values['use_sim_time'] is True
    assert by_name['bag_recorder'].kwargs['condition'].args == ('false',)


def _parameter_values(node: _Recorded, arguments: dict[str, str]) -> dict[str, Any]:
    """Return a launched node's dict parameters, launch arguments replaced by defaults."""
    values = {k: v for entry in node.kwargs['parameters'] if isinstance(entry, dict)
              for k, v in entry.items()}
    return {k: arguments[v.args[0]] if isinstance(v, _LaunchConfiguration) else v
            for k, v in values.items()}


def test_simulation_launch_starts_a_map_server_on_an_installed_map(
        monkeypatch: pytest.MonkeyPatch) -> None:
    arguments, nodes = _describe(ROOT / 'launch' / 'simulation.launch.py', monkeypatch)
    [map_server] = [n for n in nodes if n.kwargs['executable'] == 'map_server']
    yaml_filename = _parameter_values(map_server, arguments)['yaml_filename']
    assert _installed_path(yaml_filename) == f'{SHARE}/config/maps/paper_obstacle.yaml'
    installed = _installed_share_files()
    assert f'{SHARE}/config/maps/paper_obstacle.yaml' in installed
    image = yaml.safe_load((ROOT / 'config' / 'maps' / 'paper_obstacle.yaml').read_text())
    assert f'{SHARE}/config/maps/{image["image"]}' in installed


def test_navigation_launch_gives_no_world_and_no_goal_and_serves_the_map_it_is_given(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # the real-robot launch: a demo's world, goal or map must not reach a real robot
    arguments, nodes = _describe(ROOT / 'launch' / 'navigation.launch.py', monkeypatch)
    assert 'world' not in arguments and 'map' not in arguments  # map: required, no default
    by_name = {n.kwargs['executable']: n for n in nodes}
    assert set(by_name) == {'map_server', 'global_planner', 'mpc_controller'}
    values = {name: {k: v for entry in node.kwargs['parameters'] if isinstance(entry, dict)
                     for k, v in entry.items()} for name, node in by_name.items()}
    for name, given in values.items():
        assert not {'world_file', 'goal', 'initial_pose'} & set(given), name
    yaml_filename = values['map_server']['yaml_filename']
    assert isinstance(yaml_filename, _LaunchConfiguration) and yaml_filename.args == ('map',)
    # the planner plans on that map and the controller avoids what it shows
    assert values['global_planner']['use_map'] is True
    assert values['mpc_controller']['obstacle_sources'] == ['map']
    # and the parameter files it names hold no world and no goal either
    for name in ('global_planner', 'mpc_controller'):
        [params] = [e for e in by_name[name].kwargs['parameters']
                    if isinstance(e, _LaunchConfiguration)]
        shipped = Path(arguments[params.args[0]].replace(SHARE, str(ROOT)))
        given = yaml.safe_load(shipped.read_text())[name]['ros__parameters']
        assert 'goal' not in given and given['world_file'] == '', name


def test_every_shipped_world_has_an_installed_map(monkeypatch: pytest.MonkeyPatch) -> None:
    installed = _installed_share_files()
    for world in sorted((ROOT / 'config' / 'worlds').glob('*.yaml')):
        _, nodes = _describe(ROOT / 'launch' / 'simulation.launch.py', monkeypatch,
                             {'world': world.stem})
        [map_server] = [n for n in nodes if n.kwargs['executable'] == 'map_server']
        yaml_filename = _parameter_values(map_server, {})['yaml_filename']
        assert _installed_path(yaml_filename) == f'{SHARE}/config/maps/{world.stem}.yaml'
        assert _installed_path(yaml_filename) in installed


def test_simulation_launch_serves_the_map_argument_or_none_for_a_world_without_a_map(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    simulation = ROOT / 'launch' / 'simulation.launch.py'
    _, nodes = _describe(simulation, monkeypatch, {'map': 'maps/unknown_box.yaml'})
    [map_server] = [n for n in nodes if n.kwargs['executable'] == 'map_server']
    assert _parameter_values(map_server, {})['yaml_filename'].endswith(
        'config/maps/unknown_box.yaml')
    mapless = tmp_path / 'mapless_world.yaml'
    mapless.write_text((ROOT / 'config' / 'worlds' / 'paper_obstacle.yaml').read_text())
    _, nodes = _describe(simulation, monkeypatch, {'world': str(mapless)})
    executables = {n.kwargs['executable'] for n in nodes}
    assert 'map_server' not in executables and 'mpc_controller' in executables


@pytest.mark.dds
def test_simulation_launch_with_sensing_gives_the_world_only_to_the_simulator(
        monkeypatch: pytest.MonkeyPatch, ros: Any, tmp_path: Path) -> None:
    ros.tmp_path = tmp_path
    simulation = ROOT / 'launch' / 'simulation.launch.py'
    arguments, nodes = _describe(simulation, monkeypatch,
                                 {'sensing': 'true', 'world': 'unknown_box'})
    assert arguments['sensing'] == 'false'  # off unless asked for
    values = {n.kwargs['executable']: _parameter_values(n, {}) for n in nodes}
    world_file = str(ROOT / 'config' / 'worlds' / 'unknown_box.yaml')
    simulator = values['unicycle_simulator']
    assert simulator['world_file'] == world_file and simulator['robot_radius'] == 0.2
    assert values['global_planner']['world_file'] == ''
    assert values['global_planner']['use_map'] is True
    assert values['global_planner']['use_scan'] is True
    assert values['mpc_controller']['world_file'] == ''
    assert values['mpc_controller']['obstacle_sources'] == ['map', 'scan']
    assert _installed_path(values['map_server']['yaml_filename']) == (
        f'{SHARE}/config/maps/unknown_box.yaml')
    # no node but the simulator reads the world's obstacles
    readers = {name for name, v in values.items() if v.get('world_file')}
    assert readers == {'unicycle_simulator'}
    # and every node declares what the launch file gives it
    for node in nodes:
        executable = node.kwargs['executable']
        declared = _declared_parameters(executable, ros)
        assert set(values[executable]) <= declared, (executable,
                                                    set(values[executable]) - declared)


def test_simulation_launch_gives_the_simulator_the_true_world_without_sensing(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    simulation = ROOT / 'launch' / 'simulation.launch.py'
    _, nodes = _describe(simulation, monkeypatch, {'world': 'unknown_box'})
    values = {n.kwargs['executable']: _parameter_values(n, {}) for n in nodes}
    world_file = str(ROOT / 'config' / 'worlds' / 'unknown_box.yaml')
    # the simulator counts contacts in every mode; planner and controller read the world
    assert values['unicycle_simulator']['world_file'] == world_file
    assert values['global_planner']['world_file'] == world_file
    assert values['mpc_controller']['world_file'] == world_file
    assert 'obstacle_sources' not in values['mpc_controller']
    # sensing on a world without a map: refused, with the reason
    mapless = tmp_path / 'mapless_world.yaml'
    mapless.write_text((ROOT / 'config' / 'worlds' / 'paper_obstacle.yaml').read_text())
    with pytest.raises(RuntimeError, match='sensing:=true needs a map'):
        _describe(simulation, monkeypatch, {'world': str(mapless), 'sensing': 'true'})


def _rviz_topics(config: Any) -> set[str]:
    """Return every topic the RViz config names (displays and tools)."""
    topics = set()

    def visit(item: Any) -> None:
        if isinstance(item, dict):
            topic = item.get('Topic')
            if isinstance(topic, dict):
                topics.add(topic['Value'])
            for value in item.values():
                visit(value)
        elif isinstance(item, list):
            for value in item:
                visit(value)

    visit(config)
    return topics


def _rviz_endpoints(config: Any) -> list[tuple[str, dict]]:
    """Return (role, Topic entry) per topic: displays subscribe, tools (2D Goal Pose) publish."""
    manager = config['Visualization Manager']
    found: list[tuple[str, dict]] = []

    def visit(item: Any, role: str) -> None:
        if isinstance(item, dict):
            if isinstance(item.get('Topic'), dict):
                found.append((role, item['Topic']))
            for value in item.values():
                visit(value, role)
        elif isinstance(item, list):
            for value in item:
                visit(value, role)

    visit(manager['Displays'], 'subscribe')
    visit(manager['Tools'], 'publish')
    assert {topic['Value'] for _, topic in found} == _rviz_topics(config)
    return found


# RViz's QoS names, and the rclpy policies they stand for.
_RVIZ_DURABILITY = {'Volatile': DurabilityPolicy.VOLATILE,
                    'Transient Local': DurabilityPolicy.TRANSIENT_LOCAL}


@pytest.mark.dds
def test_every_topic_the_rviz_config_names_is_served_by_a_node_with_a_matching_qos(
        ros: Any) -> None:
    config = yaml.safe_load(RVIZ_FILE.read_text())
    nodes = [_make_node(executable, ros) for executable in
             ('unicycle_simulator', 'map_server', 'global_planner', 'mpc_controller')]
    for node in nodes:  # lifecycle nodes create their publishers at configure
        if isinstance(node, LifecycleNode):
            assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS, node.get_name()
    names = {node.get_name() for node in nodes}
    published = {pub.topic_name for node in nodes for pub in node.publishers}
    subscribed = {sub.topic_name for node in nodes for sub in node.subscriptions}
    graph = nodes[0]
    for role, topic in _rviz_endpoints(config):
        name, durability = topic['Value'], _RVIZ_DURABILITY[topic['Durability Policy']]
        reliable = topic['Reliability Policy'] == 'Reliable'
        if role == 'subscribe':  # an RViz display: a node must publish it
            assert name in published, f'RViz shows {name}, which no node publishes'
            peers = graph.get_publishers_info_by_topic(name)
        else:  # an RViz tool: a node must listen
            assert name in subscribed, f'RViz publishes {name}, to which no node listens'
            peers = graph.get_subscriptions_info_by_topic(name)
        peers = [info for info in peers if info.node_name in names]
        assert peers, name
        for info in peers:
            # a latched topic needs a transient_local reader (else a late RViz misses it),
            # and a transient_local or reliable reader an equally strong writer
            assert info.qos_profile.durability == durability, (name, info.node_name)
            if role == 'subscribe':
                assert not reliable or info.qos_profile.reliability == ReliabilityPolicy.RELIABLE
            else:
                assert reliable or info.qos_profile.reliability != ReliabilityPolicy.RELIABLE


def test_rviz_config_is_yaml_with_the_map_frame_and_a_goal_tool_on_goal_pose() -> None:
    config = yaml.safe_load(RVIZ_FILE.read_text())
    manager = config['Visualization Manager']
    assert manager['Global Options']['Fixed Frame'] == 'map'
    goal_tools = [t for t in manager['Tools'] if t['Class'] == 'rviz_default_plugins/SetGoal']
    assert [t['Topic']['Value'] for t in goal_tools] == ['/goal_pose']
    classes = {d['Class'] for d in manager['Displays']}
    assert {'rviz_default_plugins/Path', 'rviz_default_plugins/Odometry',
            'rviz_default_plugins/MarkerArray', 'rviz_default_plugins/Polygon',
            'rviz_default_plugins/Map'} <= classes
    [map_display] = [d for d in manager['Displays'] if d['Class'] == 'rviz_default_plugins/Map']
    assert map_display['Topic']['Value'] == '/map'
    assert map_display['Topic']['Durability Policy'] == 'Transient Local'
    assert map_display['Topic']['Reliability Policy'] == 'Reliable'


JACKAL_TEXT = '[[0.254, 0.215], [-0.254, 0.215], [-0.254, -0.215], [0.254, -0.215]]'


@pytest.mark.dds
def test_the_footprint_argument_reaches_simulator_planner_and_controller(
        monkeypatch: pytest.MonkeyPatch, ros: Any, tmp_path: Path) -> None:
    ros.tmp_path = tmp_path
    simulation = ROOT / 'launch' / 'simulation.launch.py'
    arguments, nodes = _describe(simulation, monkeypatch)
    assert arguments['footprint'] == ''
    robot_nodes = ('unicycle_simulator', 'global_planner', 'mpc_controller')
    # empty: nothing over the parameter files (each node reads its file, then the world)
    values = {n.kwargs['executable']: _parameter_values(n, {}) for n in nodes}
    assert not any('footprint' in values[name] for name in robot_nodes)
    for sensing in ('false', 'true'):
        _, nodes = _describe(simulation, monkeypatch, {'footprint': JACKAL_TEXT,
                                                       'world': 'unknown_box',
                                                       'sensing': sensing})
        values = {n.kwargs['executable']: _parameter_values(n, {}) for n in nodes}
        for name in robot_nodes:
            assert values[name]['footprint'] == JACKAL_TEXT, (name, sensing)
        assert 'footprint' not in values['map_server']
    # and each of them declares it
    for name in robot_nodes:
        assert 'footprint' in _declared_parameters(name, ros), name


def test_with_sensing_the_worlds_footprint_is_handed_to_the_nodes_that_do_not_read_it(
        monkeypatch: pytest.MonkeyPatch) -> None:
    simulation = ROOT / 'launch' / 'simulation.launch.py'
    _, nodes = _describe(simulation, monkeypatch, {'world': 'narrow_gap', 'sensing': 'true'})
    values = {n.kwargs['executable']: _parameter_values(n, {}) for n in nodes}
    jackal = yaml.safe_load(JACKAL_TEXT)
    for name in ('global_planner', 'mpc_controller'):
        assert values[name]['world_file'] == ''
        assert yaml.safe_load(values[name]['footprint']) == jackal, name
    # the simulator reads the world's footprint itself
    assert values['unicycle_simulator']['world_file'].endswith('narrow_gap.yaml')
    assert 'footprint' not in values['unicycle_simulator']


@pytest.mark.parametrize(('footprint', 'reason'), [
    ('[[0, 0], [1, 1]]', 'at least 3'),
    ('[[0.3, 0.2], [-0.3, 0.2], [0.0, 0.0], [-0.3, -0.2], [0.3, -0.2]]', 'not convex'),
    ('[]', 'give a convex polygon'),
])
def test_an_invalid_footprint_argument_is_refused_at_launch_with_the_reason(
        monkeypatch: pytest.MonkeyPatch, footprint: str, reason: str) -> None:
    with pytest.raises(RuntimeError, match=reason):
        _describe(ROOT / 'launch' / 'simulation.launch.py', monkeypatch,
                  {'footprint': footprint})


@pytest.mark.dds
@pytest.mark.parametrize(('name', 'launch_arguments'), [
    ('simulation.launch.py', {}),
    ('simulation.launch.py', {'sensing': 'true', 'world': 'narrow_gap', 'record': 'true',
                              'footprint': JACKAL_TEXT, 'reality': 'real'}),
    ('navigation.launch.py', {'map': 'maps/paper_obstacle.yaml'}),
])
def test_every_node_a_launch_file_starts_takes_its_files_and_parameters_without_a_refusal(
        name: str, launch_arguments: dict[str, str], monkeypatch: pytest.MonkeyPatch,
        ros: Any, tmp_path: Path) -> None:
    # a node refuses a parameter it does not declare: none the launch file gives may be one
    from rclpy.parameter import Parameter

    arguments, nodes = _describe(ROOT / 'launch' / name, monkeypatch, launch_arguments)
    given = {**arguments, **launch_arguments}

    def value(item: Any) -> Any:  # what launch_ros makes of a launch argument: YAML
        return yaml.safe_load(item.perform(given)) if isinstance(item, _LaunchConfiguration) \
            else item

    for node in nodes:
        files, values = [], {}
        for entry in node.kwargs['parameters']:
            if isinstance(entry, dict):
                values.update({k: value(v) for k, v in entry.items()})
            else:  # a params file: an installed path, or an argument naming one
                path = entry.perform(given) if isinstance(entry, _LaunchConfiguration) else entry
                files += ['--params-file', path.replace(SHARE, str(ROOT))]
        if node.kwargs['executable'] == 'bag_recorder':
            values['output'] = str(tmp_path / 'bag')
        module = importlib.import_module(
            f"mpc_local_planner.ros.{node.kwargs['executable']}_node")
        node_class = next(v for k, v in vars(module).items() if k.endswith('Node')
                          and isinstance(v, type) and v.__module__ == module.__name__)
        made = ros.add(node_class(context=ros.context, cli_args=['--ros-args', *files],
                                  parameter_overrides=[Parameter(k, value=v)
                                                       for k, v in values.items()]))
        assert made.get_name() == node.kwargs['name']
