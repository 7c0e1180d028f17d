"""Large JSON documents (a 10 000-node site is about 2 MB) parsed and written without any
native call that holds the GIL for long.

orjson parses or writes such a document in one native call: 10 to 25 ms during which no other
thread runs, the server's event loop included, even when the call is made in a worker thread.
Above ``LARGE`` bytes the standard library's pure-Python scanner is used to parse instead
(each string still goes through the C helpers, one short call each): slower, but the GIL
passes between the pieces. The data is orjson's: numbers, limits and refusals follow orjson,
and a document the slow path does not take as it is goes to orjson for its verdict (the same
error message as before). Writing needs no scanner: a large document is written by orjson a
few hundred list items per call (``dumps_bytes``), the same bytes as one call would give.
"""

from __future__ import annotations

import json
import math
import re
from json.scanner import py_make_scanner  # type: ignore[attr-defined]
from typing import Any

import orjson

__all__ = ["LARGE", "dumps", "loads"]

LARGE = 256 * 1024
"""Bytes above which a document is parsed in Python (orjson takes about 1 ms per 100 kB:
below this, its one call is short enough)."""

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
    """``orjson.dumps(value).decode()`` (``dumps_bytes``)."""
    return dumps_bytes(value).decode()


def dumps_bytes(value: Any) -> bytes:
    """``orjson.dumps(value)``: the same bytes, or the same error, in short calls. The dicts
    that hold a long list (at any depth) are written key by key, and such lists ``SLICE``
    items per call; everything else in one call each."""
    pieces: list[bytes] = []
    _write(value, pieces)
    return b"".join(pieces)


SLICE = 200
"""List items written per orjson call (a site's node: about 0.2 kB, 1-2 µs)."""


def _write(value: Any, pieces: list[bytes]) -> None:
    if type(value) is list and len(value) > SLICE:
        pieces.append(b"[")
        for start in range(0, len(value), SLICE):
            if start:
                pieces.append(b",")
            pieces.append(orjson.dumps(value[start : start + SLICE])[1:-1])
        pieces.append(b"]")
    elif type(value) is dict and _holds_long_list(value) and all(type(k) is str for k in value):
        pieces.append(b"{")
        for n, (key, item) in enumerate(value.items()):
            if n:
                pieces.append(b",")
            pieces += (orjson.dumps(key), b":")
            _write(item, pieces)
        pieces.append(b"}")
    else:
        pieces.append(orjson.dumps(value))  # small, or not plain: orjson's answer or error


def _holds_long_list(value: dict[Any, Any]) -> bool:
    """A list of more than SLICE items among the values, or in a dict among them."""
    return any(
        (type(v) is list and len(v) > SLICE) or (type(v) is dict and _holds_long_list(v))
        for v in value.values()
    )
