# SPDX-License-Identifier: Apache-2.0
"""runs.csv's row: typed values read back, and the same bytes written out."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest

from mpc_local_planner.core.controllers import ControllerName
from mpc_local_planner.evaluation.run_row import RUN_COLUMNS, RunRow
from mpc_local_planner.evaluation.suite_runs import CSV_COLUMNS

# rows as a sweep before the typed row wrote them (a known-map run, a navigation run, a run
# with no plan and an error), header included; the contact split's and the recoveries'
# cells empty
EARLIER = (
    ','.join(CSV_COLUMNS) + '\r\n'
    'tracking,0,False,False,80.60000000000001,4.304317101148031,0.12,3.1,9.5,,True,,'
    '1.5,404,time limit,0.081,335,0.31,circle,False,0,0,,0.5,2.25,,random 0,,,,,\r\n'
    'dwa,1,True,False,11.600000000000001,9.247130494217885,0.05,0.4,1.2,0.5,,,0.98,59,'
    'reached,,0,2.0,jackal,True,0,3,1,nan,inf,0.07,BARN 1,real,,,,\r\n'
    'regulated_pure_pursuit,2,False,False,,,,,,0.0,,,,,no plan: blocked,,,2.0,jackal,'
    'True,,,,,,,BARN 2,ideal,,,,\r\n'
    'proposed,3,False,False,,,,,,,,,,,error: KilledWorker: gone,,,0.31,circle,False,,,,,,,,'
    ',,,,\r\n'
)


def _round_trip(tmp_path: Path) -> tuple[list[RunRow], bytes]:
    source = tmp_path / 'runs.csv'
    source.write_bytes(EARLIER.encode())
    with open(source, newline='', encoding='utf-8') as stream:
        rows = [RunRow.from_csv(cells) for cells in csv.DictReader(stream)]
    target = tmp_path / 'again.csv'
    with open(target, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.DictWriter(stream, fieldnames=RUN_COLUMNS)
        writer.writeheader()
        writer.writerows(row.to_csv() for row in rows)
    return rows, target.read_bytes()


def test_the_columns_are_the_tables(tmp_path: Path) -> None:
    assert RUN_COLUMNS == CSV_COLUMNS


def test_values_read_back_typed_and_empty_cells_as_none(tmp_path: Path) -> None:
    rows, _ = _round_trip(tmp_path)
    tracking, dwa, no_plan, error = rows
    assert tracking.controller is ControllerName.TRACKING and tracking.world == 0
    assert tracking.success is False and tracking.assumption_1 is True
    assert dwa.success is True and dwa.sensing is True and dwa.replans == 3
    assert dwa.steps == 59 and dwa.time == pytest.approx(11.6)
    assert math.isnan(dwa.step_ms_median) and math.isinf(dwa.step_ms_max)
    assert no_plan.time is None and no_plan.barn_score == 0.0 and no_plan.reality == 'ideal'
    assert error.stop_reason == 'error: KilledWorker: gone' and error.name == ''
    assert all(isinstance(getattr(row, column), bool) for row in rows
               for column in ('success', 'collision', 'sensing'))


def test_an_earlier_table_is_written_out_byte_for_byte(tmp_path: Path) -> None:
    _, again = _round_trip(tmp_path)
    assert again == EARLIER.encode()


def test_a_cell_of_another_type_is_refused() -> None:
    cells = dict.fromkeys(RUN_COLUMNS, '')
    cells.update(controller='dwa', world='0', success='maybe')
    with pytest.raises(ValueError, match='not a boolean'):
        RunRow.from_csv(cells)
    cells.update(success='True', controller='teb')
    with pytest.raises(ValueError, match='unknown controller'):
        RunRow.from_csv(cells)
