"""Large sites in slices: validate and dump a 10 000-node site without holding the GIL for
more than a few milliseconds at a time.

pydantic validates or dumps a whole document in one native call that keeps the GIL (about
100 ms to validate, 15-50 ms to dump a 10 000-node site): run in a thread, it would still stop
the server's event loop that long. The long lists (nodes, edges, robots, ...) are done here in
slices of ``SLICE`` items, between which the GIL passes; the document around them is then
validated with the items already built (pydantic takes model instances as they are).
"""

from __future__ import annotations

import typing
from typing import Any

from pydantic import TypeAdapter, ValidationError

from guidebot.site.schema import Site

__all__ = ["SLICE", "dump_site_doc", "prevalidate"]

SLICE = 200
"""Items per native call: a few milliseconds each."""


def _list_adapters() -> dict[str, TypeAdapter[Any]]:
    adapters: dict[str, TypeAdapter[Any]] = {}
    for name, info in Site.model_fields.items():
        annotation = info.annotation
        if annotation is not None and typing.get_origin(annotation) is list:
            adapters[name] = TypeAdapter(annotation)
    return adapters


_LISTS = _list_adapters()


def prevalidate(data: Any) -> Any:
    """``data`` with its long lists replaced by validated items, ready for ``Site``; ``data``
    itself when it is not a mapping or a slice has errors (the whole document is then
    validated at once, so every error is reported with its place, as before)."""
    if not isinstance(data, dict):
        return data
    out = dict(data)
    for name, adapter in _LISTS.items():
        items = data.get(name)
        if not isinstance(items, list) or len(items) <= SLICE:
            continue
        built: list[Any] = []
        try:
            for i in range(0, len(items), SLICE):
                built += adapter.validate_python(items[i : i + SLICE])
        except ValidationError:
            return data
        out[name] = built
    return out


def dump_site_doc(site: Site) -> dict[str, Any]:
    """``site.model_dump(mode="json")``, the long lists a slice at a time (same result)."""
    long = {name for name in _LISTS if len(getattr(site, name)) > SLICE}
    doc = site.model_dump(mode="json", exclude=long)
    for name in long:
        items = getattr(site, name)
        dumped: list[Any] = []
        for i in range(0, len(items), SLICE):
            dumped += _LISTS[name].dump_python(items[i : i + SLICE], mode="json")
        doc[name] = dumped
    return {name: doc[name] for name in Site.model_fields}
