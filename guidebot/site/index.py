"""Lookups by id in a site's lists in O(1): a fleet of 1000 robots reconnecting asks
``Site.robot(name)`` 1000 times, a million comparisons as a scan.

The table of one list is built on the first lookup and kept with the model that owns it. It
stays right across the ways sites change here: a copy (``model_copy``, with or without
``update``, pickling to a worker) owns a fresh table, a replaced list (a draft published is a
new ``Site``; ``model_copy(update={"robots": ...})`` is a new list) or one that grew or shrank
is indexed again, and a hit is checked against the item found, so an item replaced in place is
noticed as well. Sites are values: code replaces lists rather than editing them in place, and
an in-place replacement under a new id is the one edit a miss cannot notice.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from pydantic import BaseModel, PrivateAttr

__all__ = ["Indexed", "ListIndex"]

T = TypeVar("T")


class ListIndex:
    """Tables from key to position, one per list of one model. Equal to any other, and to
    None (a model that has not looked anything up yet): pydantic compares private attributes
    in ``==``, and a cache is not data."""

    __slots__ = ("builds", "owner", "tables")

    def __init__(self, owner: int) -> None:
        self.owner = owner
        self.tables: dict[str, tuple[Sequence[Any], int, dict[str, int]]] = {}
        self.builds = 0
        """How many tables were built (tests count them: a lookup must not scan)."""

    def __eq__(self, other: object) -> bool:
        return other is None or isinstance(other, ListIndex)

    __hash__ = None  # type: ignore[assignment]

    def find(self, name: str, items: Sequence[T], key: Callable[[T], str], value: str) -> T | None:
        """The first item of ``items`` whose ``key`` is ``value`` (the table is named ``name``)."""
        table = self.tables.get(name)
        if table is None or table[0] is not items or table[1] != len(items):
            table = self._build(name, items, key)
        pos = table[2].get(value)
        if pos is None:
            return None
        item = items[pos]
        if key(item) == value:
            return item
        pos = self._build(name, items, key)[2].get(value)  # replaced in place: index again
        return None if pos is None else items[pos]

    def _build(
        self, name: str, items: Sequence[T], key: Callable[[T], str]
    ) -> tuple[Sequence[Any], int, dict[str, int]]:
        positions: dict[str, int] = {}
        for pos, item in enumerate(items):
            positions.setdefault(key(item), pos)  # the first wins, as a scan would find it
        self.builds += 1
        table = (items, len(items), positions)
        self.tables[name] = table
        return table


class Indexed(BaseModel):
    """A model whose lists are looked up by id through ``_find`` (see the module's docstring)."""

    _lookups: ListIndex | None = PrivateAttr(default=None)

    def lookups(self) -> ListIndex:
        """This model's tables; a copy of the model gets its own."""
        index = self._lookups
        if index is None or index.owner != id(self):
            index = ListIndex(id(self))
            self._lookups = index
        return index

    def _find(self, name: str, items: Sequence[T], key: Callable[[T], str], value: str) -> T | None:
        return self.lookups().find(name, items, key, value)
