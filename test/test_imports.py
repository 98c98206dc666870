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
