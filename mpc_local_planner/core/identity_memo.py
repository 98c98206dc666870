# SPDX-License-Identifier: Apache-2.0
"""What is derived from an object, kept while the same object keeps coming (by identity).

The laser's memory hands over the same piece objects from scan to scan, and the node sets
them on the controller at every control step: fitting each to the NLP's faces and growing
it by the inflation again every time cost a large share of a step (issue 34). Polygons are
not hashable (their arrays), and equal values are not what matters: the same object is.
Each entry keeps its object, so its id() cannot be taken over by another while it is kept.
"""

from __future__ import annotations

from typing import Any, Callable, Generic, Sequence, TypeVar

__all__ = ['IdentityMemo']

Item = TypeVar('Item')
Derived = TypeVar('Derived')


class IdentityMemo(Generic[Item, Derived]):
    """Each item's derived value under a setting, for the items of the last call only."""

    def __init__(self) -> None:
        self._entries: dict[int, tuple[Any, Any, Any]] = {}

    def map(self, items: Sequence[Item], setting: Any,
            derive: Callable[[Item], Derived]) -> list[Derived]:
        """Return derive(item) for each item, computed only for items new since the last call.

        Args:
            items: the objects, in order.
            setting: what derive depends on besides the item (a changed one derives again).
            derive: the computation.

        """
        known, kept = self._entries, {}
        for item in items:
            entry = known.get(id(item))
            if entry is None or entry[0] is not item or entry[1] != setting:
                entry = (item, setting, derive(item))
            kept[id(item)] = entry
        self._entries = kept
        return [kept[id(item)][2] for item in items]
