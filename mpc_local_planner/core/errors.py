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

"""Exceptions of the package, one per role, so that callers catch exactly what they handle."""

from __future__ import annotations

__all__ = ['PlanningError', 'WorldError']


class PlanningError(Exception):
    """The global planner could not produce a collision-free path (or its inputs are invalid)."""


class WorldError(ValueError):
    """A world description (YAML or BARN JSON) is malformed or inconsistent.

    A ValueError subclass: a bad world file is a bad value, and callers that already catch
    ValueError keep working.
    """
