# SPDX-License-Identifier: Apache-2.0
"""The laser's side of reality: noise, NaN and -inf beams, and lost scans (`ScanChannel`)."""

from __future__ import annotations

import numpy as np

from mpc_local_planner.sim.reality import Reality

__all__ = ['ScanChannel']


class ScanChannel:
    """The laser's side of reality: noise, NaN and -inf beams, and lost scans.

    Works on the readings (a LaserScan's ``ranges``) so that the simulator node and the
    rollout corrupt their scans the same way; draws come from one seeded generator.
    """

    def __init__(self, reality: Reality) -> None:
        self.reality = reality
        # its own stream: the base's draws do not shift the laser's when either changes
        self._rng = np.random.default_rng([reality.seed, 1])

    def lost(self) -> bool:
        """Draw whether the next scan never arrives."""
        return self.reality.scan_loss > 0.0 and bool(self._rng.random() < self.reality.scan_loss)

    def corrupt(self, ranges: np.ndarray, range_max: float) -> np.ndarray:
        """Return the readings as a real laser reports them (a copy; ideal: unchanged).

        Noise moves finite readings (a reading pushed past range_max becomes +inf: no
        return); then a fraction of the beams read NaN and a fraction -inf, as REP 117 has
        drivers report erroneous and too-close readings.
        """
        ranges = np.array(ranges, dtype=float)
        reality = self.reality
        if reality.ideal_laser:
            return ranges
        if reality.scan_noise > 0.0:
            hit = np.isfinite(ranges)
            noisy = ranges[hit] + self._rng.normal(0.0, reality.scan_noise, int(hit.sum()))
            noisy = np.maximum(noisy, 0.0)
            noisy[noisy > range_max] = np.inf
            ranges[hit] = noisy
        if reality.scan_nan > 0.0 or reality.scan_neg_inf > 0.0:
            draw = self._rng.random(len(ranges))
            ranges[draw < reality.scan_nan] = np.nan
            ranges[(draw >= reality.scan_nan)
                   & (draw < reality.scan_nan + reality.scan_neg_inf)] = -np.inf
        return ranges
