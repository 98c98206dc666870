# SPDX-License-Identifier: Apache-2.0
"""One row of runs.csv as typed values, and its CSV form both ways.

A sweep writes its rows as they come and reads them back (``--resume``, ``--plot``, the
summary of a resumed sweep): read back, a boolean is a bool again, a number a number and an
empty cell None, so no reader compares strings. The CSV form is what the csv module writes
of the values (None empty, True/False, Python's shortest float repr), so files written by
earlier sweeps read back and write out unchanged.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

from mpc_local_planner.core.controllers import controller_name, ControllerName

__all__ = ['RUN_COLUMNS', 'RunRow']


@dataclass
class RunRow:
    """One closed-loop run of a sweep (None: the value does not apply to the run).

    Attributes:
        controller: The local controller.
        world: The world's number in its suite.
        success: Reached the goal within the suite's rule, without contact.
        collision: The true footprint touched an obstacle.
        time: Seconds of simulated time at the last row.
        path_length: Metres driven.
        min_clearance: Least clearance of the true footprint, metres.
        solve_ms_median: Median of the controller's own solve times, ms.
        solve_ms_max: Largest of them, ms.
        barn_score: The BARN challenge's score (BARN worlds only).
        assumption_1: The reference path satisfies the paper's Assumption 1 (known map).
        reference_length: The reference path's length, metres (known map).
        final_distance: Metres from the last position to the goal.
        steps: Rows of the run.
        stop_reason: Why the run ended (Outcome's word, ': ' and a note), or why it did not run.
        planner_clearance: The planner's clearance of the reference path (known map).
        solver_failures: Steps whose input is not a fresh solver solution.
        v_max: The robot's largest speed, m/s.
        robot: The robot's name.
        sensing: The run sensed with its laser (a navigation run).
        contacts: 1 if the run touched an obstacle, else 0.
        replans: Plans after the first.
        replan_failures: Re-plans that found no path.
        step_ms_median: Median wall time of a control step, ms.
        step_ms_max: Largest of them, ms.
        plan_s_max: Longest planning, seconds.
        name: The world's name.
        reality: How real the robot was (sim/reality.py preset; navigation runs).
        active_contacts: Of contacts, 1 if the robot was moving into it (navigation runs).
        passive_contacts: Of contacts, 1 if it stood still and an obstacle ran into it.
        recoveries: Recoveries started (core/recoveries.py; navigation runs with them).
        recovery_s: Seconds the recoveries took, in all (back-out, spin and wait).

    """

    controller: ControllerName
    world: int
    success: bool | None = None
    collision: bool | None = None
    time: float | None = None
    path_length: float | None = None
    min_clearance: float | None = None
    solve_ms_median: float | None = None
    solve_ms_max: float | None = None
    barn_score: float | None = None
    assumption_1: bool | None = None
    reference_length: float | None = None
    final_distance: float | None = None
    steps: int | None = None
    stop_reason: str = ''
    planner_clearance: float | None = None
    solver_failures: int | None = None
    v_max: float | None = None
    robot: str = ''
    sensing: bool | None = None
    contacts: int | None = None
    replans: int | None = None
    replan_failures: int | None = None
    step_ms_median: float | None = None
    step_ms_max: float | None = None
    plan_s_max: float | None = None
    name: str = ''
    reality: str = ''
    active_contacts: int | None = None
    passive_contacts: int | None = None
    recoveries: int | None = None
    recovery_s: float | None = None

    @property
    def key(self) -> tuple[int, ControllerName]:
        """The run the row is of: (world, controller)."""
        return self.world, self.controller

    def to_csv(self) -> dict[str, Any]:
        """Return the row for csv.DictWriter (None writes an empty cell)."""
        return asdict(self)

    @classmethod
    def from_csv(cls, cells: dict[str, str]) -> RunRow:
        """Return the row of runs.csv's cells (as csv.DictReader reads them).

        A row shorter than the header (a table an earlier version wrote, before a column was
        added) reads its missing cells as empty.

        Raises:
            ValueError: for a cell that is not its column's type.

        """
        values: dict[str, Any] = {}
        for column, parse in _PARSERS.items():
            text = cells.get(column) or ''
            values[column] = text if parse is str else None if text == '' else parse(text)
        return cls(**values)


def _bool(text: str) -> bool:
    if text in ('True', 'true', '1'):
        return True
    if text in ('False', 'false', '0'):
        return False
    msg = f'not a boolean: {text!r}'
    raise ValueError(msg)


def _parser(annotation: str) -> Any:
    """Return the parser of a field's cell from its annotation (str, int, bool | None...)."""
    if annotation == 'ControllerName':
        return controller_name
    for prefix, parse in (('bool', _bool), ('int', int), ('float', float)):
        if annotation.startswith(prefix):
            return parse
    return str


_PARSERS = {f.name: _parser(str(f.type)) for f in fields(RunRow)}
RUN_COLUMNS = tuple(_PARSERS)
