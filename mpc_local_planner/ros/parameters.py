# Copyright 2026 mpc_local_planner developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Parameters declared from one table per node, and the ``--help`` text made from it.

Each node lists its parameters once, as ParameterSpec rows (name, default, description,
range): the node declares them from the table, and ``<executable> --help`` prints the same
table without starting ROS, so the help can never disagree with what the node declares.

A range is enforced on every set: by rclpy for a number (its descriptor's range), and by
the node's own set-parameters callback, through `range_problems`, for what rclpy does not
check: each element of an array, and the values between a range and its ``special`` value
(e.g. -1, "the preset's", beside 0 .. 10).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple, Sequence

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

__all__ = ['DEFAULT_WORLD_FILE', 'ParameterSpec', 'declare_parameters', 'describe',
           'format_default', 'format_help', 'format_range', 'range_problem', 'range_problems']

# The world every node and closed_loop use unless told otherwise: the paper's scenario.
DEFAULT_WORLD_FILE = 'worlds/paper_obstacle.yaml'


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
    """Declare every row of specs on node (register the set-parameters callback first)."""
    for spec in specs:
        node.declare_parameter(spec.name, spec.default, spec.descriptor())


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
