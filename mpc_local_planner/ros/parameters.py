# SPDX-License-Identifier: Apache-2.0
"""Parameters declared from one table per node, and the ``--help`` text made from it.

Each node lists its parameters once, as ParameterSpec rows (name, default, description,
range): the node declares them from the table, and ``<executable> --help`` prints the same
table without starting ROS, so the help can never disagree with what the node declares.

A parameter given to a node that it does not declare is refused (`declare_parameters` raises
UnknownParameterError, naming the closest declared name): rclpy itself ignores it without a
word, so ``horizn: 15`` in a params file would leave ``horizon`` at its default. rclpy's own
parameters (ROS_OWN_PARAMETERS, ``qos_overrides.*``) are always accepted. The params files of
a command line are read here too (`params_files`, `params_file_problem`, `params_sections`,
`section_applies`), so that a node can say in one line why a file cannot be used, or that it
holds no section for the node, as ROS matches sections to nodes.

A range is enforced on every set: by rclpy for a number (its descriptor's range), and by
the node's own set-parameters callback, through `range_problems`, for what rclpy does not
check: each element of an array, and the values between a range and its ``special`` value
(e.g. -1, "the preset's", beside 0 .. 10).
"""

from __future__ import annotations

import difflib
import math
from pathlib import Path
import re
from typing import Any, Iterable, NamedTuple, Sequence

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.node import Node
from rclpy.parameter import Parameter
import yaml

__all__ = ['ROS_OWN_PARAMETERS', 'ROS_OWN_PREFIXES', 'ParameterSpec', 'UnknownParameterError',
           'declare_parameters', 'describe', 'format_default', 'format_help', 'format_range',
           'params_file_problem', 'params_file_sections', 'params_files', 'params_sections',
           'range_problem', 'range_problems', 'refuse_unknown_parameters', 'section_applies',
           'unknown_parameters']

# Parameters rclpy declares or reads in every node by itself: never a typo of the package's.
ROS_OWN_PARAMETERS = frozenset({'use_sim_time', 'start_type_description_service'})
# Groups of parameters rclpy declares when it needs them (a publisher's QoS overrides).
ROS_OWN_PREFIXES = ('qos_overrides.',)


class UnknownParameterError(ValueError):
    """A node was given a parameter it does not declare (most likely a misspelt one)."""


# math.isclose's tolerance at a range's ends, as rclpy's (Node.PARAM_REL_TOL).
_REL_TOL = 1e-6


def describe(description: str, *, float_range: tuple[float, float] | None = None,
             int_range: tuple[int, int] | None = None, read_only: bool = False,
             dynamic_typing: bool = False, array: bool = False) -> ParameterDescriptor:
    """Return a ParameterDescriptor with an optional range (rclpy enforces it on set).

    Args:
        description: what the parameter does, its unit, and when a change takes effect.
        float_range: inclusive (from, to) for a double parameter.
        int_range: inclusive (from, to) for an integer parameter.
        read_only: refuse every change after the declaration.
        dynamic_typing: allow the type to change (e.g. an optional array given as []).
        array: the range is each element's (shown by ``ros2 param describe``; rclpy does not
            check arrays: `range_problem` does).

    """
    descriptor = ParameterDescriptor(description=description, read_only=read_only,
                                     dynamic_typing=dynamic_typing)
    if float_range is not None:
        descriptor.type = (ParameterType.PARAMETER_DOUBLE_ARRAY if array
                           else ParameterType.PARAMETER_DOUBLE)
        descriptor.floating_point_range = [
            FloatingPointRange(from_value=float(float_range[0]), to_value=float(float_range[1]),
                               step=0.0)]
    if int_range is not None:
        descriptor.type = (ParameterType.PARAMETER_INTEGER_ARRAY if array
                           else ParameterType.PARAMETER_INTEGER)
        descriptor.integer_range = [
            IntegerRange(from_value=int(int_range[0]), to_value=int(int_range[1]), step=0)]
    return descriptor


