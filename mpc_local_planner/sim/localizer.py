# SPDX-License-Identifier: Apache-2.0
"""A simulated localizer (AMCL's stand-in): the true pose with noise, at a rate.

The robot's side composes what it publishes with odometry (perception/localization.py).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

__all__ = ['Localizer', 'LOCALIZER_NOISE', 'LOCALIZER_RATE']

# The localizer stand-in of every localized run (closed_loop with --drift or a non-ideal
# --reality, the suites with a non-ideal reality): AMCL updates a moving robot's pose a few
# times a second (5 Hz) to about a centimetre in a well-mapped place (noise on x, y, and in
# rad on theta).
LOCALIZER_RATE = 5.0
LOCALIZER_NOISE = 0.01


class Localizer:
    """A localizer's stand-in (AMCL's ``amcl_pose``): the TRUE pose with noise, at a rate.

    What the unicycle_simulator node publishes with ``localizer.rate`` and
    ``localizer.noise_std`` (closed_loop sets them to LOCALIZER_RATE and LOCALIZER_NOISE):
    Gaussian noise of the same standard deviation on x, y (m) and theta (rad), its own seeded
    stream. Time is the caller's, as a `Base`'s: a pose is due at 0 (the localizer has its
    initial pose before the robot moves) and then every 1 / rate seconds.

    Args:
        rate: poses per second (> 0).
        noise_std: standard deviation of the noise (m, and rad for the heading).
        seed: seed of the noise (a run's reality seed: runs are reproducible).

    """

    def __init__(self, rate: float = LOCALIZER_RATE, noise_std: float = LOCALIZER_NOISE,
                 seed: int = 0) -> None:
        if not (math.isfinite(rate) and rate > 0.0):
            msg = f'rate must be > 0 and finite, got {rate}'
            raise ValueError(msg)
        if not (math.isfinite(noise_std) and noise_std >= 0.0):
            msg = f'noise_std must be >= 0 and finite, got {noise_std}'
            raise ValueError(msg)
        self.rate = float(rate)
        self.noise_std = float(noise_std)
        # its own stream: the base's and the laser's draws do not shift it
        self._rng = np.random.default_rng([int(seed), 2])
        self._next = 0.0

    def measure(self, time: float, pose: Sequence[float]) -> np.ndarray | None:
        """Return the localizer's pose (x, y, theta in map) at time if one is due, else None.

        Args:
            time: now (s); calls come in time order.
            pose: the TRUE pose now.

        """
        if time < self._next - 1e-9:
            return None
        period = 1.0 / self.rate
        while self._next <= time + 1e-9:
            self._next += period
        return np.asarray(pose, dtype=float)[:3] + self._rng.normal(0.0, self.noise_std, 3)
