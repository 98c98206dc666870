# SPDX-License-Identifier: Apache-2.0
"""Tests of reading a scan (perception/scans.py): what a scan must hold."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from mpc_local_planner.perception.scans import Scan, ScanError, validate_scan


def good_scan(**changes: Any) -> Scan:
    return Scan(-1.0, 0.01, 0.05, 10.0, np.full(201, 3.0))._replace(**changes)


@pytest.mark.parametrize(('scan', 'match'), [
    (good_scan(angle_increment=math.nan), 'angle_increment must be finite'),
    (good_scan(angle_increment=0.0), 'must not be 0'),
    (good_scan(intensities=np.ones(3)), '201 ranges but 3 intensities'),
    (good_scan(ranges=np.ones(10_001), angle_increment=1e-4), 'more than the 10000'),
    (good_scan(range_max=0.01), 'range_min < range_max'),
    (good_scan(range_min=-0.1), 'range_min < range_max'),
    (good_scan(range_min=math.nan), 'range_min must be finite'),
    (good_scan(range_max=math.inf), 'range_max must be finite'),
    (good_scan(angle_min=math.inf), 'angle_min must be finite'),
    (good_scan(angle_max=0.5), 'scan has 201 ranges but'),
    (good_scan(angle_min=-1e308, angle_max=1e308), 'more beams than can be counted'),
    (good_scan(angle_increment=0.1), 'more than a full turn'),
    (good_scan(ranges=np.ones((2, 3))), 'one-dimensional'),
    (good_scan(stamp=math.nan), 'stamp must be finite'),
])
def test_malformed_scans_raise_scan_error(scan: Scan, match: str) -> None:
    with pytest.raises(ScanError, match=match):
        validate_scan(scan)