class ParameterSpec(NamedTuple):
    """One parameter of a node: declared from this row, and listed by ``--help``.

    Attributes:
        name: the parameter's name (dots for groups, e.g. ``weights.position``).
        default: its default value; a ``Parameter.Type`` for a parameter without one (it is
            then unset unless given, e.g. an optional goal).
        description: what it does, its unit, and when a change takes effect.
        float_range: inclusive (from, to) for a double, enforced on every set; for an array
            of doubles, each element's.
        int_range: inclusive (from, to) for an integer (for an array: each element's).
        read_only: refuse changes after start (e.g. what only matters at configure).
        special: a value outside the range that is accepted too (for an array: as an
            element), with the meaning the description gives it: -1 = "the preset's" for
            the simulator's reality overrides, 0 = "none" for the controller's rate limits.

    """

    name: str
    default: Any
    description: str
    float_range: tuple[float, float] | None = None
    int_range: tuple[int, int] | None = None
    read_only: bool = False
    special: float | None = None

    @property
    def is_array(self) -> bool:
        """Whether the parameter is an array (its range is each element's)."""
        return isinstance(self.default, (list, tuple))

    def descriptor(self) -> ParameterDescriptor:
        """Return the ParameterDescriptor rclpy declares it with.

        Its range spans the special value too (rclpy checks that hull; `range_problem` the
        values between).
        """
        float_range, int_range = self.float_range, self.int_range
        if self.special is not None and float_range is not None:
            float_range = (min(float_range[0], self.special), max(float_range[1], self.special))
        if self.special is not None and int_range is not None:
            int_range = (min(int_range[0], int(self.special)),
                         max(int_range[1], int(self.special)))
        return describe(self.description, float_range=float_range, int_range=int_range,
                        read_only=self.read_only, array=self.is_array)


def format_range(spec: ParameterSpec, *, each: str = 'each ') -> str:
    """Return the range as --help and docs/parameters.md show it ('' without one).

    An array's range is each element's: each prefixes it.
    """
    if spec.int_range is not None:
        text = f'{spec.int_range[0]} .. {spec.int_range[1]}'
    elif spec.float_range is not None:
        text = f'{spec.float_range[0]:g} .. {spec.float_range[1]:g}'
    else:
        return ''
    if spec.special is not None:
        text = f'{spec.special:g}, or {text}'
    return f'{each}{text}' if spec.is_array else text


def _within(value: float, limits: tuple[float, float]) -> bool:
    low, high = limits
    return (low <= value <= high or math.isclose(value, low, rel_tol=_REL_TOL)
            or math.isclose(value, high, rel_tol=_REL_TOL))


def range_problem(spec: ParameterSpec, value: Any) -> str | None:
    """Say why value is outside spec's range (each element, for an array), or None.

    A value of another type is not judged here (rclpy refuses a wrong type, the nodes'
    checks the rest); NaN is outside every range.
    """
    limits = spec.float_range or spec.int_range
    if limits is None or isinstance(value, (str, bytes, bool)):
        return None
    try:
        values = [float(v) for v in value] if spec.is_array else [float(value)]
    except (TypeError, ValueError):
        return None
    if all(v == spec.special or _within(v, limits) for v in values):
        return None
    if spec.is_array:
        return f'{spec.name} must be {format_range(spec, each="")} each, got {list(value)}'
    return f'{spec.name} must be {format_range(spec)}, got {value}'


def range_problems(specs: Sequence[ParameterSpec], parameters: Sequence[Parameter]
                   ) -> list[str]:
    """Return why each parameter is outside its spec's range (`range_problem`); [] if none.

    For a node's set-parameters callback: it checks what rclpy does not (arrays, a special
    value beside a range), after the node's own, more specific checks.
    """
    by_name = {spec.name: spec for spec in specs}
    return [reason for p in parameters if p.name in by_name
            and (reason := range_problem(by_name[p.name], p.value)) is not None]


def declare_parameters(node: Node, specs: Sequence[ParameterSpec]) -> None:
    """Declare every row of specs on node, then refuse a parameter given that is none of them.

    Register the set-parameters callback first. Call once, after which the node declares
    nothing else.

    Raises:
        UnknownParameterError: a params file, ``-p`` or an override names an undeclared
            parameter (see refuse_unknown_parameters).

    """
    for spec in specs:
        node.declare_parameter(spec.name, spec.default, spec.descriptor())
    refuse_unknown_parameters(node)


def unknown_parameters(given: Iterable[str], declared: Iterable[str]) -> list[str]:
    """Return one line per given name that is not declared, with the closest declared name.

    rclpy's own parameters (ROS_OWN_PARAMETERS, ROS_OWN_PREFIXES) are never unknown.
    """
    known = sorted(set(declared) | ROS_OWN_PARAMETERS)
    problems = []
    for name in sorted(set(given)):
        if name in known or name.startswith(ROS_OWN_PREFIXES):
            continue
        close = difflib.get_close_matches(name, known, n=1)
        hint = f"did you mean '{close[0]}'?" if close else '--help lists the parameters'
        problems.append(f"unknown parameter '{name}' ({hint})")
    return problems


def refuse_unknown_parameters(node: Node) -> None:
    """Raise UnknownParameterError if node was given a parameter it has not declared.

    What the node was given is rclpy's ``_parameter_overrides``: the values of the params
    files' sections that apply to the node, of ``-p``, and of the constructor's
    parameter_overrides. rclpy has no public accessor for them, and ignores those no
    declaration takes.

    Raises:
        UnknownParameterError: one line, every unknown name with its closest declared one.

    """
    declared = node.list_parameters([], 0).names  # depth 0: every depth
    problems = unknown_parameters(node._parameter_overrides, declared)
    if problems:
        raise UnknownParameterError('; '.join(problems))


