# SPDX-License-Identifier: Apache-2.0
"""Controllers the paper's MPC is compared with."""

from mpc_local_planner.core.baselines.dwa import Dwa, DwaConfig
from mpc_local_planner.core.baselines.pure_pursuit import PurePursuit, PurePursuitConfig
from mpc_local_planner.core.baselines.tracking_mpc import TrackingMPC

__all__ = ['Dwa', 'DwaConfig', 'PurePursuit', 'PurePursuitConfig', 'TrackingMPC']
