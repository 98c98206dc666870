# SPDX-License-Identifier: Apache-2.0
"""Find the files the package ships: configs, worlds and the BARN worlds.

A parameter such as ``world_file: paper_obstacle`` should work whichever way the package was
installed, and should read the files that came with the code that runs, not those of another
copy of the package in the same environment (a checkout tested beside a ``pip install .`` or a
sourced colcon workspace, an overlay over an underlay): a copy's parameter files hold that
copy's parameters. So the share directory is looked for beside the code first: a source
checkout (editable install, tests) is its own share directory (``config/``, ``launch/``,
``rviz/``, ``package.xml``, as ``setup.py`` installs them); an installed copy
(``pip install .``, ``pip install --user``, colcon) has ``<prefix>/share/mpc_local_planner``
in the prefix it was installed into. Only where neither exists (an unusual layout) are the
ament index, ``sys.prefix`` and the user base asked. The BARN worlds are package data, so
they travel inside the Python package itself.

``mpc_local_planner_share`` (`main`) prints the share directory: the pip route's
``ros2 pkg prefix --share mpc_local_planner``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import site
import sys

__all__ = ['BARN_DIR', 'PACKAGE_NAME', 'config_roots', 'main', 'resolve_data_file',
           'share_directory']

PACKAGE_NAME = 'mpc_local_planner'
# The Python package's folder, mpc_local_planner/ (this file is in its worlds/).
_PACKAGE_DIR = Path(__file__).resolve().parents[1]
# The BARN worlds 0-99 and 200-299 shipped with the package (MIT notice in the same folder).
BARN_DIR = _PACKAGE_DIR / 'data' / 'barn'
# Suffixes tried when a name is given without one (``--world rrt_cluttered``).
_SUFFIXES = ('', '.yaml', '.yml')


def _is_share(path: Path) -> bool:
    """Return whether path holds what setup.py installs under share/ (package.xml, config/)."""
    return (path / 'package.xml').is_file() and (path / 'config').is_dir()


def _own_share_directory() -> Path | None:
    """Return the share directory that came with this copy of the code (None if not found)."""
    checkout = _PACKAGE_DIR.parent
    if (checkout / 'setup.py').is_file() and _is_share(checkout):
        return checkout
    # installed: <prefix>/lib/pythonX.Y/site-packages/mpc_local_planner, data in
    # <prefix>/share (<prefix>/Lib/site-packages on Windows)
    for prefix in checkout.parents[:3]:
        share = prefix / 'share' / PACKAGE_NAME
        if _is_share(share):
            return share
    return None


def _other_share_directories() -> list[Path]:
    """Return where else a share directory of the package may lie: ament index, prefixes."""
    found: list[Path] = []
    try:
        from ament_index_python.packages import get_package_share_directory

        found.append(Path(get_package_share_directory(PACKAGE_NAME)))
    except Exception:  # no AMENT_PREFIX_PATH, or the package is not in the index
        pass
    for prefix in (sys.prefix, site.getuserbase()):
        found.append(Path(prefix) / 'share' / PACKAGE_NAME)
    return found


def share_directory() -> Path:
    """Return the package's share directory: config/ (with worlds/ and maps/), launch/, rviz/.

    The one that came with the code that runs (see the module's docstring), else the first
    of the ament index's, sys.prefix's and the user base's.

    Raises:
        FileNotFoundError: if there is none (the message says where it looked).

    """
    own = _own_share_directory()
    if own is not None:
        return own
    others = _other_share_directories()
    for share in others:
        if _is_share(share):
            return share
    msg = (f'no share/{PACKAGE_NAME} (package.xml and config/) beside {_PACKAGE_DIR} nor at '
           + ', '.join(str(share) for share in others))
    raise FileNotFoundError(msg)


def config_roots() -> list[Path]:
    """Return the folder holding the package's configs, [] if there is no share directory."""
    try:
        return [share_directory() / 'config']
    except FileNotFoundError:
        return []


def resolve_data_file(name: str | Path) -> Path:
    """Find a file named by a parameter or an option.

    Tried in order: the name as given (absolute, or relative to the working directory),
    then under config_roots() and its ``worlds/``; a name without a suffix also tries
    ``.yaml`` and ``.yml``.

    Raises:
        FileNotFoundError: if no candidate exists (the message lists where it looked).

    """
    path = Path(name).expanduser()
    bases = [path]
    if not path.is_absolute():
        for root in config_roots():
            bases += [root / path, root / 'worlds' / path]
    candidates = [base.with_name(base.name + suffix) for base in bases
                  for suffix in (_SUFFIXES if not path.suffix else ('',))]
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    msg = f'{name}: not found; looked at ' + ', '.join(str(c) for c in bases)
    raise FileNotFoundError(msg)


def main(argv: list[str] | None = None) -> int:
    """Print the share directory (exit 0), or why there is none in one line (exit 2)."""
    parser = argparse.ArgumentParser(
        prog='mpc_local_planner_share',
        description='Print the share directory of this copy of mpc_local_planner: config/ '
                    '(the parameter files, worlds/ and maps/), launch/ and rviz/. It is what '
                    '`ros2 pkg prefix --share mpc_local_planner` prints for a colcon install, '
                    'here for any install and without ROS (for an editable install, the '
                    'source checkout).',
        epilog='example: mpc_controller --ros-args --params-file '
               '"$(mpc_local_planner_share)/config/mpc_controller.yaml"')
    parser.parse_args(argv)
    try:
        print(share_directory())
    except FileNotFoundError as err:
        print(f'mpc_local_planner_share: {err}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