def params_files(args: Sequence[str]) -> list[str]:
    """Return the files ``--params-file`` names in the ``--ros-args`` parts of args."""
    files: list[str] = []
    ros = False
    tokens = iter(args)
    for token in tokens:
        if token == '--ros-args':
            ros = True
        elif token == '--':
            ros = False
        elif ros and token == '--params-file':
            files.append(next(tokens, ''))
    return files


def params_file_problem(path: str) -> str | None:
    """Return why a params file cannot be read as YAML, in one line (None: it can).

    Only what rcl would refuse too: a missing or unreadable file, or one that is not YAML.
    What rcl alone refuses (a value outside ros__parameters, a list of mixed types) is left
    to rcl.
    """
    try:
        text = Path(path).read_text(encoding='utf-8')
    except FileNotFoundError:
        return f'params file {path!r} not found'
    except (OSError, UnicodeDecodeError) as err:
        return f'params file {path!r} cannot be read: {err}'
    try:
        yaml.safe_load(text)
    except yaml.YAMLError as err:
        return f'params file {path!r} is not valid YAML: {_yaml_error(err)}'
    return None


def _yaml_error(err: yaml.YAMLError) -> str:
    """Return what PyYAML found wrong and where, on one line."""
    mark = getattr(err, 'problem_mark', None)
    what = '; '.join(str(part) for part in (getattr(err, 'context', None),
                                            getattr(err, 'problem', None)) if part)
    if mark is None or not what:
        return ' '.join(str(err).split())
    return f'{what} (line {mark.line + 1}, column {mark.column + 1})'


def params_sections(path: str) -> list[str]:
    """Return the node names a params file has sections for, as rcl reads them.

    Nested names join with '/' (``ns: {node: {ros__parameters: ...}}`` is ``ns/node``); an
    unreadable file has none.
    """
    try:
        data = yaml.safe_load(Path(path).read_text(encoding='utf-8'))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return []
    return [name for name, _ in params_file_sections(data)]


def params_file_sections(data: Any) -> list[tuple[str, Any]]:
    """Return a params file's sections in file order, as (node name, its ros__parameters).

    The one walk of a params file's nesting, as rcl reads it: nested names join with '/'
    (``ns: {node: {ros__parameters: ...}}`` is ``ns/node``). A ros__parameters at the top
    names no node and is left out; the values are as YAML gave them (not always a mapping).

    Args:
        data: The file as ``yaml.safe_load`` read it (anything but a mapping has none).

    """
    sections: list[tuple[str, Any]] = []

    def visit(mapping: dict, prefix: str) -> None:
        for key, value in mapping.items():
            if key == 'ros__parameters':
                if prefix:
                    sections.append((prefix, value))
            elif isinstance(value, dict):
                visit(value, f'{prefix}/{key}' if prefix else str(key))

    if isinstance(data, dict):
        visit(data, '')
    return sections


def section_applies(section: str, fully_qualified_name: str) -> bool:
    """Say whether a params file's section applies to a node, as rcl and rclpy match them.

    A leading '/' is implied; ``/*`` stands for one name (``/**`` for any number), so ``/**``
    applies to every node and ``/ns/*`` to every node right in ``/ns``.
    """
    name = section if section.startswith('/') else '/' + section
    pattern = name.replace('/*', r'(/\w+)')
    try:
        return re.fullmatch(pattern, fully_qualified_name) is not None
    except re.error:
        return name == fully_qualified_name


def format_default(value: Any) -> str:
    """Return a default as --help and docs/parameters.md show it."""
    if isinstance(value, Parameter.Type):
        return '(unset)'
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(format_default(v) for v in value) + ']'
    return f'{value:g}' if isinstance(value, float) else str(value)


def format_help(executable: str, summary: str, specs: Sequence[ParameterSpec]) -> str:
    """Return the ``--help`` text: usage, what the node does, and its parameters."""
    lines = [f'usage: {executable} [--help] [--ros-args -p NAME:=VALUE ... '
             '--params-file FILE ...]', '', summary.strip(), '',
             'parameters (name, default, range: description):']
    width = max((len(spec.name) for spec in specs), default=0)
    for spec in specs:
        bounds = f' [{format_range(spec)}]' if spec.float_range or spec.int_range else ''
        lines.append(f'  {spec.name:<{width}}  {format_default(spec.default)}{bounds}: '
                     f'{spec.description}')
    return '\n'.join(lines) + '\n'
