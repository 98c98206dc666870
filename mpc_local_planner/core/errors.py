# SPDX-License-Identifier: Apache-2.0
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
