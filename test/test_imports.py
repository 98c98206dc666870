# SPDX-License-Identifier: Apache-2.0
"""Every module of the package imports: a name moved between modules fails here, at once.

test_layers.py reads the imports from the source; this imports them, so an import of a name
that no longer exists where it is imported from (a split module) fails even in a module no
other test loads.
"""

import importlib
import pkgutil

import pytest

import mpc_local_planner

MODULES = sorted(m.name for m in pkgutil.walk_packages(mpc_local_planner.__path__,
                                                      'mpc_local_planner.'))


@pytest.mark.parametrize('name', MODULES)
def test_the_module_imports(name: str) -> None:
    assert importlib.import_module(name).__name__ == name
