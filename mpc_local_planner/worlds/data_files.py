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


"""Find the files the package ships: configs, worlds and the BARN worlds.

A parameter such as ``world_file: paper_obstacle`` should work whichever way the package was
installed: built with colcon (``share/`` found through the ament index), installed with a
plain ``pip install .`` (``data_files`` land in ``<prefix>/share/``), or run from a source
checkout (editable install, tests). The BARN worlds are package data, so they travel inside
the Python package itself.
"""

from __future__ import annotations

from pathlib import Path
import site
import sys

__all__ = ['BARN_DIR', 'PACKAGE_NAME', 'config_roots', 'resolve_data_file']

PACKAGE_NAME = 'mpc_local_planner'
# The BARN worlds 0-99 and 200-299 shipped with the package (MIT notice in the same folder).
BARN_DIR = Path(__file__).resolve().parent.parent / 'data' / 'barn'
# Suffixes tried when a name is given without one (``--world rrt_cluttered``).
_SUFFIXES = ('', '.yaml', '.yml')


def config_roots() -> list[Path]:
    """Return the folders that may hold the package's ``config/``, most specific first."""
    roots: list[Path] = []
    try:
        from ament_index_python.packages import get_package_share_directory

        roots.append(Path(get_package_share_directory(PACKAGE_NAME)) / 'config')
    except Exception:
        pass
    for prefix in (sys.prefix, site.getuserbase()):
        roots.append(Path(prefix) / 'share' / PACKAGE_NAME / 'config')
    roots.append(Path(__file__).resolve().parents[2] / 'config')  # a source checkout
    unique: list[Path] = []
    for root in roots:
        if root not in unique:
            unique.append(root)
    return unique


def resolve_data_file(name: str | Path) -> Path:
    """Find a file named by a parameter or an option.

    Tried in order: the name as given (absolute, or relative to the working directory),
    then under each of config_roots() and its ``worlds/``; a name without a suffix also
    tries ``.yaml`` and ``.yml``.

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
