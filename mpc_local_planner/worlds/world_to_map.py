# SPDX-License-Identifier: Apache-2.0
"""``world_to_map WORLD --resolution R --out DIR``: a world's known obstacles as a map file.

Writes ``DIR/<world name>.yaml`` and ``.pgm`` in the map_server format, so that nav2's
map_server (or ours) can serve the map the robot is given; unknown obstacles are left out.
Bad input ends with exit code 2 and one line on stderr, like argparse's own errors.
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import NoReturn, Sequence

from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.map_files import rasterize_world, save_map
from mpc_local_planner.worlds.world import load_world

__all__ = ['main']

_PROG = 'world_to_map'


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line (no usage block)."""

    def error(self, message: str) -> NoReturn:
        """Print one line and exit with status 2."""
        self.exit(2, f'{self.prog}: error: {message}\n')


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=_PROG, description=__doc__.splitlines()[0])
    parser.add_argument('world', help='world file (.yaml or BARN .json), or a shipped name')
    parser.add_argument('--resolution', type=float, required=True, help='cell side, metres')
    parser.add_argument('--out', required=True, help='output folder')
    parser.add_argument('--margin', type=float, default=0.0,
                        help='free border around the bounds, metres (default 0)')
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line.

    Args:
        argv: Arguments without the program name (default: sys.argv[1:]).

    Returns:
        0 on success, 2 on bad input.

    """
    parser = _parser()
    args = parser.parse_args(argv)
    if not (math.isfinite(args.resolution) and args.resolution > 0.0):
        parser.error(f'--resolution must be > 0, got {args.resolution}')
    if not (math.isfinite(args.margin) and args.margin >= 0.0):
        parser.error(f'--margin must be >= 0, got {args.margin}')
    try:
        world = load_world(resolve_data_file(args.world))
        occupancy = rasterize_world(world, args.resolution, margin=args.margin)
        yaml_path = save_map(occupancy, args.out, world.name)
    except (OSError, ValueError) as err:
        message = ' '.join(str(err).split())
        print(f'{_PROG}: error: {message}', file=sys.stderr)
        return 2
    print(f'{yaml_path} ({occupancy.width} x {occupancy.height} cells)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
