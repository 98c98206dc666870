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
"""

from __future__ import annotations

from typing import Any, NamedTuple, Sequence

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

__all__ = ['ParameterSpec', 'declare_parameters', 'describe', 'format_default', 'format_help']


def describe(description: str, *, float_range: tuple[float, float] | None = None,
             int_range: tuple[int, int] | None = None, read_only: bool = False,
             dynamic_typing: bool = False) -> ParameterDescriptor:
    """Return a ParameterDescriptor with an optional range (rclpy enforces it on set).

    Args:
        description: what the parameter does, its unit, and when a change takes effect.
        float_range: inclusive (from, to) for a double parameter.
        int_range: inclusive (from, to) for an integer parameter.
        read_only: refuse every change after the declaration.
        dynamic_typing: allow the type to change (e.g. an optional array given as []).

    """
    descriptor = ParameterDescriptor(description=description, read_only=read_only,
                                     dynamic_typing=dynamic_typing)
    if float_range is not None:
        descriptor.type = ParameterType.PARAMETER_DOUBLE
        descriptor.floating_point_range = [
            FloatingPointRange(from_value=float(float_range[0]), to_value=float(float_range[1]),
                               step=0.0)]
    if int_range is not None:
        descriptor.type = ParameterType.PARAMETER_INTEGER
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
        float_range: inclusive (from, to) for a double, enforced by rclpy on every set.
        int_range: inclusive (from, to) for an integer.
        read_only: refuse changes after start (e.g. what only matters at configure).

    """

    name: str
    default: Any
    description: str
    float_range: tuple[float, float] | None = None
    int_range: tuple[int, int] | None = None
    read_only: bool = False

    def descriptor(self) -> ParameterDescriptor:
        """Return the ParameterDescriptor rclpy declares it with."""
        return describe(self.description, float_range=self.float_range,
                        int_range=self.int_range, read_only=self.read_only)


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
        limits = spec.float_range or spec.int_range
        bounds = f' [{limits[0]:g}, {limits[1]:g}]' if limits else ''
        lines.append(f'  {spec.name:<{width}}  {format_default(spec.default)}{bounds}: '
                     f'{spec.description}')
    return '\n'.join(lines) + '\n'
