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
"""docs/parameters.md is the nodes' parameter tables, as they are now."""

from __future__ import annotations

from pathlib import Path

from mpc_local_planner.ros.parameter_docs import NODES, render

DOCS = Path(__file__).resolve().parents[2] / 'docs' / 'parameters.md'


def test_the_parameter_reference_is_the_nodes_tables():
    assert DOCS.read_text(encoding='utf-8') == render(), (
        'docs/parameters.md is stale: run '
        'python3 -m mpc_local_planner.ros.parameter_docs docs/parameters.md')


def test_every_declared_parameter_has_a_row():
    text = DOCS.read_text(encoding='utf-8')
    for node in NODES:
        assert f'## `{node.executable}`' in text
        for spec in node.parameters:
            assert f'| `{spec.name}` |' in text
    # the ones the hand-written tables had lost
    assert '| `max_solve_time` |' in text
    assert '| `footprint` |' in text.split('## `unicycle_simulator`')[1]
