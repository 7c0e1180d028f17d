"""Large JSON documents (a 10 000-node site is about 2 MB) parsed and written without any
native call that holds the GIL for long.

orjson parses or writes such a document in one native call: 10 to 25 ms during which no other
thread runs, the server's event loop included, even when the call is made in a worker thread.
Above ``LARGE`` bytes the standard library's pure-Python scanner and iterencoder are used
instead (each string still goes through the C helpers, one short call each): slower, but the
GIL passes between the pieces. The data is orjson's: numbers, limits and refusals follow
orjson, and a document the slow path does not take as it is goes to orjson for its verdict
(the same error message as before).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable
from json.scanner import py_make_scanner  # type: ignore[attr-defined]
from typing import Any

import orjson

__all__ = ["LARGE", "dumps", "loads"]

LARGE = 256 * 1024
"""Bytes above which a document is parsed or written in Python (orjson takes about 1 ms per
100 kB: below this, its one call is short enough)."""

_CHUNK = 4096
_INT_MIN, _INT_MAX = -(2**63), 2**64 - 1  # orjson's integers; beyond, it gives a float
_SURROGATE_ESCAPE = re.compile(rb"\\u[dD][89abAB]")


class _Refused(ValueError):
    """The slow path will not decide: orjson gives the verdict."""


def _parse_int(text: str) -> int | float:
    value = int(text)
    return value if _INT_MIN <= value <= _INT_MAX else float(text)


def _parse_float(text: str) -> float:
    value = float(text)
    if math.isinf(value):
        raise _Refused(text)  # orjson refuses numbers that overflow a double
    return value


def _refuse(text: str) -> Any:
    raise _Refused(text)  # NaN, Infinity: not JSON


def _decoder() -> json.JSONDecoder:
    decoder = json.JSONDecoder(
        parse_int=_parse_int, parse_float=_parse_float, parse_constant=_refuse
    )
    decoder.scan_once = py_make_scanner(decoder)  # type: ignore[attr-defined]  # not the C one
    return decoder


_DECODER = _decoder()


def loads(raw: bytes) -> Any:
    """``orjson.loads(raw)``: the same data, or the same ``orjson.JSONDecodeError``."""
    if len(raw) <= LARGE or _SURROGATE_ESCAPE.search(raw):
        return orjson.loads(raw)
    try:
        return _DECODER.decode(raw.decode("utf-8"))
    except (ValueError, RecursionError):  # bad UTF-8 or JSON, NaN, overflow, deep nesting
        return orjson.loads(raw)


def dumps(value: Any) -> str:
    """``orjson.dumps(value).decode()`` for plain JSON data (dicts with string keys, lists,
    strings, numbers, booleans, None); numbers may be written differently (``1e-07`` for
    ``1e-7``), their values are the same."""
    encoder = json.JSONEncoder(ensure_ascii=False, separators=(",", ":"), allow_nan=False)
    if _small(value) or not _ints_fit(value):  # orjson refuses integers beyond 64 bits
        return orjson.dumps(value).decode()
    try:
        return _joined(encoder.iterencode(value))  # not one-shot: the Python iterencoder
    except (TypeError, ValueError):  # not plain JSON data, NaN: orjson decides
        return orjson.dumps(value).decode()


def _ints_fit(value: Any) -> bool:
    """Every integer in ``value`` is one orjson writes (the Python encoder would write any,
    and orjson would read the too large ones back as floats)."""
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)
        elif isinstance(item, int) and not isinstance(item, bool):
            if not _INT_MIN <= item <= _INT_MAX:
                return False
    return True


def _joined(pieces: Iterable[str]) -> str:
    """``"".join(pieces)`` a few thousand pieces at a time (one join of half a million
    pieces, and freeing them, are long native calls too)."""
    chunks: list[str] = []
    chunk: list[str] = []
    for piece in pieces:
        chunk.append(piece)
        if len(chunk) == _CHUNK:
            chunks.append("".join(chunk))
            chunk = []
    chunks.append("".join(chunk))
    return "".join(chunks)


def _small(value: Any) -> bool:
    """Too small for a long native call: a document with few long lists."""
    if isinstance(value, dict):
        return sum(len(v) for v in value.values() if isinstance(v, (list, dict))) < 500
    if isinstance(value, list):
        return len(value) < 500
    return True
