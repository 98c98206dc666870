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

"""Parameter helpers: descriptors with a description and range, and shared defaults."""

from __future__ import annotations

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)

__all__ = ['DEFAULT_WORLD_FILE', 'describe']

# The world every node and closed_loop use unless told otherwise: the paper's scenario.
DEFAULT_WORLD_FILE = 'worlds/paper_obstacle.yaml'


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
