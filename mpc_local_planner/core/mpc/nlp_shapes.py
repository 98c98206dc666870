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


"""The NLPs of one MPC, one per obstacle shape (slots, faces), and when they are built.

Problem (6) holds a fixed number of obstacle slots of a fixed number of faces; each shape is
its own NLP (built in tens of ms to a second, compiled by gcc in minutes). Before an MPC is
prepared a control step builds the shape it needs (a first step, a test); after prepare()
it never does: building a polygon NLP with more obstacles than were prepared took 1.1 s in a
BARN run, five control periods. The step then gets the smallest built NLP with room for its
obstacles (an unused slot is padded empty), or the largest one, which holds the nearest of
them, and the shape is built in a background thread for the steps after.
"""

from __future__ import annotations

from concurrent.futures import Future
import threading
from typing import Callable

from mpc_local_planner.core.mpc.backends import Nlp

__all__ = ['MAX_CACHED_NLPS', 'NlpShapes', 'Shape']

# NLPs kept per MPC (the oldest goes first).
MAX_CACHED_NLPS = 32

Shape = tuple[int, int]  # (obstacle slots, faces per obstacle)


class NlpShapes:
    """The built NLPs of the settings in force, by shape, and those being built.

    Args:
        structure: returns what the NLPs' structure depends on (the settings); when it
            changes, every NLP built before is dropped.
        builder: returns a function that builds a shape for the settings in force (called
            on the caller's thread, so that a background build uses the settings of when it
            was asked for).

    """

    def __init__(self, structure: Callable[[], tuple],
                 builder: Callable[[], Callable[[int, int], Nlp]]) -> None:
        self._structure = structure
        self._builder = builder
        self._nlps: dict[Shape, Nlp] = {}
        self._key: tuple | None = None
        self._builds: dict[Shape, tuple[tuple, Future]] = {}
        # set by the MPC's prepare(): from then on hold() builds nothing itself
        self.prepared = False

    def clear(self) -> None:
        """Drop every NLP (the settings changed); shapes are built on demand until prepared."""
        self._nlps.clear()
        self.prepared = False

    def built(self) -> dict[Shape, Nlp]:
        """Return the NLPs of the current settings, with the finished background builds."""
        key = self._structure()
        if key != self._key:
            self._nlps.clear()
            self._key = key
        for shape, (built_for, future) in list(self._builds.items()):
            if future.done():
                del self._builds[shape]
                if built_for == key and future.exception() is None:
                    self._store(shape, future.result())
        return self._nlps

    def get(self, shape: Shape) -> Nlp:
        """Return the NLP of this shape, built now if it is not yet."""
        nlp = self.built().get(shape)
        if nlp is None:
            nlp = self._builder()(*shape)
            self._store(shape, nlp)
        return nlp

    def hold(self, shape: Shape) -> tuple[Nlp, int]:
        """Return an NLP for obstacles of this shape and how many of them it holds.

        Not prepared, or the shape built: that NLP, all of them. Else the smallest built NLP
        with room for them (all of them), or the largest with faces enough for them (the
        first as many as its slots), while the shape is built in the background; only if no
        NLP has faces enough is the shape built now.
        """
        slots, faces = shape
        nlps = self.built()
        if shape in nlps or not self.prepared:
            return self.get(shape), slots
        self.build_in_background(shape)
        roomy = [s for s in nlps if s[0] >= slots and s[1] >= faces]
        if roomy:
            return nlps[min(roomy)], slots
        enough_faces = [s for s in nlps if s[1] >= faces]
        if not enough_faces:
            return self.get(shape), slots
        largest = max(enough_faces)
        return nlps[largest], largest[0]

    def build_in_background(self, shape: Shape) -> None:
        """Start building a shape in a daemon thread (once per shape)."""
        if shape in self._builds:
            return
        future: Future = Future()
        build = self._builder()

        def work() -> None:
            try:
                nlp = build(*shape)
                # with its IPOPTs (a step builds one only if the build fits its budget) and
                # compiled (config.compile): interpreted, a polygon NLP with many obstacles
                # ran fatrop's 200 iterations in 2.4 s (fatrop's iterations are bounded from
                # the compiled library only, see backends)
                nlp.fallback_solver()
                nlp.cold_solver()
                nlp.finish_compilation(wait=True)
                future.set_result(nlp)
            except BaseException as err:  # a failed build is dropped; the steps go on
                future.set_exception(err)

        self._builds[shape] = (self._structure(), future)
        threading.Thread(target=work, name='mpc_nlp_build', daemon=True).start()

    def wait_built(self) -> None:
        """Block until the shapes being built in the background are built (or failed)."""
        for _, future in list(self._builds.values()):
            future.exception()  # waits
        self.built()

    def iteration_time_estimate(self, nlp: Nlp) -> float:
        """Estimate a never-solved NLP's seconds per iteration from the solved ones (0: none).

        The largest measured time per iteration, scaled by the number of variables (a
        structure-exploiting iteration costs about linearly in the stage sizes). Without it
        the first solve of a shape ran fatrop's 200 iterations unbounded: single steps of
        0.3-0.8 s at 1 m/s on BARN (fatrop's own bound needs the time per iteration).
        """
        size = nlp.formulation.lbw.shape[0]
        return max((other.iteration_time * size / other.formulation.lbw.shape[0]
                    for other in self._nlps.values() if other.iteration_time > 0.0),
                   default=0.0)

    def _store(self, shape: Shape, nlp: Nlp) -> None:
        if len(self._nlps) >= MAX_CACHED_NLPS:
            self._nlps.pop(next(iter(self._nlps)))  # the oldest
        self._nlps[shape] = nlp
