# SPDX-License-Identifier: Apache-2.0
"""The suites' MPCs, one per (controller, model, config, settings) in a worker process.

An MPC builds one NLP per obstacle count in reach, and compiles it: a robot does that once at
start-up, so a suite builds each MPC once and reuses it across runs (reset between them).
What makes two MPCs the same is the frozen value of what they are built from, so that is the
key (no hand-listed fields to forget). `evaluate` sends tasks to worker processes (or a Dask
cluster), each with its own cache.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

from mpc_local_planner.core.config import MpcConfig
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.controllers import ControllerName
from mpc_local_planner.core.models import RobotModel

__all__ = ['MPC_CACHE', 'MpcCache', 'MpcKey']


@dataclass(frozen=True)
class MpcKey:
    """What an MPC is built from (hashable: every member is a frozen value).

    Attributes:
        controller: Which MPC.
        model: The robot model.
        config: The MPC's settings.
        settings: The controller's settings (None: the MPC alone, without MpcController).

    """

    controller: ControllerName
    model: RobotModel
    config: MpcConfig
    settings: ControllerSettings | None = None


@dataclass
class MpcCache:
    """Built MPCs by key, and which of them have prepared their NLPs."""

    built: dict[MpcKey, Any] = field(default_factory=dict)
    prepared: set[MpcKey] = field(default_factory=set)

    def get(self, key: MpcKey, build: Callable[[], Any]) -> Any:
        """Return the MPC of key, built by build() the first time."""
        mpc = self.built.get(key)
        if mpc is None:
            mpc = self.built[key] = build()
        return mpc

    def prepare_once(self, key: MpcKey, prepare: Callable[[], None]) -> None:
        """Run prepare() the first time it is asked for key (NLPs are built once)."""
        if key not in self.prepared:
            prepare()
            self.prepared.add(key)


# Per process: the suites' MPCs (see the module docstring).
MPC_CACHE = MpcCache()
