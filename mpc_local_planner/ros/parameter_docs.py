# SPDX-License-Identifier: Apache-2.0
"""docs/parameters.md, written from the nodes' ParameterSpec tables (as ``--help`` is).

Each node declares its parameters from one table (ros/parameters.py), and ``--help`` prints
that table; this module renders the same tables as Markdown, so the reference a user reads
cannot drift from what the nodes declare. ``test/ros/test_parameter_docs.py`` fails when the
file in the repository is stale;
``python3 -m mpc_local_planner.ros.parameter_docs docs/parameters.md`` writes it again.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import sys
from typing import NamedTuple, Sequence

from mpc_local_planner.ros import (
    bag_recorder_node,
    global_planner_node,
    global_planner_parameters,
    map_server_node,
    mpc_controller_node,
    mpc_controller_parameters,
    unicycle_simulator_node,
    unicycle_simulator_parameters,
)
from mpc_local_planner.ros.parameters import format_default, format_range, ParameterSpec

__all__ = ['NODES', 'NodeTable', 'render', 'main']


class NodeTable(NamedTuple):
    """A node's name, what it does, and its parameter table."""

    executable: str
    summary: str
    parameters: Sequence[ParameterSpec]


NODES: tuple[NodeTable, ...] = (
    NodeTable('mpc_controller', mpc_controller_node.SUMMARY,
              mpc_controller_parameters.PARAMETERS),
    NodeTable('global_planner', global_planner_node.SUMMARY,
              global_planner_parameters.PARAMETERS),
    NodeTable('unicycle_simulator', unicycle_simulator_node.SUMMARY,
              unicycle_simulator_parameters.PARAMETERS),
    NodeTable('map_server', map_server_node.SUMMARY, map_server_node.PARAMETERS),
    NodeTable('bag_recorder', bag_recorder_node.SUMMARY, bag_recorder_node.PARAMETERS),
)

_HEADER = """\
# Node parameters

Generated from the nodes' parameter tables by
`python3 -m mpc_local_planner.ros.parameter_docs docs/parameters.md` (a test fails when this
file is stale); `<executable> --help` prints the same table. Every node also takes
`use_sim_time`. Invalid values are refused with a reason: at start with exit code 2, at run
time by the set-parameters call (the value in force stays).
"""


def _cell(text: str) -> str:
    """Return text fit for a Markdown table cell (no pipes, one line)."""
    return ' '.join(str(text).split()).replace('|', '\\|')


def render(nodes: Sequence[NodeTable] = NODES) -> str:
    """Return docs/parameters.md: one section per node, one row per parameter."""
    parts = [_HEADER]
    for node in nodes:
        parts.append(f'\n## `{node.executable}`\n\n{_cell(node.summary)}\n')
        parts.append('| parameter | default | range | description |\n|---|---|---|---|')
        for spec in node.parameters:
            parts.append(f'| `{spec.name}` | `{_cell(format_default(spec.default))}` | '
                         f'{format_range(spec)} | {_cell(spec.description)} |')
    return '\n'.join(parts) + '\n'


def main(argv: Sequence[str] | None = None) -> int:
    """Write the reference to the given file, or print it."""
    parser = argparse.ArgumentParser(prog='parameter_docs', description=__doc__.splitlines()[0])
    parser.add_argument('output', nargs='?', type=Path, default=None,
                        help='file to write (default: print)')
    args = parser.parse_args(argv)
    text = render()
    if args.output is None:
        sys.stdout.write(text)
    else:
        args.output.write_text(text, encoding='utf-8')
    return 0


if __name__ == '__main__':
    sys.exit(main())
