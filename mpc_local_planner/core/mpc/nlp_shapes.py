# SPDX-License-Identifier: Apache-2.0
"""The NLPs of one MPC, one per obstacle shape (slots, faces), and when they are built.

Problem (6) holds a fixed number of obstacle slots of a fixed number of faces; each shape is
its own NLP (built in tens of ms to a second, compiled by gcc in seconds to a minute).
Before an MPC is prepared a control step builds the shape it needs (a first step, a test);
after prepare() no step builds one, in its own thread or another: a build takes several
control periods, and in a background thread it still stalls the steps meanwhile, since
CasADi holds Python's lock while it builds (see docs/design/mpc.md, section "No builds after
prepare() (nlp_shapes.py)"). The step gets the smallest prepared NLP with room for its
obstacles (an unused slot is padded empty), or the largest one, which holds the nearest of
them; the MPC checks its solution against all of them.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

from mpc_local_planner.core.mpc.backends import Nlp
from mpc_local_planner.core.obstacles import ConvexPolygon

__all__ = ['MAX_CACHED_NLPS', 'NlpShapes', 'Shape', 'slot_shape']

# NLPs kept per MPC (the oldest goes first).
MAX_CACHED_NLPS = 32

Shape = tuple[int, int]  # (obstacle slots, faces per obstacle)


def slot_shape(selected: Sequence[ConvexPolygon], faces_per_obstacle: int) -> Shape:
    """Return (slots, faces) of the NLP that holds the selected obstacles.

    Faces are rounded up to a multiple of 4 (at most faces_per_obstacle), so that boxes and
    octagons share few builds.
    """
    if not selected:
        return 0, 0
    faces = max(o.num_faces for o in selected)
    faces = min(faces_per_obstacle, 4 * math.ceil(faces / 4)) if faces > 4 else faces
    return len(selected), max(faces, 3)


class NlpShapes:
    """The built NLPs of the settings in force, by shape.

    Args:
        structure: returns what the NLPs' structure depends on (the settings); when it
            changes, every NLP built before is dropped.
        build: builds the NLP of a shape (slots, faces) for the settings in force.

    """

    def __init__(self, structure: Callable[[], tuple],
                 build: Callable[[int, int], Nlp]) -> None:
        self._structure = structure
        self._build = build
        self._nlps: dict[Shape, Nlp] = {}
        self._key: tuple | None = None
        # set by the MPC's prepare(): from then on hold() builds nothing
        self.prepared = False

    def clear(self) -> None:
        """Drop every NLP (the settings changed); shapes are built on demand until prepared."""
        self._nlps.clear()
        self.prepared = False

    def built(self) -> dict[Shape, Nlp]:
        """Return the NLPs of the current settings."""
        key = self._structure()
        if key != self._key:
            self._nlps.clear()
            self._key = key
        return self._nlps

    def prepare(self, shapes: list[Shape]) -> None:
        """Build these shapes' NLPs and their IPOPTs; from then on hold() builds nothing.

        The IPOPTs: the fallback of each, and the cold start of each that holds obstacles.
        """
        for shape in shapes:
            nlp = self.get(shape)
            nlp.fallback_solver()
            if shape[0]:
                nlp.cold_solver()
        self.prepared = True

    def ready(self, nlp: Nlp, *, wait: bool) -> None:
        """Make nlp ready to solve: its compiled functions, and a time per iteration.

        The compiled functions are waited for if wait. A never-solved NLP's time per
        iteration is bounded by its siblings' (iteration_time_estimate).
        """
        nlp.finish_compilation(wait=wait)
        if nlp.iteration_time <= 0.0:
            nlp.iteration_time = self.iteration_time_estimate(nlp)

    def get(self, shape: Shape) -> Nlp:
        """Return the NLP of this shape, built now if it is not yet."""
        nlp = self.built().get(shape)
        if nlp is None:
            nlp = self._build(*shape)
            self._store(shape, nlp)
        return nlp

    def hold(self, shape: Shape) -> tuple[Nlp, int]:
        """Return an NLP for obstacles of this shape and how many of them it holds.

        Not prepared, or the shape built: that NLP, all of them. Else the smallest built NLP
        with room for them (all of them), or the largest with faces enough for them (the
        first as many as its slots); only if no NLP has faces enough is the shape built now.
        """
        slots, faces = shape
        nlps = self.built()
        if shape in nlps or not self.prepared:
            return self.get(shape), slots
        roomy = [s for s in nlps if s[0] >= slots and s[1] >= faces]
        if roomy:
            return nlps[min(roomy)], slots
        enough_faces = [s for s in nlps if s[1] >= faces]
        if not enough_faces:
            return self.get(shape), slots
        largest = max(enough_faces)
        return nlps[largest], largest[0]

    def holding(self, active: list[ConvexPolygon], faces_per_obstacle: int
                ) -> tuple[Nlp, list[ConvexPolygon]]:
        """Return an NLP for the active obstacles (nearest first) and the ones it holds."""
        nlp, count = self.hold(slot_shape(active, faces_per_obstacle))
        return nlp, active[:count]

    def holds_more(self, active: list[ConvexPolygon], held: Sequence[ConvexPolygon],
                   faces_per_obstacle: int) -> bool:
        """Say whether the NLP for active would hold an obstacle that held does not have.

        Before prepare every NLP holds all it is given (the shape is built), so it would if
        active has more; once prepared the largest NLP holds the first as many as its slots,
        which may be those of held again.
        """
        if not self.prepared:
            return len(active) > len(held)
        _, holding = self.holding(active, faces_per_obstacle)
        return any(not any(o is h for h in held) for o in holding)

    def iteration_time_estimate(self, nlp: Nlp) -> float:
        """Estimate a never-solved NLP's seconds per iteration from the solved ones (0: none).

        The largest measured time per iteration, scaled by the number of variables (a
        structure-exploiting iteration costs about linearly in the stage sizes). fatrop's own
        time bound needs a time per iteration, so without this estimate the first solve of a
        shape would run its max_iterations unbounded by the step's budget (see
        docs/design/mpc.md, section NlpShapes.iteration_time_estimate).
        """
        size = nlp.formulation.lbw.shape[0]
        return max((other.iteration_time * size / other.formulation.lbw.shape[0]
                    for other in self._nlps.values() if other.iteration_time > 0.0),
                   default=0.0)

    def _store(self, shape: Shape, nlp: Nlp) -> None:
        if len(self._nlps) >= MAX_CACHED_NLPS:
            self._nlps.pop(next(iter(self._nlps)))  # the oldest
        self._nlps[shape] = nlp
