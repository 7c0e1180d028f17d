"""Free a large object graph a piece at a time, so that no single native call holds the GIL long.

Dropping the last reference to a parsed 10 000-node site (its YAML node tree, its JSON or YAML
data, the validated ``Site``, the route graph's distance fields) frees hundreds of thousands of
objects in one chain of native deallocations: 10 to 50 ms during which no other thread runs,
the server's event loop included, even when the drop happens in a worker thread. ``dispose``
takes such objects apart from the top, popping the items of each container in a Python loop,
so that the GIL can pass between the pieces. Only objects nobody else references are taken
apart (their reference count says so); anything shared is just let go, untouched.
"""

from __future__ import annotations

import sys
from typing import Any

__all__ = ["DEPTH", "dispose"]

DEPTH = 6
"""Levels taken apart (a container, or an object with its attribute dictionary, is a level);
what lies deeper is freed natively, a few hundred objects at a time at most in a site."""

_SHORT = 8
_ATOMS = (str, int, float, bytes, type(None))
_OWNED = 2
"""``sys.getrefcount`` of an object held by one local variable only (the call adds one)."""
_COUNTS_KNOWN = sys.implementation.name == "cpython" and sys.version_info < (3, 14)
"""Where that count is known to hold (CPython 3.14 may not count references on its stack):
elsewhere nothing is taken apart, objects are just let go."""


def dispose(box: list[Any], depth: int = DEPTH) -> int:
    """Empty ``box`` (a list the caller made for the purpose and keeps no other reference
    into) and free its items a piece at a time; returns how many containers were taken apart
    (0 when every item was still referenced elsewhere)."""
    if not _COUNTS_KNOWN:
        box.clear()
        return 0
    stack: list[tuple[Any, int]] = []
    while box:
        stack.append((box.pop(), depth))
    return _take_apart(stack)


def _take_apart(stack: list[tuple[Any, int]]) -> int:
    """Pop the items of the stack's objects and of their sole-owned containers, each down to
    its level."""
    taken = 0
    while stack:
        item, level = stack.pop()
        # Held by ``item`` alone now (the stack's tuple is gone): safe to take apart.
        if sys.getrefcount(item) != _OWNED:
            del item
            continue
        target = item.__dict__ if _has_dict(item) else item
        taken += 1
        if isinstance(target, dict):
            while target:
                _key, child = target.popitem()
                del _key
                if level > 1 and _divisible(child):
                    stack.append((child, level - 1))
                del child
        elif isinstance(target, list):
            while target:
                child = target.pop()
                if level > 1 and _divisible(child):
                    stack.append((child, level - 1))
                del child
        elif isinstance(target, tuple):
            for child in target:
                if level > 1 and _divisible(child):
                    stack.append((child, level - 1))
            child = None
        del target, item
    return taken


def _has_dict(item: Any) -> bool:
    return not isinstance(item, (dict, list, tuple, type)) and isinstance(
        getattr(item, "__dict__", None), dict
    )


def _divisible(item: Any) -> bool:
    """Worth taking apart: an object, or a container that is long or holds containers (a
    short one of numbers and strings is freed in one short native call)."""
    if isinstance(item, (dict, list, tuple)):
        if len(item) > _SHORT:
            return True
        values = item.values() if isinstance(item, dict) else item
        return not all(isinstance(v, _ATOMS) for v in values)
    return _has_dict(item)
