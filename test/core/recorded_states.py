# SPDX-License-Identifier: Apache-2.0
"""Recorded states and their perturbations, for the tests built from recorded runs.

A recorded state's last digits depend on the machine that recorded it, and another CPU's
arithmetic lands elsewhere within them. A rule that holds at the recorded digits only is
fragile: each such test runs on the state as recorded and on states moved by up to
PERTURBATION (seeded, so every run checks the same ones).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

# How far a perturbation moves a state's components and an obstacle (metres, radians).
PERTURBATION = 1e-6
# The recorded state (0) and the seeds of its 20 perturbations.
SEEDS = tuple(range(21))


def perturbed(record: Any, seed: int) -> Any:
    """Return a copy of a recorded case with its states and obstacles moved (seed 0: as is).

    Every 'x' (a state) moves by up to PERTURBATION in each component; every obstacle under
    'obstacles' too: a vertex list vertex by vertex, a polygon given as A p <= b with its
    vertices as a whole (it stays the same polygon, translated).
    """
    if seed == 0:
        return copy.deepcopy(record)
    return _perturb(record, np.random.default_rng(seed))


def _perturb(value: Any, rng: np.random.Generator, key: str | None = None) -> Any:
    if isinstance(value, dict):
        return {k: _perturb(v, rng, k) for k, v in value.items()}
    if isinstance(value, list):
        if key == 'x' and all(isinstance(v, (int, float)) for v in value):
            return (np.array(value, dtype=float)
                    + rng.uniform(-PERTURBATION, PERTURBATION, len(value))).tolist()
        if key == 'obstacles':
            return [_moved_obstacle(o, rng) for o in value]
        return [_perturb(v, rng, key) for v in value]
    return value


def _moved_obstacle(obstacle: Any, rng: np.random.Generator) -> Any:
    if isinstance(obstacle, dict):
        shift = rng.uniform(-PERTURBATION, PERTURBATION, 2)
        moved = dict(obstacle)
        moved['vertices'] = (np.array(obstacle['vertices']) + shift).tolist()
        moved['b'] = (np.array(obstacle['b']) + np.array(obstacle['A']) @ shift).tolist()
        return moved
    vertices = np.array(obstacle, dtype=float)
    return (vertices + rng.uniform(-PERTURBATION, PERTURBATION, vertices.shape)).tolist()
